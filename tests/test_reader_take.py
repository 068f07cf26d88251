"""The reader reads a pyserial POSIX port's descriptor at once for the bytes the port shows
(link.take), not through pyserial's read (a select and a timeout before its one os.read): the
same bytes, and the same exceptions, word for word, when the port goes away; any other port
is read through its own read."""

from __future__ import annotations

import contextlib
import os
import pty
import tty

import pytest
import serial
import serial.serialposix

from cmsensord import link
from cmsensord.link import take


@pytest.fixture
def pty_port():
    master, slave = pty.openpty()
    tty.setraw(slave)
    ser = serial.Serial(os.ttyname(slave), 921600, timeout=0.05)
    os.close(slave)
    yield master, ser
    ser.close()
    with contextlib.suppress(OSError):
        os.close(master)


@pytest.fixture
def selects(monkeypatch) -> list:
    """The select calls of pyserial's read (on the port and its abort pipe)."""
    got: list = []
    real = serial.serialposix.select.select

    def select(*args):
        if len(args[0]) == 2:
            got.append(args)
        return real(*args)

    monkeypatch.setattr(serial.serialposix.select, "select", select)
    return got


def _wait_shown(ser, n: int) -> None:
    link.select.select([ser.fileno()], [], [], 1.0)
    for _ in range(1000):
        if ser.in_waiting >= n:
            return
        link.select.select([], [], [], 0.001)
    raise AssertionError("the pty did not show the bytes")


def test_the_bytes_shown_are_read_as_pyserial_reads_them_without_its_select(pty_port, selects):
    master, ser = pty_port
    data = bytes(range(256)) * 7
    for reader in (ser.read, lambda n: take(ser, n)):
        os.write(master, data)
        _wait_shown(ser, len(data))
        assert reader(ser.in_waiting) == data
    assert len(selects) == 1                    # pyserial's read only
    assert take(ser, 10) == b""                 # none there (another reader took them): none


def test_a_port_that_goes_away_raises_what_pyserial_raises(pty_port):
    master, ser = pty_port
    os.close(master)                            # hung up: the tty shows bytes and reads none
    with pytest.raises(serial.SerialException) as theirs:
        ser.read(1)
    with pytest.raises(serial.SerialException) as ours:
        take(ser, 1)
    assert str(ours.value) == str(theirs.value) and "no data" in str(ours.value)


def test_a_read_that_fails_raises_what_pyserial_raises(tmp_path):
    """A descriptor whose reads fail (a directory's: EISDIR) as a port's that fail."""
    ser = serial.Serial()
    fd = os.open(tmp_path, os.O_RDONLY)
    abort_r, abort_w = os.pipe()
    ser.fd, ser.pipe_abort_read_r, ser.is_open = fd, abort_r, True
    try:
        with pytest.raises(serial.SerialException) as theirs:
            ser.read(1)
        with pytest.raises(serial.SerialException) as ours:
            take(ser, 1)
        assert str(ours.value) == str(theirs.value) and "read failed" in str(ours.value)
    finally:
        ser.is_open = False
        for f in (fd, abort_r, abort_w):
            os.close(f)


def test_any_other_port_is_read_through_its_read(pty_port, monkeypatch):
    class Port:
        fd = None

        def read(self, n: int) -> bytes:
            return b"x" * n

    assert take(Port(), 3) == b"xxx"
    master, ser = pty_port                      # a pyserial port whose read is replaced (a wrapper)
    monkeypatch.setattr(serial.Serial, "read", lambda self, n=1: b"y" * n)
    os.write(master, b"abc")
    _wait_shown(ser, 3)
    assert take(ser, 3) == b"yyy"
