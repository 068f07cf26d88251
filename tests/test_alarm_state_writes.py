"""The live daemon keeps the alarm state file without rewriting it at each change of a
chattering alarm (each rewrite is a file and a directory fsync on the board's SD card: 42 in
2 minutes, 30,000 a day): a change of levels alone is saved at most once a minute of stream
time and at the stop; a latch or an acknowledgement at once."""

from __future__ import annotations

import contextlib
import json
import time

from processes import start_board, start_daemon, stop
from test_alarms_restart import alarm_events

CHATTER = "alarms:\n  rules:\n    - {name: rms, indicator: accel_rms, alert: 3.1, danger: 6.0}\n"


def _saves(state, seconds: float) -> set[int]:
    """The distinct ``saved_ns`` the state file shows, read every 20 ms for ``seconds``."""
    seen: set[int] = set()
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        with contextlib.suppress(OSError, ValueError):     # between its writes, or not written yet
            seen.add(json.loads(state.read_text())["saved_ns"])
        time.sleep(0.02)
    return seen


def test_a_chattering_alarm_is_saved_once_a_minute_and_at_the_stop(tmp_path):
    link, state = tmp_path / "ttyBOARD", tmp_path / "logs" / "cmsensord-alarms.json"
    board = start_board("--scenario", "faulty", "--speed", "20", "--link", str(link))
    d = start_daemon(tmp_path, link, config=CHATTER)
    try:
        t0 = time.monotonic()
        saves = _saves(state, 10.0)
        stream_s = (time.monotonic() - t0) * 20
    finally:
        err = stop(d)
        board.terminate()
        board.wait(timeout=5)
    changes = [m for m in alarm_events(tmp_path / "logs") if m["kind"] in ("alarm_alert", "alarm_clear")]
    assert len(changes) >= 15, err[-2000:]                       # it chatters
    assert len(saves) <= 2 * stream_s / 60 + 2, (len(saves), stream_s, len(changes))
    last = changes[-1]
    saved = json.loads(state.read_text())["alarms"]
    assert (saved["rms/ch0"]["level"] if "rms/ch0" in saved else "normal") == last["alarm_level"], (saved, last)
