"""Fewer wake-ups of the serial reader at 1x: the loop naming the block the reader
expects next does not wake it (it sleeps until that block is due), any other naming does; and
a burst larger than a tty's buffer is read in one step (the reader waits the fraction of a
millisecond the rest takes to come), not in two steps with a decoder call and a queue put
each.  A burst's reads ask for no more than the port shows; a port that fails part way
through a burst (unplugged) keeps the bytes read before, and a board that stops part way
(or a flow-control stall longer than the refill wait) ends the step with more to read."""

from __future__ import annotations

import errno
import io
import os
import time

import pytest
import serial

from cmsensord import link
from cmsensord.frame_queue import FrameQueue
from cmsensord.link import TTY_READ_MAX, TTY_REFILL_S, SerialReader
from cmsensord.protocol import encode_rms


def test_naming_the_expected_block_does_not_wake_the_reader_naming_another_does():
    q = FrameQueue(100)
    q.expect = 7500
    q.wake_at(7500)                             # as expected: the reader sleeps on
    assert not q.named.is_set() and q.hint == 7500 and q.expect is None
    q.wake_at(7500)                             # again (the expectation is used once): wakes it
    assert q.named.is_set()
    q.named.clear()
    q.expect = 10000
    q.wake_at(9000)                             # another block (a decision's): wakes it
    assert q.named.is_set() and q.hint == 9000 and q.expect is None
    q.named.clear()
    q.expect = 10000
    q.wake_at(None)
    assert q.named.is_set()


def test_the_reader_expects_the_next_block_one_step_after_the_last_named():
    r = SerialReader("/dev/null", baud=921600, read_size=4096, queue=FrameQueue(10))
    assert r._expected(None) is None
    assert r._expected(2500) is None            # no step yet
    assert r._expected(5000) == 7500
    assert r._expected(5000) == 7500            # asked again for the same block
    assert r._expected(6000) == 7000            # the step follows the naming
    assert r._expected(100) == 1100             # a board clock gone back: the step is kept


class TtyPort:
    """A tty as the reader sees it, with no timing to it: its line discipline shows one piece
    of what came at a time (a full tty buffer, or a 2-kB piece of a long write); the next one
    that has come (:meth:`come`) moves in when the reader waits on the port's descriptor
    (``select`` is readable at once), and a wait with none come lasts its timeout.  Like
    pyserial's read, a read of more than it shows would wait for the rest: refused here."""

    timeout: float | None = 0.05

    def __init__(self, *pieces: bytes):
        self.shown, self.waiting = b"", list(pieces)
        self.came = len(pieces)
        self.reads: list[int] = []
        self.failing = False                      # unplugged: every call fails as a gone tty's
        self._ready, ready_w = os.pipe()          # readable: the next piece moved in
        os.write(ready_w, b"x")
        self._idle, self._idle_w = os.pipe()      # never readable
        self._fds = [self._ready, ready_w, self._idle, self._idle_w]
        self._next()

    def come(self, *pieces: bytes) -> None:
        self.waiting += pieces
        self.came += len(pieces)

    def _next(self) -> bool:
        if self.shown or not self.came:
            return False
        self.shown, self.came = self.waiting.pop(0), self.came - 1
        return True

    def fileno(self) -> int:
        self._check()
        return self._ready if self._next() else self._idle

    def _check(self) -> None:
        if self.failing:
            raise OSError(errno.EIO, "Input/output error")

    @property
    def in_waiting(self) -> int:
        self._check()
        return len(self.shown)

    def read(self, n: int) -> bytes:
        self._check()
        assert n <= len(self.shown), f"read({n}) of a port showing {len(self.shown)}: it would wait"
        self.reads.append(n)
        data, self.shown = self.shown[:n], self.shown[n:]
        return data

    def close(self) -> None:
        for fd in self._fds:
            os.close(fd)
        self._fds = []


@pytest.fixture
def waits(monkeypatch) -> list[float]:
    """The timeouts of the reader's waits on a port's descriptor (``select``), in order."""
    got: list[float] = []
    real = link.select.select

    def select(r, w, x, timeout):
        got.append(timeout)
        return real(r, w, x, timeout)

    monkeypatch.setattr(link.select, "select", select)
    return got


def test_a_burst_beyond_a_full_tty_buffer_is_read_in_one_step(waits):
    reader = SerialReader("/dev/fake", baud=921600, read_size=4096, queue=FrameQueue(10))
    port = TtyPort(b"a" * TTY_READ_MAX, b"b" * 1297)      # a full tty buffer, then the rest
    try:
        assert reader._read(port) == (b"a" * TTY_READ_MAX + b"b" * 1297, False)
        assert waits == [TTY_REFILL_S, 0.0]           # for the rest; then a look, no wait
        port.come(b"c" * TTY_READ_MAX)                    # a full buffer and nothing after it
        t0 = time.monotonic()
        assert reader._read(port) == (b"c" * TTY_READ_MAX, True)   # more may wait: read again
        assert time.monotonic() - t0 >= TTY_REFILL_S                # it waited for the rest
        port.come(b"d" * 100)                             # a short read: nothing waited for
        del waits[:]
        assert reader._read(port) == (b"d" * 100, False)
        assert waits == [port.timeout, 0.0]               # for its first byte; then a look
        assert port.reads == [TTY_READ_MAX, 1297, TTY_READ_MAX, 100]
    finally:
        port.close()


