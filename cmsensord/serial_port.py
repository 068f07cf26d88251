"""Opening the board's serial port: exclusively, and one line saying why it did not open.

Every cmsensord reader of a port (the daemon's reader, its reopen after an unplug, ``record``,
``--simulate``) opens it with :func:`open_serial`: pyserial's ``exclusive`` lock (POSIX
``flock(LOCK_EX | LOCK_NB)``, on a pty too).  Two readers of one port would each read part of
the stream and each lose the frames the other read; the second opener is refused instead
(:func:`is_held`), and :func:`cannot_open` names the process holding the port, from
``/proc/locks``.  pyserial takes the lock before it changes the port's settings or discards
its input, so a refused open leaves the holder's stream whole.  The lock is advisory: a
program that does not lock the port (``cat``, ``screen``) is not kept out.
"""

from __future__ import annotations

import errno
import os
import termios

import serial

from cmsensord.errors import LinkError, bad_link

#: the errors of a lock another process holds (flock with LOCK_NB)
_HELD_ERRNOS = (errno.EAGAIN, errno.EWOULDBLOCK)
#: the longest command line of a holder shown
_CMDLINE_MAX = 80
#: what pyserial and the OS really raise when a port does not open or goes away
PORT_ERRORS = (serial.SerialException, OSError, termios.error)


def open_serial(port: str, baud: int, timeout: float) -> serial.Serial:
    """``port`` opened by pyserial and locked against every other cmsensord reader (see the
    module docstring); a port another process holds raises ``SerialException`` (:func:`is_held`)."""
    return serial.Serial(port, baud, timeout=timeout, exclusive=True)


def is_held(exc: BaseException | None) -> bool:
    """``exc``, an open's error, says another process holds the port's lock."""
    return isinstance(exc, serial.SerialException) and getattr(exc, "errno", None) in _HELD_ERRNOS


def open_port_checked(port: str, baud: int, *, held_hint: str = "") -> serial.Serial:
    """Open a serial port (:func:`open_serial`) or raise LinkError with a one-line reason and
    the fix; ``held_hint`` ends the line when another process holds the port."""
    if not os.path.exists(port):
        raise LinkError(f"{port}: {cannot_open(port, None)}")
    try:
        return open_serial(port, baud, timeout=0.1)
    except PORT_ERRORS as exc:
        raise LinkError(f"{port}: {cannot_open(port, exc)}{held_hint if is_held(exc) else ''}") from None


def cannot_open(port: str, exc: BaseException | None) -> str:
    """Why ``port`` did not open (``exc``: the error of the open), with the fix."""
    if not os.path.exists(port):
        link = bad_link(port, "the board's tty, e.g. /dev/ttyACM0")
        if link.startswith("a symlink loop"):
            return link
        return f"{link + ': ' if link else ''}no such device (is the board plugged in? check `ls /dev/tty*`)"
    if os.path.isdir(port):
        return "is a directory, not a serial port: give the board's tty, e.g. /dev/ttyACM0"
    if is_held(exc):
        return (f"held by another process{holder(port)}: two readers of one port each lose the "
                "frames the other reads")
    hint = (" (add the user to the dialout group)" if "ermission" in str(exc)
            else " (is it a serial port? give the board's tty, e.g. /dev/ttyACM0)"
            if "ioctl" in str(exc) else "")
    return f"cannot open: {why(exc) if exc is not None else 'no reason given'}{hint}"


def holder(port: str) -> str:
    """`` (pid N: its command line)`` of the process holding ``port``'s flock, as
    ``/proc/locks`` names it (the command line shortened to :data:`_CMDLINE_MAX` characters,
    its program by its base name); "" when it cannot be told (no /proc, the lock gone)."""
    try:
        st = os.stat(port)
        with open("/proc/locks", encoding="ascii", errors="replace") as f:
            lines = f.read().splitlines()
    except OSError:
        return ""
    where = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    for line in lines:
        fields = line.split()
        if len(fields) >= 6 and fields[1] == "FLOCK" and fields[5] == where and fields[4].isdigit():
            return f" (pid {fields[4]}{_command(fields[4])})"
    return ""


def _command(pid: str) -> str:
    """``: the command line`` of process ``pid`` (shortened), or "" when it cannot be read."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            argv = f.read().decode(errors="replace").split("\0")
    except OSError:
        return ""
    argv = [a for a in argv if a]
    if not argv:
        return ""
    text = " ".join([os.path.basename(argv[0]), *argv[1:]])
    return ": " + (text if len(text) <= _CMDLINE_MAX else text[:_CMDLINE_MAX - 3] + "...")


def why(exc: BaseException) -> str:
    """An OS error as ``ENAME strerror``; any other by its message (or its type's name)."""
    if isinstance(exc, OSError) and exc.errno is not None:
        return f"{errno.errorcode.get(exc.errno, exc.errno)} {exc.strerror}"
    return str(exc) or type(exc).__name__

