"""Fewer wake-ups of the serial reader at 1x (issue 13): the loop naming the block the reader
expects next does not wake it (it sleeps until that block is due), any other naming does; and
a burst larger than a tty's buffer is read in one step (the reader waits the fraction of a
millisecond the rest takes to come), not in two steps with a decoder call and a queue put
each."""

from __future__ import annotations

import fcntl
import os
import struct
import termios
import threading
import time

from cmsensord.link import TTY_READ_MAX, FrameQueue, SerialReader


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
