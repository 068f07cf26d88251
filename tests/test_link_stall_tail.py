"""A live daemon on a pty written here, at the board's pace: what a stall and a replug do.

* A board that stops 1 s after line noise made a header claiming 4000 bytes: at the stall the
  daemon gives that candidate up (a CRC failure) and decodes the second of frames behind it,
  and the ``--capture`` file holds every byte, before anything stops the daemon (it is killed
  with SIGKILL, which finishes nothing).
* A board unplugged for 3 s and plugged back: its frames after ``link_restored`` are no
  ``link_stalled`` ("bytes but no valid frame") however long the unplug lasted.
"""

from __future__ import annotations

import os
import signal
import struct
import time
import tty
from pathlib import Path

import pytest

from cmsensord import __version__
from cmsensord.sinks.mcap_sink import read_messages
from processes import start_daemon, stop
from test_link_faults import _opened
from test_stream_time import rms_run, status

pytestmark = pytest.mark.process

#: a header line noise made: sync, version 1, type RMS, len 4000, and no frame behind it
NOISE_HEADER = b"\xa5\x5a\x01\x02\x00\x00\x00\x00\x00\x00\x02\x00" + struct.pack("<H", 4000)


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


def test_a_stall_after_a_noise_header_reports_the_frames_behind_it_before_any_stop(tmp_path, board):
    """3 s of frames, the noise header 1 s before their end, then silence: 4 s later the log (read
    after SIGKILL) has an observation of every frame and counts one CRC failure, and the capture
    file is every byte fed, and link_stalled says no bytes came.  Before: the 100 frames behind the
    candidate waited in the decoder for the 4000 bytes it claimed (200 of 300 observations, and
    "bytes but no valid frame for 2.2 s"), and the capture file lacked its last 2178 bytes (its
    buffer's)."""
    d = start_daemon(tmp_path, board.link, "--capture", str(tmp_path / "cap.bin"))
    assert _opened(d, board.name, 30.0), "the daemon did not open the port"
    time.sleep(0.2)                         # pyserial discards what waits at its open
    board.blocks(3.0, before_last_s=1.0, extra=NOISE_HEADER)
    time.sleep(4.0)
    d.send_signal(signal.SIGKILL)
    _, err = d.communicate(timeout=10)
    assert f"WARNING link_stalled: {board.link}: no bytes for 2 s" in event_lines(err), err
    diag = [m for t, _, m in read_messages(next((tmp_path / "logs").glob("*.mcap.part")), lenient=True)
            if t == "/cm/diagnostics"]
    assert (diag[-1]["observations"], diag[-1]["link"]["crc_failures"]) == (300, 1), diag[-1]
    assert (tmp_path / "cap.bin").read_bytes() == board.fed


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
