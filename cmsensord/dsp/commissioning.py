"""Commissioning: learn a machine's healthy model from its own healthy period.

Kim et al. 2023 choose R_min of eq. (16) as the smallest R that keeps the healthy
baseline free of anomalies and R_max from faulty data (the largest R that still
flags it).  On real machines that rule alone is fragile (one outlier second or an
unsteady run-in sets R_min for the whole life), so cmsensord extends it:

1. The bank watches y/b, the block RMS divided by the healthy baseline b (the median
   over the healthy period's decisions of each one's RMS, the root mean square of its
   blocks: the overall level an analyst reads), so R is in units of b² and means the
   same on every machine and sensor.
2. The healthy period is cut into decision periods.  For each period the
   *critical R*, R*, is the smallest R on a log grid for which one AKF counts
   fewer than f_r outliers in that period (it would not flag it).
3. A run-in transient at the start (a first quarter whose level or R* is well
   above the rest) is left out of the learning.
4. H, the healthy fluctuation, is a robust high quantile of R*:
   exp(median + 3·1.4826·MAD) of log R*, kept between the 75th percentile and the
   maximum, so a few outlier seconds do not set it.
5. R_1 (the most sensitive filter) = MARGIN·H: twice the healthy fluctuation in
   amplitude (R is a variance).  R_n = SPAN·R_1.  With ``faulty`` data, R_n is the
   paper's rule instead: the largest R that still flags at least half of the
   faulty capture's decisions.
6. A machine that stops during the healthy period (a pump that cycles, a shift's break) is
   not learned while stopped: decisions whose level is below STOPPED_SHARE of the period's
   running level (its 90th percentile), and the starts and stops beside them, are left out
   of the baseline and the critical R (they would make the stopped level the baseline).
7. The healthy period is checked as the monitor will judge it: every decision after
   the filters' transient, the run-in's too (the monitor grades them, though step 3
   leaves them out of the learning): the decisions R_1 flags, and (with the combined
   severity's ``level_alert``) those whose level is already that many times the baseline.
   A period that holds the start of a fault (a step or rise of level near its end, the
   whole of a run to failure) shows there, with where it starts, so the engineer can end
   the period before it.

Everything here is pure numpy on arrays; the command that reads captures is
``cmsensord.commission``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from cmsensord.dsp.akf import AkfBank

__all__ = [
    "MARGIN", "R_GRID", "SPAN", "HealthyModel", "bank_limits", "critical_r", "held_flags",
    "learn_healthy", "level_rise", "period_counts", "r_from_faulty", "run_in_periods",
]

#: candidate R values (in units of baseline²): 1e-7 .. 1e2, 20 per decade
R_GRID = np.logspace(-7, 2, 181)
#: R_1 = MARGIN x H: twice the healthy fluctuation amplitude
MARGIN = 4.0
#: R_n = SPAN x R_1 without faulty data
SPAN = 4.0
#: a first quarter this much above the rest in level is a run-in transient
RUNIN_LEVEL = 1.25
#: ... or this much above the rest in critical R
RUNIN_RSTAR = 2.0
#: a decision below this share of the running level (the 90th percentile) is the machine stopped
STOPPED_SHARE = 0.1


@dataclass(frozen=True)
class HealthyModel:
    """What commissioning learned for one channel."""

    baseline: float        # median over the healthy decisions of their RMS [input unit]
    spread: float          # robust std of the per-decision level ratio (1 = baseline)
    r_min: float           # eq. (16), units of baseline²
    r_max: float
    r_1: float             # R of the most sensitive AKF
    healthy_r: float       # H, robust high critical R of the healthy period
    periods: int           # decision periods learned from
    runin_periods: int     # periods left out at the start as run-in
    max_cnt: int           # highest outlier count at R_1 of a decision the monitor grades (run-in's too)
    flagged: int           # of those decisions, the ones AKF_1 (R_1) flags: cnt >= f_r, or held by c
    rstar_median: float
    r_max_rule: str = "span"   # "span": R_n = SPAN x R_1; "faulty": from the faulty recording
    level_flagged: int = 0     # healthy decisions whose level is >= level_alert x baseline
    level_first: int = -1      # the first and last of them (decision periods from the healthy
    level_last: int = -1       # period's start, 0 = the filters' transient); -1: none
    any_flagged: int = 0       # healthy decisions flagged by R_1 or by the level
    idle_periods: int = 0      # decisions left out with the machine stopped, and its starts and stops
    learned: int = 0           # decisions learned from (after the run-in, the machine running)
    steady_head: int = 0       # decisions after the transient, from the start / back from the end,
    steady_tail: int = 0       # that hold no level_alert decision of their own (:func:`steady_length`)
    runin_flagged: int = 0     # of ``flagged``, the ones in the run-in (graded, though not learned from)
    r1_first: int = -1         # the first and last decision R_1 flags (decision periods from the
    r1_last: int = -1          # healthy period's start, 0 = the filters' transient); -1: none
    faulty_r: float = float("nan")  # with faulty data: the largest R that flags half its decisions (NaN: none)
    rise: float = 1.0          # the learned decisions' last quarter median level / their first's (:func:`level_rise`)
    rise_at: int = -1          # where that rise passes half way (decision periods from the start); -1: no rise
    steady_rise: bool = False  # the steady stretch from the start (``steady_head``) holds such a rise of its own
    max_cnt_after: int = 0     # highest outlier count at R_1 of a graded decision after the run-in


def period_counts(y: np.ndarray, grid: np.ndarray, *, period: int, window: int, z_c: float,
                  p0: float = 1.0, q0: float = 1e-3) -> np.ndarray:
    """Outlier counts per complete decision period for one AKF per R in ``grid``.

    y: (T,) observations (NaN = missing).  Returns (P, len(grid)) counts, P = T // period.
    """
    y = np.asarray(y, dtype=np.float64).reshape(-1)
    grid = np.asarray(grid, dtype=np.float64)
    bank = AkfBank(grid[None, :], window=window, z_c=z_c, p0=p0, q0=q0)
    out = bank.process(y[:, None])
    P = y.size // period
    flags = out.outlier[: P * period, 0, :].reshape(P, period, grid.size)
    return flags.sum(axis=1, dtype=np.int64)


def critical_r(counts: np.ndarray, f_r: float, grid: np.ndarray) -> np.ndarray:
    """Per period, the smallest grid R whose count is below f_r (it would not flag).

    The count falls with R; a period that flags even at the largest R gets inf.
    """
    quiet = counts < f_r
    first = np.argmax(quiet, axis=1)
    r = np.asarray(grid, dtype=np.float64)[first]
    return np.where(quiet.any(axis=1), r, np.inf)


def _robust_high(rstar: np.ndarray) -> float:
    finite = rstar[np.isfinite(rstar)]
    if finite.size == 0:
        raise ValueError("no decision period of the healthy data is quiet at any R")
    log_r = np.log(finite)
    med = np.median(log_r)
    mad = np.median(np.abs(log_r - med))
    high = float(np.exp(med + 3.0 * 1.4826 * mad))
    return float(np.clip(high, np.quantile(finite, 0.75), finite.max()))


def run_in_periods(level: np.ndarray, rstar: np.ndarray) -> int:
    """Periods at the start to leave out as a run-in transient (0, 1 or 2 quarters).

    A quarter is run-in when its median level is above RUNIN_LEVEL x, or its
    median R* above RUNIN_RSTAR x, the median of the periods after it.
    """
    P = level.size
    q = P // 4
    if q < 2:
        return 0
    skip = 0
    for _ in range(2):
        head, rest = slice(skip, skip + q), slice(skip + q, P)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)   # a quarter of the machine stopped: NaN
            lv_head, lv_rest = np.nanmedian(level[head]), np.nanmedian(level[rest])
            r_head, r_rest = np.nanmedian(rstar[head]), np.nanmedian(rstar[rest])
        if lv_head > RUNIN_LEVEL * lv_rest or r_head > RUNIN_RSTAR * r_rest:
            skip += q
        else:
            break
    return skip


def bank_limits(r_1: float, n: int, span: float = SPAN) -> tuple[float, float]:
    """R_min, R_max of eq. (16) giving AKF_1 the variance r_1 and AKF_n span x r_1.

    R_i = R_min + i (R_max - R_min)/n, so R_1 = R_min + (R_max - R_min)/n.  A bank of n <= span
    AKFs cannot reach span x r_1 with R_min > 0 and R_1 = r_1 (Kim et al. 2023 use n = 10):
    then R_min = r_1 / span and R_n is as wide as eq. (16) allows with R_1 kept at r_1.
    """
    if n == 1:
        return r_1 / span, r_1
    r_max = span * r_1
    r_min = (n * r_1 - r_max) / (n - 1)
    if r_min <= 0:
        r_min = r_1 / span
        r_max = n * r_1 - (n - 1) * r_min
    return float(r_min), float(r_max)


def r_from_faulty(counts: np.ndarray, f_r: float, grid: np.ndarray) -> float:
    """The largest grid R that still flags at least half of the faulty decisions.

    Kim et al. 2023 take R_max as the largest R that still flags the faulty data;
    "half of the decisions" keeps one loud second from setting it.  NaN if even
    the smallest R flags fewer than half.
    """
    flagged = (counts >= f_r).mean(axis=0) >= 0.5
    idx = np.flatnonzero(flagged)
    return float(np.asarray(grid)[idx.max()]) if idx.size else float("nan")


def _level_per_period(y: np.ndarray, period: int) -> np.ndarray:
    P = y.size // period
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)   # an all-missing period is NaN
        return np.sqrt(np.nanmean(np.square(y[: P * period].reshape(P, period)), axis=1))


def idle_periods(level: np.ndarray) -> np.ndarray:
    """Per decision, whether the machine is stopped (level below STOPPED_SHARE of the 90th
    percentile level; NaN: missing) or starting or stopping (a decision beside a stopped one)."""
    finite = np.isfinite(level)
    if not finite.any():
        return np.zeros(level.size, dtype=bool)
    with np.errstate(invalid="ignore"):
        stopped = level < STOPPED_SHARE * np.percentile(level[finite], 90)
    idle = stopped.copy()
    idle[1:] |= stopped[:-1]
    idle[:-1] |= stopped[1:]
    return idle


def level_rise(ratio: np.ndarray, skip: int) -> tuple[float, int] | None:
    """A level that rises through the learned decisions (``ratio``: each decision's level /
    baseline, NaN where not learned from; the first ``skip``, the run-in, left out): (the last
    quarter's median / the first quarter's, the first decision of the first quarter-long window
    whose median is above the first quarter's by more than the noise: where the rise starts) when
    the last quarter is RUNIN_LEVEL x the first or more, the mirror of the run-in rule, and beyond
    the noise of two quarter medians (three standard errors of their difference, the decisions'
    scatter taken from one to the next, so that a slow rise is no part of it); else None."""
    at = np.flatnonzero(np.isfinite(ratio[skip:])) + skip
    q = at.size // 4
    if q < 2:
        return None
    v = ratio[at]
    first, last = float(np.median(v[:q])), float(np.median(v[-q:]))
    scatter = 1.4826 * float(np.median(np.abs(np.diff(v)))) / np.sqrt(2.0)
    noise = 3.0 * 1.2533 * scatter * np.sqrt(2.0 / q)
    if not (first > 0 and last >= RUNIN_LEVEL * first and last - first > noise):
        return None
    running = np.median(np.lib.stride_tricks.sliding_window_view(v, q), axis=1)
    j = int(np.argmax(running > first + noise))
    return last / first, int(at[j])


def steady_length(level: np.ndarray, alert: float, max_rounds: int = 100) -> int:
    """How many of the per-decision ``level`` values, from the first, make a steady healthy period:
    none of them at ``alert`` x their own median (NaN: missing).

    The span is cut at its first loud decision and checked again against the median of what is
    left, until none is loud (a level rising through the span lowers the median as it is cut).
    Reversed ``level`` gives the steady stretch at the end (after a start-up).
    """
    k = level.size
    for _ in range(max_rounds):
        head = level[:k]
        if not np.any(np.isfinite(head)):
            return 0
        with np.errstate(invalid="ignore"):
            loud = np.flatnonzero(head >= alert * np.nanmedian(head))
        if not loud.size:
            return k
        k = int(loud[0])
    return k


def learn_healthy(y: np.ndarray, *, f_r: float, period: int, n: int, window: int, z_c: float,
                  p0: float = 1.0, q0: float = 1e-3, faulty: np.ndarray | None = None,
                  grid: np.ndarray = R_GRID, level_alert: float | None = None, c: float = 0.4) -> HealthyModel:
    """The healthy model of one channel from its block RMS ``y`` (T,), NaN = missing.

    The first decision period (the filters' transient) is not learned from.
    ``faulty``: block RMS of a faulty recording of the same machine (optional).
    ``level_alert``: the combined severity's level / baseline alert, for the check of the
    healthy period's own levels (None: the paper's severity, without a level part).
    ``c``: the decisions' hysteresis (``monitor.c``), for the check of the decisions R_1 flags.
    """
    y = np.asarray(y, dtype=np.float64).reshape(-1)
    if f_r >= period:
        raise ValueError(f"f_r = {f_r:g} must be below the {period} observations per decision")
    level_raw = _level_per_period(y, period)[1:]
    if np.count_nonzero(np.isfinite(level_raw)) < 1:
        raise ValueError(f"need at least 2 decision periods of data ({period} observations each; "
                         f"the first is the filters' transient), got {np.count_nonzero(np.isfinite(y))} "
                         "observation(s)")
    idle = idle_periods(level_raw)
    running = np.where(idle, np.nan, level_raw)
    if not np.isfinite(running).any():
        raise ValueError("the machine does not run steadily in the healthy period (every decision is stopped, "
                         "starting or stopping); choose a period where it runs")
    baseline = float(np.nanmedian(running))
    if not baseline > 0:
        raise ValueError("the healthy period's block RMS is zero: no signal on this channel (no sensor on it?): "
                         "leave it out (import --channels, or a --config BASE.yaml listing the channels to learn)")
    def counts_of(series: np.ndarray, rs: np.ndarray) -> np.ndarray:
        return period_counts(series / baseline, rs, period=period, window=window, z_c=z_c, p0=p0, q0=q0)[1:]

    counts = counts_of(y, grid)
    rstar = critical_r(counts, f_r, grid)
    rstar[idle] = np.nan                    # not learned from (:func:`_robust_high` takes finite ones)
    skip = run_in_periods(running, rstar)
    kept = slice(skip, None)
    rstar = rstar[kept]
    H = _robust_high(rstar)
    r_1 = MARGIN * H
    r_min, r_max = bank_limits(r_1, n)
    rule, r_f = "span", float("nan")
    if faulty is not None:
        fc = counts_of(np.asarray(faulty, np.float64), grid)
        r_f = r_from_faulty(fc, f_r, grid)
        if np.isfinite(r_f) and r_f > r_1:
            r_min = (n * r_1 - r_f) / (n - 1) if n > 1 else 0.0
            if r_min <= 0:                  # R_n = r_f out of eq. (16)'s reach with R_1 = r_1:
                r_min = r_1 / 2             # R_1 is larger, and the healthy check runs at it
                r_1 = r_min + (r_f - r_min) / n
            r_max, rule = r_f, "faulty"
    med = np.nanmedian(running / baseline)
    spread = float(1.4826 * np.nanmedian(np.abs(running / baseline - med)))
    check = _check_period(counts_of(y, np.array([r_1]))[:, 0], level_raw / baseline, f_r, c, skip, level_alert)
    rise = level_rise(running / baseline, skip)
    head = check["steady_head"] if check["level_flagged"] else 0
    return HealthyModel(
        baseline=baseline, spread=spread, r_min=float(r_min), r_max=float(r_max), r_1=float(r_1),
        healthy_r=H, periods=int(rstar.size), runin_periods=int(skip),
        rstar_median=float(np.median(rstar[np.isfinite(rstar)])), r_max_rule=rule, faulty_r=r_f,
        idle_periods=int(np.count_nonzero(idle)), learned=int(np.count_nonzero(~np.isnan(rstar))), **check,
        rise=rise[0] if rise else 1.0, rise_at=rise[1] + 1 if rise else -1,
        steady_rise=level_rise((running / baseline)[:head], skip) is not None,
    )


def held_flags(cnt: np.ndarray, f_r: float, c: float) -> np.ndarray:
    """Per decision, one AKF's F_a by Fig. 3 from its outlier counts ``cnt``: set at cnt >= f_r,
    cleared at cnt < c f_r, else kept (:class:`~cmsensord.dsp.severity.AnomalyDecider`)."""
    out = np.zeros(cnt.size, dtype=bool)
    state = False
    for k, v in enumerate(cnt.tolist()):
        state = True if v >= f_r else False if v < c * f_r else state
        out[k] = state
    return out


def _check_period(at_r1: np.ndarray, ratio: np.ndarray, f_r: float, c: float, skip: int,
                  level_alert: float | None) -> dict[str, int]:
    """The healthy period judged as the monitor will judge it: every decision after the filters'
    transient is graded, the run-in's (the first ``skip``, not learned from) too.  ``at_r1``: the
    outlier counts at R_1 per decision, ``ratio``: the decisions' levels / baseline; the
    :class:`HealthyModel` fields of the check by name."""
    by_r1 = held_flags(at_r1, f_r, c)
    r1_at = np.flatnonzero(by_r1)
    flagged = by_r1.copy()
    loud = np.empty(0, dtype=np.int64)
    steady = (ratio.size, ratio.size)
    if level_alert is not None:
        loud = np.flatnonzero(ratio >= level_alert)
        if loud.size:
            steady = (steady_length(ratio, level_alert), steady_length(ratio[::-1], level_alert))
    flagged[loud] = True
    return dict(
        max_cnt=int(at_r1.max()), max_cnt_after=int(at_r1[skip:].max()) if at_r1.size > skip else 0,
        flagged=int(r1_at.size), runin_flagged=int(np.count_nonzero(by_r1[:skip])),
        r1_first=int(r1_at[0]) + 1 if r1_at.size else -1, r1_last=int(r1_at[-1]) + 1 if r1_at.size else -1,
        level_flagged=int(loud.size), level_first=int(loud[0]) + 1 if loud.size else -1,
        level_last=int(loud[-1]) + 1 if loud.size else -1, any_flagged=int(np.count_nonzero(flagged)),
        steady_head=steady[0], steady_tail=steady[1],
    )
