"""Fewer wake-ups of the serial reader at 1x (issue 13): the loop naming the block the reader
expects next does not wake it (it sleeps until that block is due), any other naming does; and
a burst larger than a tty's buffer is read in one step (the reader waits the fraction of a
millisecond the rest takes to come), not in two steps with a decoder call and a queue put
each.  A burst's reads ask for no more than the port shows; a port that fails part way
through a burst (unplugged) keeps the bytes read before, and a board that stops part way
(or a flow-control stall longer than the refill wait) ends the step with more to read."""

from __future__ import annotations

import errno
import fcntl
import io
import os
import struct
import termios
import threading
import time

import serial

from cmsensord.link import TTY_READ_MAX, TTY_REFILL_S, TTY_WRITE_CHUNK, FrameQueue, SerialReader
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


class PipePort:
    """The read end of a pipe as a port: a descriptor, bytes waiting by FIONREAD."""

    timeout = 0.05

    def __init__(self, fd: int):
        self.fd = fd

    def fileno(self) -> int:
        return self.fd

    @property
    def in_waiting(self) -> int:
        return struct.unpack("I", fcntl.ioctl(self.fd, termios.FIONREAD, b"\0\0\0\0"))[0]

    def read(self, n: int) -> bytes:
        return os.read(self.fd, n)


def test_a_burst_beyond_a_full_tty_buffer_is_read_in_one_step():
    r_fd, w_fd = os.pipe()
    try:
        reader = SerialReader("/dev/fake", baud=921600, read_size=4096, queue=FrameQueue(10))
        port = PipePort(r_fd)
        os.write(w_fd, b"a" * TTY_READ_MAX)     # a full tty buffer; the rest comes 1 ms later

        def rest():
            time.sleep(0.001)
            os.write(w_fd, b"b" * 1297)

        t = threading.Thread(target=rest)
        t.start()
        data, more = reader._read(port)
        t.join()
        assert data == b"a" * TTY_READ_MAX + b"b" * 1297 and not more
        os.write(w_fd, b"c" * TTY_READ_MAX)     # a full buffer and nothing after it
        t0 = time.monotonic()
        data, more = reader._read(port)
        assert data == b"c" * TTY_READ_MAX and more                 # more may wait: read again
        assert time.monotonic() - t0 < 0.05
        os.write(w_fd, b"d" * 100)              # a short read: nothing waited for
        assert reader._read(port) == (b"d" * 100, False)
    finally:
        os.close(r_fd)
        os.close(w_fd)


class StrictPort(PipePort):
    """A pipe port with pyserial's read: a read of more bytes than come waits for them, for
    ever here (a port opened without a timeout); asking for more than it shows is refused."""

    timeout = None

    def __init__(self, fd: int):
        super().__init__(fd)
        self.reads: list[int] = []

    def read(self, n: int) -> bytes:
        shown = self.in_waiting
        assert n <= shown, f"read({n}) of a port showing {shown}: it would wait for the rest"
        self.reads.append(n)
        return os.read(self.fd, n)


def _later(delay: float, fd: int, data: bytes) -> threading.Thread:
    def write():
        time.sleep(delay)
        os.write(fd, data)
    t = threading.Thread(target=write)
    t.start()
    return t


def test_a_burst_is_read_asking_for_no_more_than_the_port_shows():
    """A tty's full buffer, the rest 1 ms later, 4096-byte reads of a longer backlog: every
    read asks for what the port shows (a port without a timeout never waits in a read)."""
    r_fd, w_fd = os.pipe()
    try:
        reader = SerialReader("/dev/fake", baud=921600, read_size=4096, queue=FrameQueue(10))
        port = StrictPort(r_fd)
        os.write(w_fd, b"a" * TTY_READ_MAX)
        t = _later(0.001, w_fd, b"b" * 3 * 4096 + b"c" * 7)
        data, more = reader._read(port)
        t.join()
        assert data == b"a" * TTY_READ_MAX + b"b" * 3 * 4096 + b"c" * 7 and not more
        assert port.reads[0] == TTY_READ_MAX and sum(port.reads) == len(data), port.reads
    finally:
        os.close(r_fd)
        os.close(w_fd)


