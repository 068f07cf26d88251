"""A live daemon on a pty written here, at the board's pace: what a stall and a replug do.

* A board unplugged for 3 s and plugged back: its frames after ``link_restored`` are no
  ``link_stalled`` ("bytes but no valid frame") however long the unplug lasted.
"""

from __future__ import annotations

import os
import time
import tty
from pathlib import Path

import pytest

from cmsensord import __version__
from processes import start_daemon, stop
from test_link_faults import _opened
from test_stream_time import rms_run, status

pytestmark = pytest.mark.process

class PtyBoard:
    """A board on a pty published at ``link``: it sends whole blocks in real time, and can be
    unplugged (its pty closed, the name removed) and plugged back (a new pty, the same name)."""

    def __init__(self, link: Path):
        self.link = link
        self.seq, self.sent = 0, 0          # the next seq, and the blocks the board has made
        self.fed = bytearray()              # every byte written to the link
        self._open()

    def _open(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.name = os.ttyname(self.slave)
        self.link.symlink_to(self.name)

    def write(self, data: bytes) -> None:
        os.write(self.master, data)
        self.fed += data

    def blocks(self, seconds: float, before_last_s: float | None = None, extra: bytes = b"") -> None:
        """``seconds`` of RMS blocks (one channel, a STATUS first each second), 100 a second in real
        time; ``extra`` written ``before_last_s`` before the end."""
        start, n = time.monotonic(), round(100 * seconds)
        done = 0
        while done < n:
            due = min(n, int((time.monotonic() - start) * 100) + 1)
            if before_last_s is not None and done <= n - round(100 * before_last_s) < due:
                cut = n - round(100 * before_last_s)
                self._send(cut - done)
                self.write(extra)
                done = cut
            self._send(due - done)
            done = due
            time.sleep(0.02)

    def _send(self, k: int) -> None:
        out = bytearray()
        for _ in range(k):
            data, self.seq = rms_run(self.seq, [250 * self.sent], st=status() if self.sent % 100 == 0 else None)
            out += data
            self.sent += 1
        if out:
            self.write(bytes(out))

    def unplug(self, seconds: float) -> None:
        """Gone for ``seconds``: its clock runs on, the blocks of that time are lost."""
        os.close(self.master)
        os.close(self.slave)
        self.link.unlink()
        time.sleep(seconds)
        self.sent += round(100 * seconds)
        self.seq += round(100 * seconds)
        self._open()

    def close(self) -> None:
        os.close(self.master)
        os.close(self.slave)


def event_lines(err: str) -> list[str]:
    """The event lines of the daemon's stderr (not its settings line)."""
    return [line for line in err.splitlines()
            if line.startswith(("WARNING ", "INFO ")) and not line.startswith("INFO effective settings")]


@pytest.fixture
def board(tmp_path):
    b = PtyBoard(tmp_path / "ttyBOARD")
    yield b
    b.close()


def test_frames_after_a_replug_are_no_stall(tmp_path, board):
    """2 s of frames, 3 s unplugged, 3 s of frames: link_lost, link_restored, the frames lost, and no
    link_stalled.  Before: right after link_restored, "bytes but no valid frame for 3.2 s (wrong
    baud rate, or line noise?)", timed from the last frame before the unplug."""
    d = start_daemon(tmp_path, board.link)
    assert _opened(d, board.name, 30.0), "the daemon did not open the port"
    time.sleep(0.2)
    board.blocks(2.0)
    board.unplug(3.0)
    assert _opened(d, board.name, 30.0), "the daemon did not open the port again"
    time.sleep(0.2)
    board.blocks(3.0)
    time.sleep(0.5)
    err = stop(d)
    assert d.returncode == 0 and "Traceback" not in err, err
    lines = event_lines(err)
    assert lines[:3] == [f"INFO start: cmsensord {__version__} on {board.link}",
                         "INFO config: board firmware 1.2: RMS mode, 1 channel(s), fs 25000 Hz, block 250",
                         f"WARNING link_lost: {board.link}: EIO Input/output error; reconnecting"], lines
    assert lines[-1] == "INFO stop: cmsensord stopping (signal SIGTERM)", lines
    # the loop tells the reader's link_restored after the batch it came with: either comes first
    assert sorted(lines[3:-1]) == [f"INFO link_restored: {board.link} open again",
                                   "WARNING frames_lost: 300 frame(s) lost before seq 502 (seq gap)"], lines
