"""Parts of an import too quiet for its 12-bit range: one WARNING line a channel.

The full-scale range of a channel is one for the whole capture (the default from the whole
recording's peak, :func:`~.adc.nice_range`), so a snapshot far quieter than the loudest spans
a few counts only: the IMS rig's outer-race recording at +-80 m/s² (0.039 m/s² a count) has
snapshots of 0.0098 m/s² RMS, a quarter of a count, whose counts are mostly 0 and +-1. Their
level, kurtosis and crest factor are then those of the rounding, not of the vibration (an RMS
of 0.0019 m/s², a kurtosis of 405.7 against 1.39). :class:`LevelTally` sums each channel's
squares and peak over each snapshot (a continuous recording: over each second of it, about
``round(fs / block_len)`` blocks), of the signal the counts stand for (its mean removed, the
blocks left out for missing samples not counted), and :func:`quantised_lines` says, per
channel, how many snapshots (or seconds) carry under ``MIN_RMS_COUNTS`` counts RMS at the
channel's range, which is the first, and the range that resolves them when they are imported
on their own. A part whose every value is 0 is no quantisation: it is not counted.
"""

from __future__ import annotations

import numpy as np

from .adc import nice_range
from .blocks import BlockPlan

__all__ = ["MIN_RMS_COUNTS", "LevelTally", "quantised_lines"]

#: a part whose RMS spans fewer counts than this is quantised (rounding's own RMS: 0.29 count)
MIN_RMS_COUNTS = 10.0


class LevelTally:
    """Each channel's sum of squares, samples and peak per part (a snapshot, or a second of a
    continuous recording: ``blocks_per_s`` blocks), block by block (see module docstring)."""

    def __init__(self, n_channels: int, plan: BlockPlan, fs: int):
        snapshots = plan.snap_blocks.size
        snap_of = np.repeat(np.arange(snapshots), plan.snap_blocks)
        blocks_per_s = round(fs / plan.block_len)
        self.snapshots = snapshots > 1
        self.part_of = snap_of if self.snapshots else np.arange(snap_of.size) // max(1, blocks_per_s)
        #: each part's blocks
        self.blocks = np.bincount(self.part_of, minlength=snapshots if self.snapshots else 0)
        parts = self.blocks.size
        self.sq = np.zeros((parts, n_channels))
        self.n = np.zeros((parts, n_channels), dtype=np.int64)
        self.peak = np.zeros((parts, n_channels))

    def add(self, b0: int, xb: np.ndarray, lost: np.ndarray) -> None:
        """Blocks ``b0``.. : ``xb`` (C, nb, L) m/s² without their mean, ``lost`` (C, nb) left out."""
        keep = ~lost
        part = self.part_of[b0:b0 + xb.shape[1]]
        np.add.at(self.sq, part, (np.einsum("cbl,cbl->cb", xb, xb) * keep).T)
        np.add.at(self.n, part, (keep * xb.shape[2]).T)
        np.maximum.at(self.peak, part, (np.abs(xb).max(axis=-1) * keep).T)


def quantised_lines(tally: LevelTally, names: list[str], units: list[str], full_scale: list[float],
                    scale: list[float], sources: list[str], block_s: float, mode: str) -> dict[int, str]:
    """A WARNING line for each channel (by index) with parts under ``MIN_RMS_COUNTS`` counts RMS
    (see module docstring); ``sources``: the snapshots' names and places; ``block_s``: a block's seconds."""
    out = {}
    with np.errstate(invalid="ignore", divide="ignore"):
        counts = np.sqrt(tally.sq / tally.n) / np.asarray(scale)
    what = "level (block RMS) is" if mode == "rms" else "level, kurtosis and crest factor are"
    start_s = (np.cumsum(tally.blocks) - tally.blocks) * block_s
    for c, name in enumerate(names):
        heard = (tally.n[:, c] > 0) & (tally.sq[:, c] > 0)
        quiet = np.flatnonzero(heard & (counts[:, c] < MIN_RMS_COUNTS))
        if not quiet.size:
            continue
        k, u = int(quiet[0]), units[c]
        at = f"at +-{full_scale[c]:g} {u} ({scale[c]:.4g} {u} a count"
        if tally.snapshots:
            head = (f"{quiet.size:,} of {len(sources):,} snapshot(s) carry under {MIN_RMS_COUNTS:g} counts RMS {at}"
                    f"; the first: {sources[k]}, {counts[k, c]:.2g} counts RMS)")
            alone = "import them on their own (their files, or a copy holding only them) with "
        else:
            head = (f"{tally.blocks[quiet].sum() * block_s:.4g} s of its {tally.blocks.sum() * block_s:.4g} s carry "
                    f"under {MIN_RMS_COUNTS:g} counts RMS {at}; the first from {start_s[k]:.4g} s, "
                    f"{counts[k, c]:.2g} counts RMS)")
            alone = "import that part on its own with "
        fix = "give " if quiet.size == heard.sum() else alone
        out[c] = (f"  WARNING {name}: {head}: their {what} the rounding's, not the vibration's; "
                  f"{fix}--range {nice_range(float(tally.peak[quiet, c].max())):g}")
    return out
