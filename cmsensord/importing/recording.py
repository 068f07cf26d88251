"""The recording read from the files: physical samples in m/s², snapshots, optional tacho.

A :class:`Recording` is what every reader's output becomes before encoding:

* ``samples``: m/s² (a microphone's Pa: :attr:`Recording.units`), every snapshot end to
  end, in memory up to a bound and beyond it on disk (:class:`~.samples.SampleStore`);
* ``snapshots``: where each contiguous snapshot lies in ``samples`` (start, length),
  which file (and which entry of it) it came from, and its time in the original
  recording where that is known;
* ``tacho_edges``: optional tacho edges as fractional sample indices into ``samples``
  (a pulse column's rising crossings, or a speed column's revolutions), or ``rpm`` for
  edges synthesised at a constant speed;
* ``dc``: each snapshot's mean per channel, which the capture writer subtracts (:mod:`.dc`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .samples import SampleStore
from .units import physical_unit

__all__ = ["Snapshot", "Recording"]


@dataclass(frozen=True)
class Snapshot:
    """One contiguous stretch of samples: ``samples.read(start, start + length)``."""

    source: str  # file name, with "[i]" for the i-th snapshot inside a file
    start: int
    length: int
    source_time_s: float | None = None  # its first sample's time in the original recording


@dataclass
class Recording:
    fs: int
    samples: SampleStore  # m/s^2
    names: list[str]
    snapshots: list[Snapshot]
    sources: list[str]
    source_units: list[str] = field(default_factory=list)  # each channel's unit in the files ([]: m/s2)
    tacho_edges: np.ndarray | None = None  # float64 fractional sample indices into samples
    tacho_source: str | None = None  # the pulse or speed column's name, or "rpm"
    tacho_from: str | None = None  # "pulses" (a pulse column), "speed" (a speed column) or "rpm" (constant)
    rpm: float | None = None
    rpm_source: str | None = None  # "--rpm" or the file it was read from
    rpm_differs: bool = False  # the files gave speeds more than 1 % apart (rpm is the first's)
    ppr: int = 1
    notes: list[str] = field(default_factory=list)  # things the user should know (printed)
    source_start: str | None = None  # the date and time source_time_s counts from (ISO 8601), if known
    dc: np.ndarray | None = None  # (snapshots, channels): each snapshot's mean, subtracted (None: kept)
    dc_peak: np.ndarray | None = None  # (channels,): the largest |x - mean|
    dc_counts: np.ndarray | None = None  # (snapshots, channels): the samples each mean is of

    def __post_init__(self) -> None:
        if len(self.names) != self.samples.n_channels:
            raise ValueError(f"{self.samples.n_channels} channels but {len(self.names)} names")
        end = sum(s.length for s in self.snapshots)
        if end != self.samples.n_samples:
            raise ValueError(f"the snapshots cover {end} samples, the store holds {self.samples.n_samples}")

    @property
    def units(self) -> list[str]:
        """Each channel's physical unit: m/s2, or a microphone's Pa."""
        return [physical_unit(u) for u in self.source_units] or ["m/s2"] * self.n_channels

    @property
    def n_channels(self) -> int:
        return self.samples.n_channels

    @property
    def n_samples(self) -> int:
        return self.samples.n_samples

    @property
    def peak(self) -> np.ndarray:
        """Each channel's largest |x|, m/s², of the samples without their mean when it is
        removed (:mod:`.dc`); 0 where that leaves only the rounding of a constant's mean (under
        1e-9 of its values)."""
        if self.dc_peak is None:
            return self.samples.peak
        return np.where(self.dc_peak > 1e-9 * self.samples.peak, self.dc_peak, 0.0)