def test_a_burst_is_read_asking_for_no_more_than_the_port_shows():
    """A long backlog (a port with a larger buffer than a tty's) and a full tty buffer with
    the rest after it: 4096-byte reads of at most what the port shows (a port opened without a
    timeout never waits in a read)."""
    reader = SerialReader("/dev/fake", baud=921600, read_size=4096, queue=FrameQueue(10))
    port = TtyPort(b"a" * 10000)
    port.timeout = None
    try:
        assert reader._read(port) == (b"a" * 10000, False)
        port.come(b"b" * TTY_READ_MAX, b"c" * 7)
        assert reader._read(port) == (b"b" * TTY_READ_MAX + b"c" * 7, False)
        assert port.reads == [4096, 4096, 1808, TTY_READ_MAX, 7]
    finally:
        port.close()


def test_a_board_that_stalls_longer_than_the_refill_wait_is_read_in_the_next_step():
    """The rest of the burst has not come by the end of the refill wait after a full tty
    buffer (the board stopped, or its flow control held it): the step ends with more to
    read, and the next read takes the rest once it comes."""
    reader = SerialReader("/dev/fake", baud=921600, read_size=4096, queue=FrameQueue(10))
    port = TtyPort(b"a" * TTY_READ_MAX)
    try:
        assert reader._read(port) == (b"a" * TTY_READ_MAX, True)
        assert reader._read(port) == (b"", False)         # nothing within the port's timeout
        port.come(b"b" * 500)
        assert reader._read(port) == (b"b" * 500, False)
    finally:
        port.close()


def test_a_write_the_tty_hands_over_in_pieces_is_read_in_one_step(waits):
    """A tty's writer hands a long write over 2 kB at a time, and the tty moves each piece
    into its buffer a moment later: after a read that emptied the port, the reader looks once
    more without waiting (``select`` lets the tty move in what it holds), so the pieces in
    are one step; a piece not in yet is the next step's, not waited for."""
    reader = SerialReader("/dev/fake", baud=921600, read_size=4096, queue=FrameQueue(10))
    port = TtyPort(b"a" * 2048, b"a" * 2048, b"b" * 1000)
    try:
        assert reader._read(port) == (b"a" * 4096 + b"b" * 1000, False)
        assert waits == [0.0, 0.0, 0.0]
        port.come(b"c" * 1500)
        assert reader._read(port) == (b"c" * 1500, False)
        port.come(b"d" * 1000)
        assert reader._read(port) == (b"d" * 1000, False)
        assert waits == [0.0] * 3 + [port.timeout, 0.0] * 2     # each: its first byte, a look
    finally:
        port.close()


def test_bytes_read_before_the_port_fails_mid_burst_are_decoded_and_captured_then_link_lost():
    """A reader thread on a port that fails right after a read of a full tty buffer of frames
    (unplugged part way through a burst): the frames of that read reach the queue and the
    capture, then link_lost is reported and the reader waits for the device to come back."""
    data = b"".join(encode_rms(i, i * 250, [1.0, 2.0, 3.0, 4.0]) for i in range(200))[:TTY_READ_MAX]
    port = TtyPort(data, b"lost")

    def read(n: int, read=port.read) -> bytes:
        got = read(n)
        port.failing = True                             # unplugged right after this read
        return got

    port.read = read  # type: ignore[method-assign]
    ports = [port]

    def open_port():
        if not ports:
            raise serial.SerialException("could not open port /dev/fake: No such file or directory")
        return ports.pop()

    q, cap = FrameQueue(1000), io.BytesIO()
    reader = SerialReader("/dev/fake", baud=921600, read_size=4096, queue=q, capture=cap, open_port=open_port,
                          reconnect_min_s=0.05, reconnect_max_s=0.05)
    port_close = port.close
    port.close = lambda: None  # type: ignore[method-assign]
    reader.start()
    try:
        deadline = time.monotonic() + 5.0
        while not reader.events and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        reader.stop()
        reader.join(timeout=2.0)
        port_close()
    assert [kind for _, kind, _ in reader.events][:1] == ["link_lost"]
    assert "/dev/fake: EIO Input/output error; reconnecting" in reader.events[0][2]
    assert cap.getvalue() == data
    whole = len(data) // len(encode_rms(0, 0, [1.0, 2.0, 3.0, 4.0]))
    assert [f.seq for f in q.get(timeout=0)] == list(range(whole))
