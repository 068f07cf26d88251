"""The tests' process helpers: a daemon a test leaves running is stopped after it."""

from __future__ import annotations

import processes
from processes import start_daemon


def test_a_daemon_left_running_is_killed_and_named(tmp_path):
    d = start_daemon(tmp_path, tmp_path / "ttyNONE")     # waits for its port for ever
    assert d.poll() is None
    left = processes.stop_left_running()
    assert d.returncode is not None
    assert left == [" ".join(map(str, d.args))] and "cmsensord" in left[0]
    assert processes.STARTED == []
