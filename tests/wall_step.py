"""``python tests/wall_step.py WHEN STEP_S ARGS``: ``cmsensord ARGS`` whose wall clock
(``time.time``, ``time.time_ns``) steps by STEP_S seconds (negative: back) once, as an NTP
sync steps a board's clock; the monotonic clock does not step. WHEN: seconds on the
monotonic clock from the start, or ``N@PATTERN``: once N files match the glob PATTERN
(checked every 0.1 s)."""

from __future__ import annotations

import glob
import sys
import time

when, step_ns = sys.argv[1], int(float(sys.argv[2]) * 1e9)
del sys.argv[1:3]
_time_ns, _monotonic = time.time_ns, time.monotonic
_start = _monotonic()
_state = {"stepped": False, "checked": -1.0}


def _due() -> bool:
    now = _monotonic()
    try:
        return now - _start >= float(when)
    except ValueError:
        pass
    if now - _state["checked"] < 0.1:
        return False
    _state["checked"] = now
    n, pattern = when.split("@", 1)
    return len(glob.glob(pattern)) >= int(n)


def _stepped_ns() -> int:
    if not _state["stepped"] and _due():
        _state["stepped"] = True
    return _time_ns() + (step_ns if _state["stepped"] else 0)


time.time_ns = _stepped_ns
time.time = lambda: _stepped_ns() / 1e9

from cmsensord.cli import main  # noqa: E402  (after the clock is replaced)

sys.exit(main())
