"""Observations on the block clock's slots: the rows (slot, channel) the banks take.

The block values of the blocks placed on slots (:meth:`~cmsensord.monitor.clock.BlockClock.place`)
become one row per slot from the first slot still to observe to the newest one placed: the
monitored channels' board columns, in float64, NaN and not valid where no block came (a
missing observation), where the board sends fewer channels than a channel's column, or where
a value is not finite.
"""

from __future__ import annotations

import numpy as np


def observation_rows(first: int, slots: np.ndarray, vals: np.ndarray,
                     index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(y, valid), each (T, len(index)), of slots ``first`` .. ``slots[-1]``: the board columns
    ``index`` of ``vals`` (one row per block, its slot in ``slots``, increasing, none before
    ``first``)."""
    T = int(slots[-1]) + 1 - first
    top = max(index.tolist())              # a few channels: no array reduction
    if vals.shape[1] <= top:                # the board sends fewer channels: those are missing
        vals = np.pad(vals, ((0, 0), (0, top + 1 - vals.shape[1])), constant_values=np.nan)
    if T == len(slots):                     # a block in every slot (slots first .. first + T - 1)
        y = vals[:, index].astype(np.float64)
        return y, np.isfinite(y)
    y = np.full((T, len(index)), np.nan)
    valid = np.zeros((T, len(index)), dtype=bool)
    y[slots - first] = vals[:, index]
    valid[slots - first] = True
    valid &= np.isfinite(y)
    return y, valid
