"""The daemon's ``--capture FILE`` over a restart: the second run appends to what the first
captured (a service restart does not overwrite it), says so, and a replay reads both runs."""

from __future__ import annotations

import json
import re
import time

from processes import cmsensord, start_board, start_daemon, stop


def _run(tmp_path, cap) -> str:
    """One board of 3 s at 1x (it holds its pty after), the daemon capturing it: its stderr."""
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", "--duration", "3", "--link", str(link), "--flow-control")
    d = start_daemon(tmp_path, link, "--capture", str(cap))
    json.loads(sim.stdout.readline())                # the board has sent everything
    time.sleep(1.0)
    err = stop(d)
    sim.terminate()
    sim.wait(timeout=5)
    assert d.returncode == 0 and "Traceback" not in err, err
    return err


def test_a_restarted_daemon_appends_to_its_capture(tmp_path):
    cap = tmp_path / "cap.bin"
    first = _run(tmp_path, cap)
    size = cap.stat().st_size
    assert size > 0 and "appending to" not in first
    second = _run(tmp_path, cap)
    assert f"INFO capture: appending to {cap} ({size / 1e6:.1f} MB captured there before: a replay reads " \
           "this restart as a gap)" in second, second
    assert cap.stat().st_size > size
    r = cmsensord("replay", str(cap), "--out", str(tmp_path / "replay"))
    assert r.returncode == 0, r.stderr
    assert "WARNING time_base: board clock restarted" in r.stderr, r.stderr     # the second run's board
    assert int(re.search(r"\((\d+) observations", r.stderr).group(1)) > 300, r.stderr   # one run: <= 300
