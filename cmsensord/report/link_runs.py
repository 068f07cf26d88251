"""The link counters of a report, summed over the runs its files hold, whatever their order.

Each ``/cm/diagnostics`` message carries the counters of its daemon run (a daemon start, a
replay, a simulation) since that run began. The total over the logs is the sum, over the runs,
of each run's last counters. A run is told by the ``run`` value of its files' ``cmsensord``
metadata (:func:`~cmsensord.service.sink.open_sink` writes one per run into every file):
files of one run (a rotation, a reopen) share it, however many there are and in whatever order
they are given. A file without it (written before there was one) starts a new run unless,
taking such files in the order of their first diagnostics, it continues the one before: the
same ``source``, and neither ``uptime_s`` nor ``bytes_received`` went back.

Only the counters of two diagnostics messages per file are kept (its first and its newest), so
memory does not grow with the length of the log.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["LinkRuns"]


#: a diagnostics message's link counters and queue drops
Counters = tuple[dict[str, float], float]
_Entry = tuple[float, float, int, Counters]     # (uptime_s, bytes_received, t_ns, its counters)


@dataclass
class _File:
    """The diagnostics of one file: its run (None: unknown), source, first and newest message."""

    run: str | None
    source: str
    first: _Entry | None = None
    last: _Entry | None = None


class LinkRuns:
    """Diagnostics file by file (:meth:`begin`, :meth:`add`); the totals over the runs (:meth:`totals`)."""

    def __init__(self) -> None:
        self._files: list[_File] = []

    def begin(self, metadata: dict[str, str]) -> None:
        """The next messages are of a file whose ``cmsensord`` metadata is ``metadata``."""
        run = metadata.get("run")
        self._files.append(_File(run or None, metadata.get("source", "")))

    def add(self, t_ns: int, uptime_s: float, received: float, counters: Counters) -> None:
        """One diagnostics message of the current file (its ``uptime_s``, ``bytes_received``, its
        link counters and queue drops)."""
        if not self._files:
            self.begin({})
        f = self._files[-1]
        entry = (uptime_s, received, t_ns, counters)
        if f.first is None:
            f.first = entry
        if f.last is None or entry[:2] >= f.last[:2]:
            f.last = entry

    def runs(self) -> list[Counters]:
        """The counters of the newest diagnostics message of each run."""
        newest: dict[tuple[str, str | int], _Entry] = {}
        legacy: list[tuple[_File, _Entry, _Entry]] = []
        for f in self._files:
            if f.first is None or f.last is None:
                continue
            if f.run is not None:
                _newest(newest, ("run", f.run), f.last)
            else:
                legacy.append((f, f.first, f.last))
        legacy.sort(key=lambda x: x[1][2])              # by the time of the first diagnostics
        key: tuple[str, str | int] = ("legacy", 0)
        for i, (f, first, last) in enumerate(legacy):
            if i == 0 or not _continues(legacy[i - 1], (f, first, last)):
                key = ("legacy", i)
            _newest(newest, key, last)
        return [entry[3] for entry in newest.values()]

    def totals(self) -> tuple[dict[str, int], int, int]:
        """(link counters, queue drops, runs) summed over the runs."""
        link: dict[str, int] = {}
        drops = 0
        runs = self.runs()
        for counters, dropped in runs:
            for k, v in counters.items():
                link[k] = link.get(k, 0) + int(v)
            drops += int(dropped)
        return link, drops, len(runs)


def _newest(newest: dict[tuple[str, str | int], _Entry], key: tuple[str, str | int], entry: _Entry) -> None:
    if key not in newest or entry[:2] >= newest[key][:2]:
        newest[key] = entry


def _continues(before: tuple[_File, _Entry, _Entry], after: tuple[_File, _Entry, _Entry]) -> bool:
    """Whether the file ``after`` (no run in its metadata) goes on with the run of ``before``:
    the same source, and its first uptime_s and bytes_received not below the newest of ``before``."""
    (f0, _, last), (f1, first, _) = before, after
    return f0.source == f1.source and first[0] >= last[0] and first[1] >= last[1]
