"""How long the board's indicator records are, against ``indicators.interval_s``.

A RAW record holds at most :data:`MAX_INTERVAL_SAMPLES` samples (2.62 s at 25 kHz): a longer
setting gives records of that length (:func:`capped_interval` says so).  An RMS record sums
whole board blocks, the setting rounded to the nearest number of them, half to even, at least
one (:func:`rms_blocks`): a setting that is not a whole number of blocks gives records of that
rounded length (:func:`rounded_interval` says so).  The daemon and replay give these lines as
``config`` warnings when the board's STATUS gives its rate (:mod:`cmsensord.monitor.channels`),
calibrate as notes (:mod:`cmsensord.observations`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

from cmsensord.protocol import MODE_RAW, MODE_RMS

if TYPE_CHECKING:
    from cmsensord.config import Config


#: most samples in one interval (a board far faster than the TM4C's 25 kHz gets shorter
#: intervals, so memory stays bounded: a copy per interval waits for the shaft speed)
MAX_INTERVAL_SAMPLES = 1 << 16


def capped_interval(cfg: Config, fs: int) -> str | None:
    """The line that ``indicators.interval_s`` is longer than a RAW record holds at ``fs`` Hz
    (:data:`MAX_INTERVAL_SAMPLES`), with the record length given instead and the longest
    setting that fits; None when it fits or no indicator record is written.  RMS mode has no
    such bound (its records sum block RMS values, no samples are kept: :func:`rounded_interval`)."""
    ind = cfg.indicators
    if not ind.enabled or fs < 1 or round(ind.interval_s * fs) <= MAX_INTERVAL_SAMPLES:
        return None
    cap = MAX_INTERVAL_SAMPLES / fs
    step = 10.0 ** (math.floor(math.log10(cap)) - 2)      # 3 significant figures, rounded down: it fits
    fits = math.floor(cap / step + 1e-9) * step
    return (f"indicators.interval_s {ind.interval_s:g} s is longer than a RAW record holds at {fs} Hz "
            f"({MAX_INTERVAL_SAMPLES:,} samples, {cap:.3g} s): indicator records are {cap:.3g} s; set "
            f"indicators.interval_s {fits:.3g} or less")


def rms_blocks(interval_s: float, fs: int, block_len: int) -> int:
    """The board blocks an RMS-mode record sums: ``interval_s`` rounded to the nearest whole
    number of blocks of ``block_len`` samples at ``fs`` Hz (half to even), at least one."""
    return max(1, round(interval_s * fs / block_len))


def rounded_interval(cfg: Config, fs: int, block_len: int) -> str | None:
    """The line that ``indicators.interval_s`` is not a whole number of the RMS board's blocks
    (to 1e-9 relative), with the record length it gets instead (:func:`rms_blocks`) and the
    whole-block settings either side of it (that the configuration takes); None when it is or
    no indicator record is written."""
    ind = cfg.indicators
    if not ind.enabled or fs < 1 or block_len < 1:
        return None
    exact = ind.interval_s * fs / block_len
    per = rms_blocks(ind.interval_s, fs, block_len)
    if abs(exact - per) <= 1e-9 * exact:
        return None
    top = next(f.metadata.get("le", math.inf) for f in dataclasses.fields(ind) if f.name == "interval_s")
    near = [n for n in sorted({max(1, math.floor(exact)), max(1, math.ceil(exact))})
            if n * block_len / fs <= top * (1 + 1e-9)]        # settings the configuration takes
    return (f"indicators.interval_s {ind.interval_s:.12g} s is not a whole number of the board's RMS blocks "
            f"({block_len} samples at {fs} Hz, {block_len / fs:.12g} s): indicator records are {per} "
            f"block{'s' if per > 1 else ''}, {per * block_len / fs:.12g} s; set indicators.interval_s "
            + " or ".join(f"{n * block_len / fs:.12g}" for n in near))


def interval_note(cfg: Config, mode: int, fs: int, block_len: int) -> str | None:
    """The line that a board in ``mode`` at ``fs`` Hz and ``block_len`` samples a block gives
    records of another length than ``indicators.interval_s``: :func:`capped_interval` in RAW
    mode, :func:`rounded_interval` in RMS mode; None when they are that long."""
    if mode == MODE_RAW:
        return capped_interval(cfg, fs)
    return rounded_interval(cfg, fs, block_len) if mode == MODE_RMS else None
