"""The daemon's ``--capture FILE`` over a restart: the second run appends to what the first
captured (a service restart does not overwrite it), says so, and a replay reads both runs."""

from __future__ import annotations

import re

from processes import cmsensord, daemon_on_short_board


def _run(tmp_path, cap, seed: int) -> str:
    """One board of 3 s at 1x (it holds its pty after; its noise from ``seed``), the daemon
    capturing it: its stderr.  Two runs of one seed send the same frames: a first run that
    the daemon joined late (fewer than 256 frames) would make the second's frames repeats."""
    return daemon_on_short_board(tmp_path, "--capture", str(cap), board=("--duration", "3", "--seed", str(seed)))[1]


def test_a_restarted_daemon_appends_to_its_capture(tmp_path):
    cap = tmp_path / "cap.bin"
    first = _run(tmp_path, cap, 1)
    size = cap.stat().st_size
    assert size > 0 and "appending to" not in first
    second = _run(tmp_path, cap, 2)
    assert f"INFO capture: appending to {cap} ({size / 1e6:.1f} MB captured there before: a replay reads " \
           "this restart as a gap)" in second, second
    assert cap.stat().st_size > size
    r = cmsensord("replay", str(cap), "--out", str(tmp_path / "replay"))
    assert r.returncode == 0, r.stderr
    assert "WARNING time_base: board clock restarted" in r.stderr, r.stderr     # the second run's board
    assert int(re.search(r"\((\d+) observations", r.stderr).group(1)) > 300, r.stderr   # one run: <= 300