def test_a_board_that_stalls_longer_than_the_refill_wait_is_read_in_the_next_step():
    """The rest of the burst comes 40 ms after a full tty buffer (the board stopped, or its
    flow control held it): the step ends after the refill wait with more to read, and the
    next read takes the rest when it comes."""
    r_fd, w_fd = os.pipe()
    try:
        reader = SerialReader("/dev/fake", baud=921600, read_size=4096, queue=FrameQueue(10))
        port = PipePort(r_fd)
        port.timeout = 1.0
        os.write(w_fd, b"a" * TTY_READ_MAX)
        t = _later(0.04, w_fd, b"b" * 500)
        t0 = time.monotonic()
        assert reader._read(port) == (b"a" * TTY_READ_MAX, True)
        took = time.monotonic() - t0
        assert reader._read(port) == (b"b" * 500, False)
        t.join()
        assert TTY_REFILL_S <= took < 0.04
    finally:
        os.close(r_fd)
        os.close(w_fd)


def test_a_write_the_tty_hands_over_in_pieces_is_read_in_one_step():
    """A tty's writer hands a long write over 2 kB at a time: a read that took one piece waits
    the moment the next takes (one step for the write), a read of another size does not."""
    r_fd, w_fd = os.pipe()
    try:
        reader = SerialReader("/dev/fake", baud=921600, read_size=4096, queue=FrameQueue(10))
        port = PipePort(r_fd)
        os.write(w_fd, b"a" * TTY_WRITE_CHUNK)
        t = _later(0.001, w_fd, b"b" * 1000)
        assert reader._read(port) == (b"a" * TTY_WRITE_CHUNK + b"b" * 1000, False)
        t.join()
        os.write(w_fd, b"c" * 2047)
        t = _later(0.02, w_fd, b"d" * 1000)
        assert reader._read(port) == (b"c" * 2047, False)
        t.join()
        assert reader._read(port) == (b"d" * 1000, False)
    finally:
        os.close(r_fd)
        os.close(w_fd)


class UnpluggedPort(PipePort):
    """A pipe port unplugged after its first read: from then on it fails as a gone tty does."""

    def __init__(self, fd: int):
        super().__init__(fd)
        self.reads = 0

    @property
    def in_waiting(self) -> int:
        if self.reads:
            raise OSError(errno.EIO, "Input/output error")
        return super().in_waiting

    def read(self, n: int) -> bytes:
        self.reads += 1
        return super().read(n)

    def close(self) -> None:
        pass


def test_bytes_read_before_the_port_fails_mid_burst_are_decoded_and_captured_then_link_lost():
    """A reader thread on a port that fails right after a read of a full tty buffer of frames
    (unplugged part way through a burst): the frames of that read reach the queue and the
    capture, then link_lost is reported and the reader waits for the device to come back."""
    data = b"".join(encode_rms(i, i * 250, [1.0, 2.0, 3.0, 4.0]) for i in range(200))[:TTY_READ_MAX]
    r_fd, w_fd = os.pipe()
    os.write(w_fd, data)
    ports = [UnpluggedPort(r_fd)]

    def open_port():
        if not ports:
            raise serial.SerialException("could not open port /dev/fake: No such file or directory")
        return ports.pop()

    q, cap = FrameQueue(1000), io.BytesIO()
    reader = SerialReader("/dev/fake", baud=921600, read_size=4096, queue=q, capture=cap, open_port=open_port,
                          reconnect_min_s=0.05, reconnect_max_s=0.05)
    reader.start()
    try:
        deadline = time.monotonic() + 5.0
        while not reader.events and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        reader.stop()
        reader.join(timeout=2.0)
        os.close(r_fd)
        os.close(w_fd)
    assert [kind for _, kind, _ in reader.events][:1] == ["link_lost"]
    assert "/dev/fake: EIO Input/output error; reconnecting" in reader.events[0][2]
    assert cap.getvalue() == data
    whole = len(data) // len(encode_rms(0, 0, [1.0, 2.0, 3.0, 4.0]))
    assert [f.seq for f in q.get(timeout=0)] == list(range(whole))
