"""``cmsensord record``: the bytes of a serial port into a capture file (docs/PROTOCOL.md)."""

from __future__ import annotations

import sys
import time

from cmsensord.errors import LinkError
from cmsensord.link import open_port_checked
from cmsensord.service.signals import StopFlag
from cmsensord.source import SerialSource


def record(port: str, out: str, *, baud: int, duration_s: float | None) -> int:
    """Capture the bytes of ``port`` to ``out`` until ``duration_s``, a signal, or the port goes
    away; a status line per second says what is being captured."""
    ser = open_port_checked(port, baud)     # a missing or wrong device: LinkError, nothing written
    try:
        f = open(out, "wb")
    except OSError as exc:
        ser.close()
        raise LinkError(f"{out}: cannot write capture: {exc.strerror or exc}") from None
    stop = StopFlag()
    stop.install()
    source = SerialSource(port, baud=baud, capture=f, open_port=_once(ser))
    t0 = time.monotonic()
    next_status = t0 + 1.0
    with f, source:
        for _ in source:                    # the frames only feed the counters shown
            if stop.event.is_set() or (duration_s is not None and time.monotonic() - t0 >= duration_s):
                break
            if _lost(source):
                break
            if time.monotonic() >= next_status:
                next_status += 1.0
                c = source.counters
                print(f"recorded {c.bytes_received} B, {sum(c.frames.values())} frames, "
                      f"crc errors {c.crc_failures}", file=sys.stderr, flush=True)
        source.stop()
    print(f"capture: {out} ({source.counters.bytes_received} bytes)", file=sys.stderr)
    return 0


def _once(ser):
    """The already opened port the first time; a port that went away is not reopened."""
    ports = [ser]

    def open_port():
        if ports:
            return ports.pop()
        raise OSError("port went away")
    return open_port


def _lost(source: SerialSource) -> bool:
    """The port went away or the capture file cannot be written: say so and stop."""
    for _, kind, message in list(source.events):
        if kind in ("link_lost", "disk_error"):
            print(f"cmsensord record: {message.split('; ')[0]}; stopping", file=sys.stderr)
            return True
    return False
