"""Regular tacho edges in one pass: how many of a batch of edges the edge-by-edge repair
(:class:`~cmsensord.dsp.tacho.edges.EdgeRuns`) would simply commit as one pulse each.

In a running machine almost every edge comes one predicted interval after the
previous one: no timeout ends the run before it, it is later than the last edge
received, its interval ratio r = d / P is within 1 +- tol of the prediction P
(docs/tacho.md, step 3), and it is committed as one pulse.  :func:`regular_prefix`
checks that for a whole batch at once, assuming each edge before was committed so,
with the same arithmetic as the edge-by-edge path (the same operations in the same
order), and returns how many leading edges pass; the edge that does not, and what
follows, go edge by edge.  A ratio within ``MARGIN`` of a tolerance edge does not
pass either: whatever an ulp of difference in the prediction (``x ** 2`` is C's
pow() in Python, a product here) the decision is the edge-by-edge one.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["regular_prefix", "RegularState", "MARGIN", "MIN_EDGES"]

#: ratios this close to 1 +- tol are left to the edge-by-edge path
MARGIN = 1e-9
#: fewer edges than this go edge by edge (the numpy pass costs about as much as 10 edges)
MIN_EDGES = 8

IntArray = npt.NDArray[np.int64]


class RegularState:
    """The run's state the check needs: the last ``w`` committed intervals as (mid, rate)
    (the predictor's history, full), the last committed edge and the last three edges
    received (all committed: nothing pending), in 1/256 sample."""

    __slots__ = ("mid", "rate", "q3")

    def __init__(self, mid: list[float], rate: list[float], q3: tuple[int, int, int]):
        self.mid, self.rate, self.q3 = mid, rate, q3


def regular_prefix(st: RegularState, q: IntArray, adv: IntArray, tol: float, periods: float,
                   lo: int, hi: int) -> int:
    """How many leading edges of ``q`` (1/256 sample, in arrival order) are regular, given
    ``adv`` (same length): the coverage end (1/256 sample) checked for a timeout just before
    each edge, or -1 for none (an edge after another of the same frame)."""
    m = q.size
    w = len(st.mid)
    qq = np.concatenate((np.asarray(st.q3, dtype=np.int64), q))    # q3[2] is the last committed
    d = np.diff(qq)                                                # interval before each raw edge
    dn = d[2:]                                                     # the new edges' intervals
    # the timeout in force before edge j: from the two intervals before it (EdgeRuns._timeout_q)
    dt = np.maximum(d[1:m + 1], d[:m])
    tq = np.minimum(hi, np.maximum(lo, np.ceil(periods * dt.astype(np.float64)).astype(np.int64)))
    stop = qq[2:m + 2] + tq
    ok = (dn > 0) & (q <= stop) & (adv <= stop)
    # the predictor's history before edge j: the w entries before it (EdgeRuns._commit); an
    # edge not after the one before (dn <= 0) is not regular, nor is any after it
    with np.errstate(divide="ignore", invalid="ignore"):
        mid = np.concatenate((st.mid, qq[2:m + 1] + 0.5 * dn[:-1]))
        rate = np.concatenate((st.rate, 1.0 / dn[:-1]))
        P = _predict(np.lib.stride_tricks.sliding_window_view(mid, w)[:m],
                     np.lib.stride_tricks.sliding_window_view(rate, w)[:m], qq[2:m + 2], w)
        r = dn / P
    ok &= (r > 1.0 - tol + MARGIN) & (r < 1.0 + tol - MARGIN)
    bad = np.flatnonzero(~ok)
    return int(bad[0]) if bad.size else m


def _predict(mid: npt.NDArray[np.float64], rate: npt.NDArray[np.float64], cq_last: IntArray,
             n: int) -> npt.NDArray[np.float64]:
    """EdgeRuns._predict on each row of (mid, rate) windows (n columns), the sums column by
    column from 0.0 as Python's sum() adds (the caller ignores numpy's float warnings)."""
    t_ref = mid[:, -1]
    xs = mid - t_ref[:, None]
    xm = _sum(xs) / n
    ym = _sum(rate) / n
    dx = xs - xm[:, None]
    sxx = _sum(dx ** 2)
    slope = np.where(sxx > 0, _sum(dx * (rate - ym[:, None])) / np.where(sxx > 0, sxx, 1.0), 0.0)
    r0 = ym + slope * ((cq_last - t_ref) - xm)
    d_last = 1.0 / rate[:, -1]
    disc = r0 * r0 + 2.0 * slope
    d = 2.0 / (r0 + np.sqrt(np.where(disc > 0, disc, 0.0)))
    P = np.minimum(np.maximum(d, 0.5 * d_last), 2.0 * d_last)
    return np.where((r0 <= 0) | (disc <= 0), d_last, P)


def _sum(a: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Row sums added left to right from 0.0 (Python's sum() of floats)."""
    s = 0.0 + a[:, 0]
    for k in range(1, a.shape[1]):
        s = s + a[:, k]
    return s
