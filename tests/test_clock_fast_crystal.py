"""A board whose crystal runs fast, live: one ``time_base`` event when its clock is ahead of the
wall clock by more than ``link.max_drift_s``, then stamps that catch up and stay on the wall
clock (tests/test_clock_drift.py drives the clock by hand over hours of such a board)."""

from __future__ import annotations

import re
import subprocess
import sys
import time

import pytest

from cmsensord.sinks.mcap_sink import read_messages
from processes import ENV, spawn, start_daemon, stop
from test_link_faults import _opened
from test_link_silence import warnings_and_infos

pytestmark = pytest.mark.process

S = 1_000_000_000


def test_a_fast_board_is_re_anchored_once_and_never_said_to_be_behind(tmp_path):
    """The simulated board at 1.2 x real time from the moment the daemon has its port open,
    ``max_drift_s: 1``: ahead by ~1 s at the first look that measures its rate (5 s),
    re-anchored, its stamps 10 % slower until they meet the wall clock (~11 s later), then at its
    measured rate.  One time_base line, ahead; the decisions' stamps go on ~0.8 s apart, never a
    jump, and end on the wall clock.  Guards against the catch-up going on past the wall clock:
    ``board clock behind the wall clock by 1.0 s`` ~11 s after it met it, with a jump of the
    stamps by that second, and against the wall clock on the stream's time base staying ahead by
    the drift once the stamps met the wall clock: ``stop`` stamped ~1 s after the daemon stopped.
    The first frame is stamped when the loop handles it, as a replay stamps it: ahead by the
    board's ~1 s and that delay (0.1-0.9 s on a loaded 2-core machine at the daemon's start).
    The rate is 30000 Hz measured over at least 5 s of wall clock from when the newest frame
    read at the first frame's handling came, each end of it a read or a look up to ~75 ms late
    on a loaded machine: within 3 %, 29100-30899 Hz, and the catch-up's stamps 25000 / (1.1 x
    that) = 0.74-0.78 s apart.  Guards against the rate measured from the first frame's handling:
    34700 Hz at a 0.8-s delay, the catch-up's stamps 0.655 s apart."""
    sim = spawn([sys.executable, "-m", "firmware_sim", "--pty", "--hold", "--start-on-stdin",
                 "--scenario", "healthy", "--speed", "1.2"],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=ENV)
    try:
        port = sim.stdout.readline().strip()
        d = start_daemon(tmp_path, port, max_drift_s=1.0)
        assert _opened(d, port, 30.0), "the daemon did not open the port"
        time.sleep(0.2)                     # pyserial discards what waits at its open
        sim.stdin.write("\n")
        sim.stdin.flush()
        time.sleep(33.0)
        term = time.time_ns()
        err = stop(d)
        done = time.time_ns()
    finally:
        sim.terminate()
        sim.wait(timeout=5)
    assert d.returncode == 0 and "Traceback" not in err, err
    lines = [line for line in warnings_and_infos(err) if "time_base" in line]
    assert len(lines) == 1 and re.fullmatch(
        r"WARNING time_base: board clock ahead of the wall clock by (1\.\d|2\.0) s \(it runs at "
        r"(29[1-9]|30[0-8])\d\d Hz for fs 25000 Hz\): time segment 1 re-anchored to the wall clock", lines[0]), lines
    msgs = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    decisions = [s for t, s, _ in msgs if t.endswith("/severity")]
    steps = [round((b - a) / S, 3) for a, b in zip(decisions, decisions[1:])]
    assert len(decisions) > 35 and 0.7 < min(steps) and max(steps) < 1.05, \
        f"{len(decisions)} decisions, steps " + ", ".join(map(str, steps))
    assert abs(decisions[-1] - term) < 1.5 * S, (decisions[-1] - term) / S
    [stopped] = [s for t, s, m in msgs if t == "/cm/events" and m["kind"] == "stop"]
    assert term - 0.1 * S <= stopped <= done + 0.3 * S, ((stopped - term) / S, (done - term) / S)
