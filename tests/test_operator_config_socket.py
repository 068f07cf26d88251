"""`cmsensord status --config FILE` with no daemon answering: the line says what to try for that
configuration, not to give the --config FILE already given; a relative ``output.dir`` (which the
unit's daemon takes in its working directory, /var/lib/cmsensord) names the socket it answers on."""

from __future__ import annotations

import subprocess
import sys

import pytest

from cmsensord.service.control import SOCKET_NAME, STATE_DIR
from processes import ENV

pytestmark = pytest.mark.process

OUT = "a daemon started with --out DIR answers on --socket DIR/cmsensord.sock"


def _status(cwd, cfg) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cmsensord", "status", "--config", str(cfg)], cwd=cwd, env=ENV,
                          capture_output=True, text=True, timeout=60)


def test_no_daemon_of_a_config_with_a_relative_output_dir_names_the_services_socket(tmp_path):
    cfg = tmp_path / "site.yaml"
    cfg.write_text("output:\n  dir: cm-test-logs\n")
    p = _status(tmp_path, cfg)
    assert p.returncode == 1 and p.stdout == ""
    assert p.stderr == (f"cmsensord: no daemon answers on {tmp_path / 'cm-test-logs' / SOCKET_NAME}: No such file "
                        f"or directory (output.dir cm-test-logs of {cfg} is relative, taken here; the service runs in "
                        f"{STATE_DIR}, its daemon answers on --socket {STATE_DIR / 'cm-test-logs' / SOCKET_NAME}; "
                        f"{OUT})\n")


def test_no_daemon_of_a_config_asks_whether_it_runs_not_for_the_config(tmp_path):
    cfg = tmp_path / "site.yaml"
    cfg.write_text(f"output:\n  dir: {tmp_path / 'logs'}\n")
    p = _status(tmp_path, cfg)
    assert p.returncode == 1 and p.stdout == ""
    assert p.stderr == (f"cmsensord: no daemon answers on {tmp_path / 'logs' / SOCKET_NAME}: No such file or "
                        f"directory (is the daemon of {cfg} running? see systemctl status cmsensord; {OUT})\n")
