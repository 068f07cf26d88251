"""Anomaly decisions and the severity index of a bank of AKFs.

Implements Kim et al. 2023 section III.C-D: the 1-s anomaly decision of Fig. 3 and the
severity index of eqs. (16)-(18), vectorised over (channel, filter).

Fig. 3, for every AKF of every channel, once per decision period:

    cnt  = number of outliers (|z| > z_c, eq. 15) in the period
    if cnt >= f_r:          F_a = 1            (anomaly detected)
    elif cnt < c * f_r:     F_a = 0            (no anomaly / decision cancelled)
    else:                   F_a kept           (hysteresis, 0 < c < 1)
    cnt = 0

    I_i   = i/n if F_a of AKF_i is 1 else 0                 (18)
    S_idx = max(I_1, ..., I_n)                               (17)

The AKF with R_max (AKF_n) flagging an anomaly means failure (section IV).

Choices the paper leaves open:

* The period is counted in observation slots (received or missing): with the
  100 Hz RMS stream a period is 100 slots = 1 s of ADC time, so decisions are
  aligned to the board's clock, not to when frames happen to arrive.  A lost
  observation cannot be an outlier; the period reports how many were missing.
* The first period is the filters' transient (Fig. 5: "except for the first
  1-s interval, in which the AKF is in a transient state"); its decision is
  reported with ``transient = True`` and does not change F_a.

Extension (not in the paper), selected by ``level_alert``: the *combined*
severity also grades the level of the period against the machine's learned
healthy baseline, the way vibration analysts grade an overall level:

    ratio     = RMS over the period of y/baseline (the root mean square of the blocks')
    S_level   = 0                                   ratio < alert
              = 0.5 + 0.5 log(ratio/alert)/log(danger/alert), at most 1, floored to i/n
    S_idx     = max(S_AKF, S_level)

so the AKF bank reports a change of the signal's dynamics early and the level
part keeps a grown level reported once the bank has adapted to it.  Without
``level_alert`` the decider is the paper's.

Extension (not in the paper), in the combined mode: a period with a quarter whose ratio
is below ``signal_floor`` (a fraction of the healthy baseline) has no signal to judge (a
sensor, cable or ADC fault, or the machine stopped), nor has a period with no observation
at all after one such: its decision keeps F_a and S_idx as they were
(``Decision.no_signal``), so a dead sensor does not read as a healed machine, and the
period the signal goes (or comes back) in, half dead, is not judged either.

Extension (not in the paper), in both modes, selected by ``flat_signal`` (RAW blocks): a flat
block (all its samples one ADC count: a dead sensor, a cut cable, an input pinned at a rail; a
real accelerometer through a real ADC always moves by a count or so) is no evidence about the
machine: the chain gives it to the banks as no observation (no outlier, no level ratio), as a
lost one, though it is not counted ``missing``.  A period has no signal in the same way, with or
without a baseline (``Decision.no_signal``; ``Decision.flat`` says which counts, how many of
the blocks looked at):

* with a quarter in which every block of a channel that came is flat (the channel dies or
  comes back in it: ``Decision.flat_quarter``);
* with flat blocks at least a quarter of the channel's blocks looked at, wherever they lie
  (intermittent: an input that drops to a rail and back, block by block, as a loose connector;
  ``Decision.flat_share``);
* after a period with no signal for flat blocks, with no block of the channel looked at (lost
  frames, or the board sends RMS frames, whose samples cannot be seen move): nothing shows the
  samples move again.

Extension (not in the paper), in both modes: a period that lacks more than half of a channel's
observations (frames lost, a link down, values the board could not have sent) is not judged
for that channel: F_a and S_idx are kept as they were (``Decision.no_data``). Fig. 3 compares
the outliers counted in a period with f_r; with most observations missing that count falls
under c f_r whatever the machine does, and a failing channel would clear for the gap.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

__all__ = ["HOLD_EVENT_DECISIONS", "NOT_LOOKED", "AnomalyDecider", "Decision", "level_severity"]

#: whole periods in one :meth:`AnomalyDecider.update` call from which they are decided in one
#: pass (:meth:`AnomalyDecider._decide_many`; the same decisions as one period at a time)
ONE_PASS_PERIODS = 1

#: consecutive decisions a flag may be held by the hysteresis alone
#: (c f_r <= cnt < f_r) before the monitor reports it
HOLD_EVENT_DECISIONS = 60

#: the flat count of a slot whose block was not looked at for flatness (an RMS frame's value, a
#: RAW block too short to tell): neither flat nor moving (NaN: looked at, and it moves)
NOT_LOOKED = -1.0


def level_severity(ratio, n: int, alert, danger) -> np.ndarray:
    """S_level of a level ratio (level / healthy baseline); NaN ratio -> 0.

    0 below ``alert``, 0.5 at ``alert``, log-linear up to 1 at ``danger``, floored to
    the bank's grid i/n so it reads like the paper's index.
    """
    r = np.asarray(ratio, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = 0.5 + 0.5 * np.log(r / alert) / np.log(danger / alert)
    s = np.where(np.isfinite(r) & (r >= alert), np.clip(s, 0.5, 1.0), 0.0)
    return np.floor(s * n + 1e-9) / n


@dataclass
class Decision:
    """The outcome of one decision period for all channels."""

    slot: int                 # observation slot index at the end of the period (exclusive)
    period: int               # 0-based period number
    transient: bool
    cnt: np.ndarray           # (C, n) outliers counted in the period
    anomaly: np.ndarray       # (C, n) F_a after the decision
    prev_anomaly: np.ndarray  # (C, n) F_a before the decision
    severity: np.ndarray      # (C,) S_idx, eq. (17)
    prev_severity: np.ndarray
    f_r: np.ndarray           # (C,) rotation frequency used
    missing: np.ndarray       # (C,) observations missing in the period
    severity_akf: np.ndarray  # (C,) the bank's S_idx (= severity in the paper's mode)
    level: np.ndarray         # (C,) the period's RMS / baseline (NaN without a baseline)
    severity_level: np.ndarray  # (C,) S_level (NaN in the paper's mode)
    held: np.ndarray          # (C, n) consecutive decisions F_a was kept by the hysteresis alone
    held_max: int = 0         # the largest of ``held``
    no_signal: np.ndarray | None = None  # (C,) combined: no signal in the period, F_a and S_idx held
    quietest: np.ndarray | None = None   # (C,) combined: the lowest level ratio of the period's quarters
    no_data: np.ndarray | None = None    # (C,) more than half the period missing: F_a and S_idx held
    #: (C, 4) flat_signal: lowest, highest count of the flat blocks (NaN: none), how many, of how many looked at
    flat: np.ndarray | None = None
    flat_quarter: np.ndarray | None = None   # (C,) flat_signal: a quarter of flat blocks (no signal for it)
    flat_share: np.ndarray | None = None     # (C,) flat_signal: a quarter of the blocks looked at flat (no signal)
    flat_slots: np.ndarray | None = None     # (period, C) flat_signal: the slots whose block was flat


class AnomalyDecider:
    """Fig. 3 decisions and eqs. (17)-(18) for C channels x n AKFs.

    ``period`` is the number of observation slots per decision (100 for 1 s
    at 100 Hz).  State (cnt, F_a, position in the period) is carried between
    calls, so a stream may be split anywhere.
    """

    def __init__(self, n_channels: int, n_filters: int, *, f_r, c, period: int = 100,
                 transient_periods: int = 1, level_alert=None, level_danger=None, signal_floor=0.0,
                 flat_signal=None):
        if period < 1:
            raise ValueError(f"period: expected >= 1 observation, got {period}")
        self.C, self.n = n_channels, n_filters
        self.f_r = np.broadcast_to(np.asarray(f_r, dtype=np.float64), (n_channels,)).copy()
        self.c = np.broadcast_to(np.asarray(c, dtype=np.float64), (n_channels,)).copy()
        self.period = int(period)     # slots of the period in progress
        self.nominal_period = self.period   # ... and of every period at the block rate now
        self.transient_periods = int(transient_periods)
        self.cnt = np.zeros((n_channels, n_filters), dtype=np.int64)
        self.anomaly = np.zeros((n_channels, n_filters), dtype=np.uint8)
        self.missing = np.zeros(n_channels, dtype=np.int64)
        self.phase = 0            # slots seen in the current period
        self.periods = 0          # decisions made
        self.slot = 0             # slots seen in total
        self.level_weights = np.arange(1, n_filters + 1, dtype=np.float64) / n_filters  # i/n
        self.held = np.zeros((n_channels, n_filters), dtype=np.int64)
        self.level_alert = None if level_alert is None else np.broadcast_to(
            np.asarray(level_alert, dtype=np.float64), (n_channels,)).copy()
        if level_danger is None and self.level_alert is not None:
            level_danger = 2.0 * self.level_alert
        self.level_danger = None if level_danger is None else np.broadcast_to(
            np.asarray(level_danger, dtype=np.float64), (n_channels,)).copy()
        self.signal_floor = np.broadcast_to(np.asarray(signal_floor, dtype=np.float64), (n_channels,)).copy()
        self._level = np.full((self.period, n_channels), np.nan)
        self._last_severity = np.zeros(n_channels)
        self._quiet = np.zeros(n_channels, dtype=bool)   # a quarter of the period below signal_floor
        self._quietest = np.full(n_channels, np.nan)
        self._lost = np.zeros(n_channels, dtype=bool)    # the last decision had no signal
        #: the channels whose flat blocks are no signal (None: flat blocks not looked at)
        self.flat_signal = None if flat_signal is None else np.broadcast_to(
            np.asarray(flat_signal, dtype=bool), (n_channels,)).copy()
        self._flat = np.full((self.period, n_channels), np.nan)   # per slot: a flat block's count, else NaN
        self._came = np.zeros((self.period, n_channels), dtype=bool)   # per slot: an observation came
        self._flat_seen = False                                   # a flat block in the period
        self._flat_quarter = np.zeros(n_channels, dtype=bool)     # the period had a flat quarter
        self._flat_share = np.zeros(n_channels, dtype=bool)       # ... a quarter of its blocks flat
        self._unlooked = np.zeros(n_channels, dtype=bool)         # ... no block looked at
        self._lost_flat = np.zeros(n_channels, dtype=bool)        # the last decision: no signal for flat blocks

    def set_period(self, period: int) -> None:
        """Decide every ``period`` slots (the block rate changed): the period in progress keeps the
        share of a period it had left, in slots at the new rate (at least one); the next are ``period`` long."""
        if period < 1:
            raise ValueError(f"period: expected >= 1 observation, got {period}")
        left = self.period - self.phase
        self._resize(self.phase + max(1, round(left * period / self.nominal_period)) if self.phase else period)
        self.nominal_period = int(period)

    def _resize(self, period: int) -> None:
        """The period in progress is ``period`` slots (its level ratios so far kept)."""
        keep = min(self.phase, period)
        level, flat = np.full((period, self.C), np.nan), np.full((period, self.C), np.nan)
        came = np.zeros((period, self.C), dtype=bool)
        level[:keep], flat[:keep], came[:keep] = self._level[:keep], self._flat[:keep], self._came[:keep]
        self.period, self._level, self._flat, self._came = period, level, flat, came

    @property
    def combined(self) -> bool:
        """True when the severity also grades the level (``level_alert`` given)."""
        return self.level_alert is not None

    def severity_of(self, anomaly: np.ndarray) -> np.ndarray:
        """S_idx = max_i I_i with I_i = i/n F_a,i (eqs. 17-18); 0 when no flag is set."""
        return (anomaly * self.level_weights).max(axis=-1)

    def update(self, outlier: np.ndarray, valid: np.ndarray, f_r=None,
               level: np.ndarray | None = None, flat: np.ndarray | None = None) -> list[Decision]:
        """Count a block of T observation slots; return the decisions it completes.

        outlier: (T, C, n) flags; valid: (T, C) False for missing observations.
        f_r: optional (C,) rotation frequency for decisions in this block (tacho).
        level: (T, C) level ratios y/baseline (combined mode; NaN = missing).
        flat: (T, C) the count of each flat block (all samples that count), NaN where it moves,
        :data:`NOT_LOOKED` where the block was not looked at.
        """
        if self.flat_signal is None:
            flat = None
        outlier = np.asarray(outlier)
        T = outlier.shape[0]
        if outlier.shape[1:] != (self.C, self.n):
            raise ValueError(f"outlier: expected shape (T, {self.C}, {self.n}), got {outlier.shape}")
        if f_r is not None:
            self.f_r = np.broadcast_to(np.asarray(f_r, dtype=np.float64), (self.C,)).copy()
        decisions: list[Decision] = []
        start = 0
        while start < T:
            k = (T - start) // self.period              # whole periods: decided in one pass
            if self.phase == 0 and k >= ONE_PASS_PERIODS and level is None \
                    and not self.combined and self.periods >= self.transient_periods \
                    and (flat is None or self._moving(flat[start:start + k * self.period])):
                whole = np.asarray(valid[start:start + k * self.period], dtype=bool)
                if self._all_judged(whole):
                    decisions += self._decide_many(outlier[start:start + k * self.period], whole)
                    start += k * self.period
                    continue
            take = min(T - start, self.period - self.phase)
            seg = slice(start, start + take)
            self.cnt += outlier[seg].sum(axis=0, dtype=np.int64)
            self.missing += (~np.asarray(valid[seg], dtype=bool)).sum(axis=0)
            if level is not None:
                lv = np.where(np.asarray(valid[seg], dtype=bool), level[seg], np.nan)
                self._level[self.phase:self.phase + take] = lv
            if flat is not None:
                self._flat[self.phase:self.phase + take] = part = flat[seg]
                self._came[self.phase:self.phase + take] = valid[seg]
                self._flat_seen = self._flat_seen or bool((part >= 0).any())
            elif self.flat_signal is not None:          # slots of no flat block
                self._came[self.phase:self.phase + take] = False
            self.phase += take
            self.slot += take
            start += take
            if self.phase == self.period:
                decisions.append(self._decide())
        return decisions

    def _moving(self, flat: np.ndarray) -> bool:
        """No block of ``flat`` is flat and no channel is without signal (the periods may be
        decided in one pass)."""
        return not self._lost.any() and not bool((flat >= 0).any())

    def _all_judged(self, valid: np.ndarray) -> bool:
        """No whole period of ``valid`` (K period, C) lacks more than half a channel's
        observations (none held for ``no_data``)."""
        if valid.all():
            return True
        P = self.period
        return not ((~valid).reshape(-1, P, self.C).sum(axis=1) * 2 > P).any()

    def _decide(self) -> Decision:
        prev = self.anomaly.copy()
        transient = self.periods < self.transient_periods
        level, s_level = self._level_part(transient)
        signal_lost = no_data = unjudged = None
        flat, flat_slots = self._flat_part() if self.flat_signal is not None else (None, None)
        if (self.combined or self.flat_signal is not None) and not transient:
            # no signal: a quiet or flat quarter, a quarter of the blocks flat, no block looked at while
            # lost for flat blocks, or no observation at all while lost
            quiet = self._quiet if self.combined else False
            by_flat = self._flat_quarter | self._flat_share | (self._unlooked & self._lost_flat)
            signal_lost = self._lost = quiet | by_flat | ((self.missing >= self.period) & self._lost)
            self._lost_flat = by_flat
        if not transient:
            no_data = self.missing * 2 > self.period
            unjudged = no_data if signal_lost is None else signal_lost | no_data
            fr = self.f_r[:, None]
            set_ = self.cnt >= fr                       # cnt >= f_r  -> F_a = 1
            clear = self.cnt < self.c[:, None] * fr     # cnt < c f_r -> F_a = 0
            self.anomaly = np.where(set_, 1, np.where(clear, 0, self.anomaly)).astype(np.uint8)
            kept = (self.anomaly == 1) & ~set_
            held = np.where(kept, self.held + 1, 0)
            if unjudged.any():                          # no signal or no data: F_a as it was
                self.anomaly[unjudged] = prev[unjudged]
                held[unjudged] = self.held[unjudged]
            self.held = held
        s_akf = self.severity_of(self.anomaly)
        severity = np.maximum(s_akf, np.nan_to_num(s_level)) if self.combined else s_akf
        if unjudged is not None and unjudged.any():
            severity = np.where(unjudged, self._last_severity, severity)
        d = Decision(
            slot=self.slot, period=self.periods, transient=transient,
            cnt=self.cnt.copy(), anomaly=self.anomaly.copy(), prev_anomaly=prev,
            severity=severity, prev_severity=self._last_severity.copy(),
            f_r=self.f_r.copy(), missing=self.missing.copy(),
            severity_akf=s_akf, level=level, severity_level=s_level, held=self.held.copy(),
            held_max=int(self.held.max()), no_signal=signal_lost,
            quietest=self._quietest.copy() if self.combined else None, no_data=no_data, flat=flat,
            flat_quarter=None if flat is None else self._flat_quarter.copy(),
            flat_share=None if flat is None else self._flat_share.copy(), flat_slots=flat_slots,
        )
        self._last_severity = severity.copy()
        self.cnt[:] = 0
        self.missing[:] = 0
        self.phase = 0
        self.periods += 1
        if self.period != self.nominal_period:      # the period of a change of rate is over
            self._resize(self.nominal_period)
        return d

    def _decide_many(self, outlier: np.ndarray, valid: np.ndarray) -> list[Decision]:
        """The decisions of K whole periods (outlier (K period, C, n), valid (K period, C)),
        after the transient and without the level part, in one pass: what K calls of
        :meth:`_decide` give, array for array (integer counts and flags; the severity index
        the same products and maxima)."""
        P, C, n = self.period, self.C, self.n
        K = outlier.shape[0] // P
        # counts in a narrow type (faster), exact while a period has fewer than 65536 slots
        cnt = outlier.reshape(K, P, C * n).sum(axis=1, dtype=np.uint16 if P < 1 << 16 else np.int64)
        cnt = cnt.astype(np.int64).reshape(K, C, n)
        missing = np.zeros((K, C), dtype=np.int64) if valid.all() else \
            (~valid).reshape(K, P, C).sum(axis=1, dtype=np.int64)
        fr = self.f_r[:, None]
        set_ = cnt >= fr
        decided = set_ | (cnt < self.c[:, None] * fr)
        # F_a: set or cleared where decided (set if the last decided period set it), else kept
        ks = np.arange(K)[:, None, None]
        last = np.maximum.accumulate(np.where(decided, ks, -1), axis=0)
        last_set = np.maximum.accumulate(np.where(set_, ks, -1), axis=0)
        prev0 = self.anomaly
        anomaly = np.where(last >= 0, (last_set == last) & (last >= 0), prev0[None] == 1).astype(np.uint8)
        # held: decisions in a row that kept a flag by the hysteresis alone
        kept = (anomaly == 1) & ~set_
        reset = np.maximum.accumulate(np.where(kept, -1, ks), axis=0)
        held = np.where(kept, np.where(reset >= 0, ks - reset, ks + 1 + self.held[None]), 0)
        s_akf = (anomaly * self.level_weights).max(axis=-1)
        prev_anomaly = np.concatenate((prev0[None], anomaly[:-1]))
        prev_sev = np.concatenate((self._last_severity[None], s_akf[:-1]))
        held_max = held.reshape(K, -1).max(axis=1).tolist()
        nan = np.full(C, np.nan)
        judged = np.zeros(C, dtype=bool)       # no period here lacks half its observations
        judged.flags.writeable = False
        f_r = self.f_r.copy()
        out = []
        slot, period = self.slot, self.periods
        # the periods' rows as views, by list() (one call each instead of one index per period)
        for k, (c_k, a_k, pa_k, s_k, ps_k, m_k, h_k, hm_k) in enumerate(zip(
                list(cnt), list(anomaly), list(prev_anomaly), list(s_akf), list(prev_sev), list(missing),
                list(held), held_max)):
            slot += P
            out.append(Decision(slot=slot, period=period + k, transient=False, cnt=c_k, anomaly=a_k,
                                prev_anomaly=pa_k, severity=s_k, prev_severity=ps_k, f_r=f_r, missing=m_k,
                                severity_akf=s_k, level=nan, severity_level=nan, held=h_k, held_max=hm_k,
                                no_data=judged))
        self.slot = slot
        self.periods += K
        self.anomaly, self.held = anomaly[-1].copy(), held[-1].copy()
        self._last_severity = s_akf[-1].copy()
        return out

    def _flat_part(self) -> tuple[np.ndarray | None, np.ndarray | None]:
        """(C, 4) the lowest and highest count of the period's flat blocks (NaN: none), how many
        there were and how many blocks were looked at, and (period, C) which slots were flat (None,
        None: no flat block, and no channel without signal for them).  Sets, with ``flat_signal``
        on, the channels with a flat quarter (every block that came in it flat, one at least) in
        ``_flat_quarter``, those whose flat blocks are at least a quarter of the blocks looked at in
        ``_flat_share``, and those with no block looked at in ``_unlooked``."""
        C = self.C
        if not self._flat_seen and not self._lost_flat.any():
            self._flat_quarter, self._flat_share, self._unlooked = (np.zeros(C, dtype=bool) for _ in range(3))
            return None, None
        f, came = self._flat, self._came
        looked = came & (f != NOT_LOOKED)
        is_flat = looked & (f >= 0)
        moved = looked & ~is_flat
        quarters = [(came[a:b].any(axis=0) & ~moved[a:b].any(axis=0) & is_flat[a:b].any(axis=0))
                    for a, b in _quarters(len(f))]
        assert self.flat_signal is not None
        n, seen = is_flat.sum(axis=0), looked.sum(axis=0)
        self._flat_quarter = np.any(quarters, axis=0) & self.flat_signal
        self._flat_share = (n > 0) & (4 * n >= seen) & self.flat_signal
        self._unlooked = seen == 0
        self._flat_seen = False
        lo = np.where(is_flat, f, np.inf).min(axis=0)
        hi = np.where(is_flat, f, -np.inf).max(axis=0)
        return np.stack([np.where(n > 0, lo, np.nan), np.where(n > 0, hi, np.nan), n, seen], axis=1), is_flat.copy()

    def _level_part(self, transient: bool) -> tuple[np.ndarray, np.ndarray]:
        """(level ratio, S_level) of the period; NaN in the paper's mode. The ratio is the
        period's RMS over the baseline: the root mean square of its block ratios (received)."""
        nan = np.full(self.C, np.nan)
        if not self.combined:
            return nan, nan
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)   # an all-missing period (or quarter)
            sq = np.square(self._level)
            level = np.sqrt(np.nanmean(sq, axis=0))
            quarters = np.sqrt(np.stack([np.nanmean(q, axis=0) for q in np.array_split(sq, 4) if len(q)]))
            self._quietest = np.nanmin(quarters, axis=0)
        self._quiet = self._quietest < self.signal_floor      # NaN (no quarter received): not quiet
        self._level[:] = np.nan
        if transient:
            return level, np.zeros(self.C)
        assert self.level_alert is not None and self.level_danger is not None
        return level, level_severity(level, self.n, self.level_alert, self.level_danger)


def _quarters(n: int) -> list[tuple[int, int]]:
    """(start, end) of the quarters of ``n`` slots, the slots of :func:`numpy.array_split`'s four
    parts (the first ``n % 4`` one longer; none empty), as the quiet quarters are taken."""
    size, extra = divmod(n, 4)
    edges = [k * size + min(k, extra) for k in range(5)]
    return [(a, b) for a, b in zip(edges, edges[1:]) if b > a]
