"""What the user asked for: the import's settings, one typed object."""

from __future__ import annotations

from dataclasses import dataclass

from .samples import MEMORY_MB

__all__ = ["ImportOptions"]


@dataclass(frozen=True)
class ImportOptions:
    out: str
    mode: str = "raw"  # "raw" or "rms"
    fs: float | None = None  # overrides / supplies the sampling rate
    channels: tuple[str, ...] | None = None  # indices (from 0) or names; None: all
    names: tuple[str, ...] | None = None
    array: tuple[str, ...] | None = None  # .npz: names or patterns
    variable: tuple[str, ...] | None = None  # .mat: names or patterns
    separator: str | None = None  # CSV; None: detected
    header: bool | None = None  # CSV; None: detected
    unit: tuple[str, ...] | None = None  # one, or one per channel; None: the file's own, else m/s2
    sensitivity: tuple[float, ...] | None = None  # mV/g, for the channels in V: one, or one per channel
    scale_factor: tuple[float, ...] = (1.0,)  # one, or one per channel
    full_scale: tuple[float, ...] | None = None  # m/s^2, one or one per channel; None: from the data
    block_len: int | None = None  # None: round(fs / 100)
    snapshot_len: int | None = None  # split each file's samples into snapshots of this length
    snapshot_interval: float | None = None  # s between snapshot starts in the original recording
    order: str = "name"  # "name", "mtime" or "given"
    tacho_column: str | None = None
    speed_column: str | None = None  # a column of shaft speed in rpm: TACHO edges from it
    tacho_threshold: float | None = None
    ppr: int = 1
    rpm: float | None = None  # synthesise TACHO frames at this constant speed
    keep_dc: bool = False  # keep each channel's mean (default: taken out, as the board's offset: .dc)
    memory_mb: float = MEMORY_MB  # samples held in memory at most; beyond, on disk beside ``out``
    join_recordings: bool = False  # lay files of many snapshots each end to end (:func:`.sources.build_recording`)
