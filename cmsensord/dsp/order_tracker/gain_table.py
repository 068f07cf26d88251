"""The tracker's steady-state gains tabulated against speed, filled as the speed visits them.

:class:`GainTable` holds [k | S] (and P(n|n-1) when the smoother needs it) on a
speed grid over [min_rpm, 1.1 max_rpm] and interpolates them linearly in the
grid coordinate.  The grid is geometric (a step proportional to the speed: the
gains of orders are functions of ω/fs, which vary as fast, relatively, at every
speed), with an absolute cap on the step when a fixed-frequency component
crosses the orders (near a crossing no steady state exists and the gains change
within a few rpm), and as many points as a memory budget allows.  See
docs/order_tracker.md (§4 Gains).
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable

import numpy as np

try:  # the compiled kernel is optional (and an older build may lack lerp_rows): numpy is the fallback
    from cmsensord.dsp import _trackerkernel  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _trackerkernel = None

SEGMENT = 64                 # the table is computed in segments of this many speeds
REL_STEP = 1.0 / 300.0       # default relative step of the grid (1 rpm at 300 rpm)
BUDGET_BYTES = 16_000_000    # the most the filled table may hold (the grid coarsens to fit)
MAX_POINTS = 8192


class SpeedGrid:
    """Speeds g(i), i = 0..n-1: geometric lo (1 + q)^i up to s_c = h/q, then steps of h.

    ``coord(speed)`` is the inverse (continuous, increasing), the coordinate the
    table interpolates in.  h = inf: geometric throughout.
    """

    def __init__(self, lo: float, top: float, q: float, h: float):
        self.lo, self.top, self.q, self.h = float(lo), float(top), float(q), float(h)
        self.lq = math.log1p(self.q)          # the geometric part's step in log speed
        self.s_c = min(self.h / self.q, self.top)
        self.linear = self.s_c < self.top      # a part of steps h above s_c
        self.x_c = math.log(self.s_c / self.lo) / self.lq     # coordinate of s_c
        x_top = self.x_c + (self.top - self.s_c) / self.h if self.linear else self.x_c
        self.n = max(2, math.ceil(x_top - 1e-9) + 1)

    def speeds(self, i: np.ndarray) -> np.ndarray:
        """The grid speeds at indices i (each the same whenever computed)."""
        i = np.asarray(i, dtype=np.float64)
        if not self.linear:
            return self.lo * np.exp(i * self.lq)
        geo = self.lo * np.exp(np.minimum(i, self.x_c) * self.lq)
        return np.where(i <= self.x_c, geo, self.s_c + (i - self.x_c) * self.h)

    def coord(self, speed: np.ndarray) -> np.ndarray:
        """Grid coordinate of speeds >= lo (a speed below lo maps to 0)."""
        s = np.maximum(speed, self.lo)
        if not self.linear:
            return np.log(s / self.lo) / self.lq
        x = np.log(np.minimum(s, self.s_c) / self.lo) / self.lq
        return np.where(s > self.s_c, self.x_c + (s - self.s_c) / self.h, x)


def choose_grid(lo: float, top: float, step_at_lo: float | None, cap_rpm: float | None,
                bytes_per_point: int) -> SpeedGrid:
    """The grid over [lo, top]: relative step ``step_at_lo`` / lo (None: REL_STEP), the
    absolute step capped at ``cap_rpm`` (None: no cap), coarsened (the cap doubled, then
    the relative step grown) until the table fits in BUDGET_BYTES and MAX_POINTS."""
    q = REL_STEP if step_at_lo is None else step_at_lo / lo
    h = math.inf if cap_rpm is None else max(cap_rpm, q * lo)
    n_max = max(16, min(MAX_POINTS, BUDGET_BYTES // bytes_per_point))
    grid = SpeedGrid(lo, top, q, h)
    while grid.n > n_max and grid.linear:
        h *= 2.0
        grid = SpeedGrid(lo, top, q, h)
    if grid.n > n_max:                       # geometric throughout, coarser
        q = max(q, math.expm1(math.log(top / lo) / (n_max - 2)))
        grid = SpeedGrid(lo, top, q, math.inf)
    return grid


def weakly(method: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
           ) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """A bound ``method`` called through a weak reference to its object: a table given its
    owner's method so does not keep the owner (owner -> table -> owner would be a cycle that
    only the cycle collector frees, with the table's up to 16 MB in it); ReferenceError once
    the owner is gone."""
    ref = weakref.WeakMethod(method)

    def call(grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        bound = ref()
        if bound is None:
            raise ReferenceError("the gain table's owner is gone")
        return bound(grid)

    return call


class GainTable:
    """Steady-state [k | S] (n, 2K+1) and, with ``want_p``, P(n|n-1) (n, 2K, 2K) on a
    :class:`SpeedGrid`, filled in segments of SEGMENT speeds when first needed by
    ``solve(speeds) -> (kS, P)``; every entry is the same whenever it is computed.

    ``lookup`` interpolates linearly in the grid coordinate (the differences to the
    next point are stored beside the values, so that a lookup is a gather and a
    multiply-add; in the compiled kernel when ``kernel`` and it is built, else numpy:
    the same numbers).  ``nbytes`` is the memory of the arrays (allocated as zeros:
    pages never filled take none).
    """

    def __init__(self, grid: SpeedGrid, K: int, want_p: bool,
                 solve: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], kernel: bool = True):
        self.grid = grid
        self.want_p = want_p
        self._solve = solve
        # ``kernel``: interpolate in the compiled kernel when it is built (the same numbers)
        self._lerp = getattr(_trackerkernel, "lerp_rows", None) if kernel else None
        self._lerp_at = getattr(_trackerkernel, "lerp_at", None) if kernel and not want_p else None
        n, d = grid.n, 2 * K
        self.have = np.zeros(-(-n // SEGMENT), dtype=bool)
        self.kS = np.zeros((n, d + 1))
        self.dkS = np.zeros((n - 1, d + 1))
        self.P = np.zeros((n, d, d)) if want_p else None
        self.dP = np.zeros((n - 1, d, d)) if want_p else None

    @staticmethod
    def bytes_per_point(K: int, want_p: bool) -> int:
        d = 2 * K
        return 2 * 8 * (d + 1 + (d * d if want_p else 0))

    @property
    def nbytes(self) -> int:
        arrays = (self.kS, self.dkS, self.P, self.dP, self.have)
        return sum(a.nbytes for a in arrays if a is not None)

    @property
    def filled_bytes(self) -> int:
        """The bytes of the segments filled so far (what a run has touched)."""
        return round(self.nbytes * self.have.mean())

    def fill(self, i: np.ndarray) -> None:
        """Compute the segments that hold grid points i or i + 1 and are not there yet."""
        seg, n = SEGMENT, self.grid.n
        if i.size and self.have[int(i.min()) // seg:(int(i.max()) + 1) // seg + 1].all():
            return                                  # the common case: every segment there
        need = np.zeros_like(self.have)
        need[i // seg] = True
        need[(i + 1) // seg] = True
        miss = np.flatnonzero(need & ~self.have)
        if not miss.size:
            return
        pts = np.concatenate([np.arange(m * seg, min((m + 1) * seg, n)) for m in miss])
        kS, P = self._solve(self.grid.speeds(pts))
        self.kS[pts] = kS
        if self.P is not None:
            self.P[pts] = P
        self.have[miss] = True
        # differences to the next point, where both ends are there now
        j = np.concatenate([pts - 1, pts])
        j.sort()                                    # np.unique's values (it imports numpy.ma: ~20 ms)
        j = j[np.concatenate(([True], j[1:] != j[:-1]))]
        j = j[(j >= 0) & (j < n - 1)]
        j = j[self.have[j // seg] & self.have[(j + 1) // seg]]
        self.dkS[j] = self.kS[j + 1] - self.kS[j]
        if self.P is not None and self.dP is not None:
            self.dP[j] = self.P[j + 1] - self.P[j]

    def lookup(self, speed: np.ndarray):
        """k (N, 2K), S (N,) and P (N, 2K, 2K) (None without ``want_p``) at model speeds."""
        x = self.grid.coord(speed)
        if self._lerp_at is not None:       # the rows there: index, fraction and rows in one pass
            N, w = x.size, self.kS.shape[1]
            k, S = np.empty((N, w - 1)), np.empty(N)
            if self._lerp_at(self.kS, self.dkS, x, self.have.view(np.uint8), SEGMENT, k, S, w, w - 1):
                return k, S, None
        i = np.minimum(x.astype(np.int64), self.grid.n - 2)
        f = np.clip(x - i, 0.0, 1.0)
        if i.size:
            self.fill(i)
        if self._lerp is not None:            # the same operations per entry, in one pass
            N, w = i.size, self.kS.shape[1]
            k, S = np.empty((N, w - 1)), np.empty(N)
            self._lerp(self.kS, self.dkS, i, f, k, S, w, w - 1)
            P = None
            if self.P is not None and self.dP is not None:
                d = self.P.shape[1]
                P = np.empty((N, d, d))
                self._lerp(self.P, self.dP, i, f, P, P[:0], d * d, d * d)
            return k, S, P
        kS = self.dkS[i]
        kS *= f[:, None]
        kS += self.kS[i]
        P = None
        if self.P is not None and self.dP is not None:      # in place: one (N, 2K, 2K) array less
            P = self.dP[i]
            P *= f[:, None, None]
            P += self.P[i]
        return np.ascontiguousarray(kS[:, :-1]), kS[:, -1].copy(), P
