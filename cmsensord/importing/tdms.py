"""TDMS reader: National Instruments' files (LabVIEW, DAQExpress, FlexLogger), with the
optional ``tdms`` extra (npTDMS).

Every numeric channel of the file's groups is a column, named by the channel (``group.channel``
where two groups name a channel alike). A waveform channel says its own rate and start:
``wf_increment`` (seconds a sample) gives fs, ``wf_start_time`` the file's snapshot time, so a
logger's directory of one file per snapshot needs neither ``--fs`` nor ``--snapshot-interval``.
TDMS stores that time in UTC; it is taken in this computer's local time (``TZ`` sets another
zone), as LabVIEW and the logger show it and as the other formats' dates are read, with a
note. Channels shorter than the longest (a temperature logged beside the
vibration) are left out with a note, except the speed column (``--speed-column``), which is
taken to span the same time (:func:`~.variables.stretched`). The channels are read a stretch
at a time as the import converts them (:class:`~.columns.Columns`), not whole.
"""

from __future__ import annotations

import logging
from contextlib import contextmanager
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np

from .columns import Columns
from .errors import ImportFailure
from .table import Table
from .time_column import whole_hz
from .variables import stretched

__all__ = ["read_tdms"]


def read_tdms(path: str, slow: str | None = None) -> Table:
    """The file's numeric channels side by side (``slow``: the speed column's name), its rate and
    start from the first full-length channel's waveform properties (see module docstring)."""
    try:
        from nptdms import TdmsFile
    except ImportError:
        raise ImportFailure(f"{path}: reading TDMS files needs npTDMS: pip install 'cmsensord[tdms]'") from None
    said: list[str] = []        # what npTDMS logged of the file (a cut-short segment, a bad version)
    try:
        with _heard(said):
            f = TdmsFile.open(path)      # the channels' data is read later, a stretch at a time
    except Exception as exc:  # npTDMS raises what the bytes make it (ValueError, KeyError, struct.error, ...)
        why = " ".join(str(exc).split()) or type(exc).__name__
        raise ImportFailure(f"{path}: not a readable TDMS file ({why}); export it again from LabVIEW, or as CSV") \
            from None
    try:
        return _table(path, f, slow, said)
    except BaseException:
        f.close()
        raise


def _table(path: str, f, slow: str | None, said: list[str]) -> Table:
    """The Table of the open file ``f`` (its channels read when the import asks; closed with ``data.close``)."""
    chans = [(g.name, c.name, c.properties, c) for g in f.groups() for c in g.channels()
             if _numeric(c) and len(c) > 1]
    if not chans:
        why = f"not a readable TDMS file ({said[0]})" if said else "no numeric channel in the file"
        raise ImportFailure(f"{path}: {why}; export it again from LabVIEW, or as CSV")
    plain = [name for _, name, _, _ in chans]
    names = [name if plain.count(name) == 1 else f"{g}.{name}" for g, name, _, _ in chans]
    n = max(len(c) for _, _, _, c in chans)
    keep = [k for k, (_, _, _, c) in enumerate(chans) if len(c) == n or (names[k] == slow and len(c) < n)]
    left = [f"{names[k]} ({len(c)})" for k, (_, _, _, c) in enumerate(chans) if k not in keep]
    data = Columns([_reader(chans[k][3], n, said) for k in keep], n, np.dtype(np.float64), close=f.close)
    first = next(props for _, _, props, c in chans if len(c) == n)
    note = f"channel(s) {', '.join(left)} hold fewer samples than the others' {n}: not imported" if left else None
    start = first.get("wf_start_time")
    times, zone = None, None
    if isinstance(start, np.datetime64) and not np.isnat(start):
        utc = (start.astype("datetime64[us]") - np.datetime64(0, "us")).astype(np.float64) / 1e6
        local, zone = _local(utc)
        times = np.array([local])
    units = [u if isinstance(u := chans[k][2].get("unit_string"), str) else None for k in keep]
    return Table(path=path, data=data, columns=[names[k] for k in keep], kind="channel", fs=_fs(first), units=units,
                 times=times, dated=times is not None, layout_note=note, time_note=zone and (
                     f"the files' start times (wf_start_time) are UTC: taken in this computer's local time "
                     f"({zone}), as LabVIEW shows them; TZ=Area/City sets another zone"),
                 notes=[f"{Path(path).name}: npTDMS: {said[0]}; the channels' samples there are imported"] if said
                 else [])


class _Heard(logging.Handler):
    def __init__(self, said: list[str]):
        super().__init__(logging.WARNING)
        self.said = said

    def emit(self, record: logging.LogRecord) -> None:
        self.said.append(record.getMessage())


@contextmanager
def _heard(said: list[str]):
    """npTDMS's warnings (it prints them to stderr itself) into ``said`` instead."""
    from nptdms.log import log_manager

    saved = [(log, log.propagate, list(log.handlers)) for log in log_manager.loggers.values()]
    for log, _, _ in saved:
        log.handlers, log.propagate = [_Heard(said)], False
    try:
        yield
    finally:
        for log, propagate, handlers in saved:
            log.handlers, log.propagate = handlers, propagate


def _numeric(channel) -> bool:
    """Whether a channel holds numbers (not times or text), from its type, without reading it."""
    try:
        return np.dtype(channel.dtype).kind in "iuf"
    except TypeError:
        return False


def _reader(channel, n: int, said: list[str]):
    """Samples a..b of a channel, float64 (read then; npTDMS's warnings into ``said``); a slower
    one (a speed column with fewer samples) read whole, interpolated to ``n`` over the same time."""
    if len(channel) != n:
        with _heard(said):
            x = stretched(np.asarray(channel[:], dtype=np.float64)[None, :, None], n)[0, :, 0]
        return lambda a, b: x[a:b]

    def read(a: int, b: int) -> np.ndarray:
        with _heard(said):
            return np.asarray(channel.read_data(a, b - a), dtype=np.float64)
    return read


def _fs(properties: dict) -> float | None:
    """1 / the waveform's ``wf_increment``, when it has one that is a time step."""
    try:
        inc = float(properties["wf_increment"])
    except (KeyError, TypeError, ValueError):
        return None
    return whole_hz(1.0 / inc) if np.isfinite(inc) and inc > 0 else None


def _local(utc_s: float) -> tuple[float, str]:
    """The local wall-clock reading of a UTC time, as seconds counted like the naive dates of the
    other formats, and the zone (``CET, UTC+01:00``)."""
    at = datetime.fromtimestamp(utc_s, timezone.utc).astimezone()
    offset = at.utcoffset() or timedelta(0)
    sign, mins = ("-" if offset < timedelta(0) else "+"), abs(int(offset.total_seconds())) // 60
    name = at.tzname() or ""
    plain = f"UTC{sign}{mins // 60:02d}:{mins % 60:02d}"
    return utc_s + offset.total_seconds(), name if name == "UTC" and not mins else f"{name}, {plain}"
