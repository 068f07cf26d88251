"""The speed the order tracker reads: at its kept samples, ``delay_in`` input samples earlier.

The anti-alias filter delays the signal by ``delay_in`` input samples, so a kept (tracker)
sample at input index j D is tracked at the speed of input sample j D - delay_in: the speed
passes through a delay line of ``delay_in`` samples (the state's ``rpm_line``, oldest first,
starting filled with the first input's speed).  :func:`delayed` reads it from the speed of
every input sample of a call; :func:`delayed_at` from a function asked only for the samples
read (one in D), which gives the same speeds.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from cmsensord.dsp.order_tracker.state import TrackerState

#: the speed [rpm] at input samples i (counted from the call's first sample), for process()
SpeedAt = Callable[[np.ndarray], np.ndarray]


def piece_of(rpm: np.ndarray | SpeedAt, a: int, n: int) -> np.ndarray | SpeedAt:
    """The speed of the input samples a .. a + n - 1 of a call, as the tracker takes it for a
    call of those samples alone."""
    if callable(rpm):
        return lambda i: rpm(i + a)
    return rpm[a:a + n]


def delayed(st: TrackerState, n: int, rpm: np.ndarray, take: np.ndarray) -> np.ndarray:
    """The speed ``n`` input samples earlier at the kept samples ``take`` of this call (the
    delay line [rpm_line, rpm] read there, without joining the whole call), and the line
    moved on."""
    if st.n_in == 0 and rpm.size:            # the line starts filled with the first speed
        st.rpm_line[:] = rpm[0]
    k = int(np.searchsorted(take, n))        # kept samples still in the old line
    rd = np.concatenate([st.rpm_line[take[:k]], rpm[take[k:] - n]])
    st.rpm_line = (rpm[len(rpm) - n:].copy() if len(rpm) >= n
                   else np.concatenate([st.rpm_line[len(rpm):], rpm]))
    return rd


def delayed_at(st: TrackerState, n: int, D: int, speed_at: SpeedAt, T: int, take: np.ndarray) -> np.ndarray:
    """:func:`delayed` of a call of T input samples whose speed comes from ``speed_at``,
    asked only where it is read: the input samples m with m + n a multiple of D (every kept
    sample is, counted from the first input), and the first input's (the line starts filled
    with it).  The line keeps those only (its other entries NaN, never read); its entries,
    and so the speeds read, are those of :func:`delayed`."""
    p0 = -(st.n_in + n) % D
    if st.n_in and T >= n:
        return _delayed_at_steady(st, n, D, speed_at, T, take, p0)
    pos = np.arange(p0, T, D)
    first = st.n_in == 0 and p0 > 0            # the first input's speed fills the line
    if first:
        pos = np.concatenate(([0], pos))
    vals = np.asarray(speed_at(pos), dtype=np.float64)
    if st.n_in == 0:
        st.rpm_line[:] = vals[0]
    k = int(np.searchsorted(take, n))           # kept samples still in the old line
    rd = np.concatenate([st.rpm_line[take[:k]], vals[(take[k:] - n - p0) // D + first]])
    tail = max(T - n, 0)                        # the line: positions tail .. T - 1 of this call
    new = np.full(T - tail, np.nan)
    at = int(np.searchsorted(pos, tail))
    new[pos[at:] - tail] = vals[at:]
    st.rpm_line = np.concatenate([st.rpm_line[T:], new]) if T < n else new
    return rd


def _delayed_at_steady(st: TrackerState, n: int, D: int, speed_at: SpeedAt, T: int, take: np.ndarray,
                       p0: int) -> np.ndarray:
    """:func:`delayed_at` of a call after the first one and at least as long as the line (the
    live calls): the same entries read and kept, by slices (the kept samples ``take`` and the
    positions asked are steps of D, the kept ones at multiples of D from the first input)."""
    vals = np.asarray(speed_at(np.arange(p0, T, D)), dtype=np.float64)
    k = len(range(int(take[0]), n, D)) if take.size else 0      # kept samples still in the old line
    j0 = (int(take[k]) - n - p0) // D if k < take.size else 0
    rd = np.concatenate([st.rpm_line[int(take[0]) if k else n:n:D], vals[j0:j0 + take.size - k]])
    tail = T - n                                # the line: positions tail .. T - 1 of this call
    at = len(range(p0, tail, D))                # positions asked before it
    new = np.empty(n)
    new.fill(np.nan)                            # np.full's values, without its Python wrapper
    new[p0 + at * D - tail::D] = vals[at:]
    st.rpm_line = new
    return rd
