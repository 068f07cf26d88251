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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["AnomalyDecider", "Decision"]


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


class AnomalyDecider:
    """Fig. 3 decisions and eqs. (17)-(18) for C channels x n AKFs.

    ``period`` is the number of observation slots per decision (100 for 1 s
    at 100 Hz).  State (cnt, F_a, position in the period) is carried between
    calls, so a stream may be split anywhere.
    """

    def __init__(self, n_channels: int, n_filters: int, *, f_r, c, period: int = 100,
                 transient_periods: int = 1):
        if period < 1:
            raise ValueError(f"period: expected >= 1 observation, got {period}")
        self.C, self.n = n_channels, n_filters
        self.f_r = np.broadcast_to(np.asarray(f_r, dtype=np.float64), (n_channels,)).copy()
        self.c = np.broadcast_to(np.asarray(c, dtype=np.float64), (n_channels,)).copy()
        self.period = int(period)
        self.transient_periods = int(transient_periods)
        self.cnt = np.zeros((n_channels, n_filters), dtype=np.int64)
        self.anomaly = np.zeros((n_channels, n_filters), dtype=np.uint8)
        self.missing = np.zeros(n_channels, dtype=np.int64)
        self.phase = 0            # slots seen in the current period
        self.periods = 0          # decisions made
        self.slot = 0             # slots seen in total
        self.level_weights = np.arange(1, n_filters + 1, dtype=np.float64) / n_filters  # i/n

    def severity_of(self, anomaly: np.ndarray) -> np.ndarray:
        """S_idx = max_i I_i with I_i = i/n F_a,i (eqs. 17-18); 0 when no flag is set."""
        return (anomaly * self.level_weights).max(axis=-1)

    def update(self, outlier: np.ndarray, valid: np.ndarray, f_r=None) -> list[Decision]:
        """Count a block of T observation slots; return the decisions it completes.

        outlier: (T, C, n) flags; valid: (T, C) False for missing observations.
        f_r: optional (C,) rotation frequency for decisions in this block (tacho).
        """
        outlier = np.asarray(outlier)
        T = outlier.shape[0]
        if outlier.shape[1:] != (self.C, self.n):
            raise ValueError(f"outlier: expected shape (T, {self.C}, {self.n}), got {outlier.shape}")
        if f_r is not None:
            self.f_r = np.broadcast_to(np.asarray(f_r, dtype=np.float64), (self.C,)).copy()
        decisions: list[Decision] = []
        start = 0
        while start < T:
            take = min(T - start, self.period - self.phase)
            seg = slice(start, start + take)
            self.cnt += outlier[seg].sum(axis=0, dtype=np.int64)
            self.missing += (~np.asarray(valid[seg], dtype=bool)).sum(axis=0)
            self.phase += take
            self.slot += take
            start += take
            if self.phase == self.period:
                decisions.append(self._decide())
        return decisions

    def _decide(self) -> Decision:
        prev = self.anomaly.copy()
        transient = self.periods < self.transient_periods
        if not transient:
            fr = self.f_r[:, None]
            set_ = self.cnt >= fr                       # cnt >= f_r  -> F_a = 1
            clear = self.cnt < self.c[:, None] * fr     # cnt < c f_r -> F_a = 0
            self.anomaly = np.where(set_, 1, np.where(clear, 0, self.anomaly)).astype(np.uint8)
        d = Decision(
            slot=self.slot, period=self.periods, transient=transient,
            cnt=self.cnt.copy(), anomaly=self.anomaly.copy(), prev_anomaly=prev,
            severity=self.severity_of(self.anomaly), prev_severity=self.severity_of(prev),
            f_r=self.f_r.copy(), missing=self.missing.copy(),
        )
        self.cnt[:] = 0
        self.missing[:] = 0
        self.phase = 0
        self.periods += 1
        return d
