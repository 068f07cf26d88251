"""The in-memory recording: physical samples in m/s², snapshots, optional tacho.

A :class:`Recording` is what every reader's output becomes before encoding:

* ``data``: float64 (channels, samples), m/s², every snapshot end to end;
* ``snapshots``: where each contiguous snapshot lies in ``data`` (start, length),
  which file (and which entry of it) it came from, and its time in the original
  recording where that is known;
* ``tacho_edges``: optional rising tacho edges as fractional sample indices into
  ``data`` (a pulse column), or ``rpm`` for edges synthesised at a constant speed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Snapshot", "Recording"]


@dataclass(frozen=True)
class Snapshot:
    """One contiguous stretch of samples: ``data[:, start:start + length]``."""

    source: str  # file name, with "[i]" for the i-th snapshot inside a file
    start: int
    length: int
    source_time_s: float | None = None  # its first sample's time in the original recording


@dataclass
class Recording:
    fs: int
    data: np.ndarray  # float64 (C, n), m/s^2
    names: list[str]
    snapshots: list[Snapshot]
    sources: list[str]
    source_unit: str = "m/s2"
    tacho_edges: np.ndarray | None = None  # float64 fractional sample indices into data
    tacho_source: str | None = None  # "column NAME" or "rpm"
    rpm: float | None = None
    rpm_source: str | None = None  # "--rpm" or the file it was read from
    ppr: int = 1
    notes: list[str] = field(default_factory=list)  # things the user should know (printed)
    source_start: str | None = None  # the date and time source_time_s counts from (ISO 8601), if known

    def __post_init__(self) -> None:
        if self.data.ndim != 2:
            raise ValueError(f"data must be (channels, samples), got shape {self.data.shape}")
        if len(self.names) != self.data.shape[0]:
            raise ValueError(f"{self.data.shape[0]} channels but {len(self.names)} names")
        end = sum(s.length for s in self.snapshots)
        if end != self.data.shape[1]:
            raise ValueError(f"the snapshots cover {end} samples, data holds {self.data.shape[1]}")

    @property
    def n_channels(self) -> int:
        return self.data.shape[0]

    @property
    def n_samples(self) -> int:
        return self.data.shape[1]
