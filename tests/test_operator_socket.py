"""`cmsensord status` typed beside `cmsensord --simulate` (the README's first command, the
default ``output.dir``) finds that daemon when the service's socket is not there (it said
"no daemon answers on /var/lib/cmsensord/cmsensord.sock")."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from cmsensord.service.control import SOCKET_NAME, STATE_DIR
from processes import ENV, spawn, stop

pytestmark = pytest.mark.skipif((STATE_DIR / SOCKET_NAME).exists(), reason="a service's socket is there")


def status(cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cmsensord", "status"], cwd=cwd, env=ENV, capture_output=True,
                          text=True, timeout=60)


def test_status_finds_the_simulation_started_in_the_same_directory(tmp_path):
    p = status(tmp_path)
    assert p.returncode == 1 and p.stderr.startswith(f"cmsensord: no daemon answers on {STATE_DIR / SOCKET_NAME}: ")
    daemon = spawn([sys.executable, "-m", "cmsensord", "--simulate", "--duration", "600", "--speed", "1"],
                   cwd=tmp_path, env=ENV, stderr=subprocess.PIPE, text=True)
    try:
        sock = tmp_path / "cmsensord-logs" / SOCKET_NAME
        deadline = time.monotonic() + 30
        while not sock.is_socket() and time.monotonic() < deadline:
            time.sleep(0.1)
        p = status(tmp_path)
        assert p.returncode == 0, p.stderr
        assert "| rx " in p.stdout, p.stdout
    finally:
        stop(daemon)
