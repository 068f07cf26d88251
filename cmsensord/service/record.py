"""``cmsensord record``: the bytes of a serial port into a capture file (docs/PROTOCOL.md).

The port is opened exclusively (:mod:`cmsensord.serial_port`): a port another process reads
(the daemon, another ``record``) is refused with one line naming that process, as two readers
would each lose the frames the other read.  The frames lost in seq gaps (docs/PROTOCOL.md
rule 3, counted by the decoder) are on every status line and on the last one, so a capture
missing frames says so.
"""

from __future__ import annotations

import sys
import time

from cmsensord.errors import LinkError
from cmsensord.out_paths import out_file_refused
from cmsensord.protocol import LinkCounters
from cmsensord.serial_port import open_port_checked
from cmsensord.service.signals import StopFlag
from cmsensord.source import SerialSource

#: what ``record`` says after the line of a port another process holds
HELD_HINT = ("; stop it first, or, if it is the daemon, use its captures (`cmsensord capture-now`, "
             "or its --capture FILE for the port's bytes)")


def record(port: str, out: str, *, baud: int, duration_s: float | None) -> int:
    """Capture the bytes of ``port`` to ``out`` until ``duration_s``, a signal, or the port goes
    away; a status line per second says what is being captured, and the last line what was.
    Exit status 1 when the capture file could not be written (a full disk): the last line says so."""
    refused = out_file_refused(out, "capture.bin")
    if refused:
        raise LinkError(refused)
    ser = open_port_checked(port, baud, held_hint=HELD_HINT)    # LinkError, nothing written
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
    failed: str | None = None
    try:
        with source:
            for _ in source:                    # the frames only feed the counters shown
                if stop.event.is_set() or (duration_s is not None and time.monotonic() - t0 >= duration_s):
                    break
                failed, lost = _lost(source)
                if lost:
                    break
                if time.monotonic() >= next_status:
                    next_status += 1.0
                    print(f"recorded {_tally(source.counters)}", file=sys.stderr, flush=True)
            source.stop()
    finally:
        try:
            f.close()                           # its buffered bytes written: a full disk says so here too
        except OSError as exc:
            failed = failed or f"capture file: {exc.strerror or exc}"
    c = source.counters
    if failed is not None:
        print(f"capture: {out} ({_tally(c)}); incomplete: {failed} (the bytes before it are in the file; "
              "free space or give another --out, and record again)", file=sys.stderr)
        return 1
    print(f"capture: {out} ({_tally(c)})"
          + ("; incomplete: frames the board sent are missing (another program reading the port, "
             "or a link losing bytes?)" if c.frames_lost else ""), file=sys.stderr)
    return 0


def _tally(c: LinkCounters) -> str:
    """``N B, N frames, crc errors N, N frames lost (seq gaps)``: what the decoder counted."""
    return (f"{c.bytes_received} B, {sum(c.frames.values())} frames, crc errors {c.crc_failures}, "
            f"{c.frames_lost} frames lost (seq gaps)")


def _once(ser):
    """The already opened port the first time; a port that went away is not reopened."""
    ports = [ser]

    def open_port():
        if ports:
            return ports.pop()
        raise OSError("port went away")
    return open_port


def _lost(source: SerialSource) -> tuple[str | None, bool]:
    """The port went away or the capture file cannot be written: say so and stop (True); the
    capture file's error, if that is why."""
    for _, kind, message in list(source.events):
        if kind in ("link_lost", "disk_error"):
            why = message.split("; ")[0]
            print(f"cmsensord record: {why}; stopping", file=sys.stderr)
            return (why if kind == "disk_error" else None), True
    return None, False
