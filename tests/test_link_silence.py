"""A silent link is no slow board clock: live, with ``link.max_drift_s`` at its default, a
link that says nothing for a while (a stalled reader, a USB cable pulled and put back) and
then brings what the board kept starts no ``time_base`` segment, and the stamps stay on the
wall clock.  Guards against the drift check measuring the board's rate over the silence
(``board clock behind the wall clock by 11.0 s (it runs at 8817 Hz for fs 25000 Hz)``), stamping
the frames after it at that rate and running ahead (``ahead of the wall clock by 42.7 s``; a 40-s
silence: 523 s), catching up 10 % of the wall time, for hours."""

from __future__ import annotations

import os
import re
import signal
import time

import pytest

from cmsensord import __version__
from cmsensord.sinks.mcap_sink import read_messages
from processes import start_board, start_daemon, stop
from test_link_faults import _opened
from test_stream_time import rms_run, status

pytestmark = pytest.mark.process

S = 1_000_000_000


def warnings_and_infos(err: str) -> list[str]:
    """The event lines of the daemon's stderr (not its settings line)."""
    return [line for line in err.splitlines()
            if line.startswith(("WARNING ", "INFO ")) and not line.startswith("INFO effective settings")]


def test_a_board_silent_for_12_s_keeps_its_stamps_on_the_wall_clock(tmp_path):
    """The simulated board (real time, RMS) streams 6 s, is stopped (SIGSTOP) 12 s and goes on:
    its clock ran on, so it sends the 12 s it owes as fast as it can (the pty drops what does
    not fit: a seq gap, then its t0 at the present).  The daemon says the link stalled, counts
    the frames lost, re-anchors the slots at the t0 jump, and nothing else: no time_base
    event, and its last stamp is the wall clock when it stops."""
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", "--link", str(link))
    d = start_daemon(tmp_path, link, max_drift_s=2.0)
    try:
        time.sleep(6.0)
        sim.send_signal(signal.SIGSTOP)
        time.sleep(12.0)
        sim.send_signal(signal.SIGCONT)
        time.sleep(10.0)
        term = time.time_ns()
        err = stop(d)
    finally:
        sim.send_signal(signal.SIGCONT)
        sim.terminate()
        sim.wait(timeout=5)
    assert d.returncode == 0 and "Traceback" not in err, err
    lines = warnings_and_infos(err)
    assert [line for line in lines if "time_base" in line] == [], lines
    assert lines[:3] == [f"INFO start: cmsensord {__version__} on {link}",
                         "INFO config: board firmware 1.0: RMS mode, 1 channel(s), fs 25000 Hz, block 250",
                         f"WARNING link_stalled: {link}: no bytes for 2 s"], lines
    assert lines[-1] == "INFO stop: cmsensord stopping (signal SIGTERM)", lines
    for line in lines[3:-1]:                # what the pty dropped of the 12 s the board owed
        assert re.fullmatch(r"WARNING frames_lost: \d+ frame\(s\) lost before seq \d+ \(seq gap\)"
                            r"|INFO config: board clock jumped [0-9.]+ s ahead \(t0 \d+ after \d+\): time base "
                            r"re-anchored",
                            line), lines
    msgs = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    decisions = [s for t, s, _ in msgs if t.endswith("/severity")]
    assert abs(decisions[-1] - term) < 3 * S, (decisions[-1] - term) / S     # the last is up to 1 s old
    assert abs(max(s for _, s, _ in msgs) - term) < 2 * S, (max(s for _, s, _ in msgs) - term) / S


def test_a_backlog_coming_in_over_more_than_5_s_after_a_silence_is_no_drift(tmp_path):
    """Live on a pty written here: a board (RMS) sends in real time for 3 s, then nothing for 7 s
    while its clock runs on and it keeps its blocks, then sends what it kept at 1.5 times real
    time until it has caught up (14 s), then in real time.  While the backlog comes in its
    stamps are behind the wall clock, more than 2 s for over 6 s, but on their way back: no
    time_base event, and every stamp is the board's t0 on the first frame's anchor.  Guards
    against ``behind by 6.9 s`` at the first look after the silence and, measuring the rate only
    from there on, still ``behind by 3.9 s (it runs at 37416 Hz for fs 25000 Hz)`` 6 s later."""
    master, slave = os.openpty()
    port = os.ttyname(slave)
    d = start_daemon(tmp_path, port, max_drift_s=2.0)
    try:
        assert _opened(d, port, 30.0), "the daemon did not open the port"
        time.sleep(0.2)                     # pyserial discards what waits at its open
        start, seq, sent = time.monotonic(), 0, 0
        while (e := time.monotonic() - start) < 26.0:
            owed = e if e < 3.0 else 3.0 if e < 10.0 else min(e, 3.0 + 1.5 * (e - 10.0))
            n = int(owed * 100) - sent      # whole blocks of 250 samples, 100 a second
            if n > 0:
                data, seq = rms_run(seq, [250 * (sent + k) for k in range(n)], st=status() if not sent else None)
                os.write(master, data)
                sent += n
            time.sleep(0.05)
        term = time.time_ns()
        err = stop(d)
    finally:
        os.close(master)
        os.close(slave)
    assert d.returncode == 0 and "Traceback" not in err, err
    lines = warnings_and_infos(err)
    assert lines == [f"INFO start: cmsensord {__version__} on {port}",
                     "INFO config: board firmware 1.2: RMS mode, 1 channel(s), fs 25000 Hz, block 250",
                     f"WARNING link_stalled: {port}: no bytes for 2 s",
                     "INFO stop: cmsensord stopping (signal SIGTERM)"], lines
    msgs = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    decisions = [s for t, s, _ in msgs if t.endswith("/severity")]
    assert len(decisions) == 25                 # one a second of the board's 26 s, the last incomplete
    first = decisions[0]
    assert [s - first for s in decisions] == [k * S for k in range(25)]     # on the board's clock
    assert abs(decisions[-1] - term) < 3 * S, (decisions[-1] - term) / S


def test_a_daemon_frozen_while_the_board_sends_says_no_stall(tmp_path):
    """The daemon's whole process frozen (SIGSTOP/SIGCONT: a paused VM, a machine stuck on swap)
    three times for 2.5 s while the simulated board (real time) goes on sending: what it sent
    waits in the port, and the daemon reads it when it runs again.  No event but the start, the
    board's config and the stop; the decisions go on a second apart on the board's clock.
    Guards against ``link_stalled: ...: no bytes for 2 s`` at nearly every thaw, the loop
    judging the link before the reader had read again."""
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", "--link", str(link))
    d = start_daemon(tmp_path, link, max_drift_s=2.0)
    try:
        time.sleep(5.0)
        for _ in range(3):
            d.send_signal(signal.SIGSTOP)
            time.sleep(2.5)
            d.send_signal(signal.SIGCONT)
            time.sleep(1.5)
        err = stop(d)
    finally:
        d.send_signal(signal.SIGCONT)
        sim.terminate()
        sim.wait(timeout=5)
    assert d.returncode == 0 and "Traceback" not in err, err
    assert warnings_and_infos(err) == [f"INFO start: cmsensord {__version__} on {link}",
                                       "INFO config: board firmware 1.0: RMS mode, 1 channel(s), fs 25000 Hz, "
                                       "block 250",
                                       "INFO stop: cmsensord stopping (signal SIGTERM)"], err
    msgs = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    decisions = [s for t, s, _ in msgs if t.endswith("/severity")]
    assert len(decisions) >= 13 and [b - a for a, b in zip(decisions, decisions[1:])] == [S] * (len(decisions) - 1)
