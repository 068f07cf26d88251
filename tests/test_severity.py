"""Fig. 3 anomaly decisions and eqs. (17)-(18) of Kim et al. 2023."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cmsensord.dsp.severity import AnomalyDecider


def run_counts(decider, counts_per_period):
    """Feed periods whose outlier counts per AKF are given: list of (C, n) int arrays."""
    out = []
    for cnt in counts_per_period:
        cnt = np.asarray(cnt)
        C, n = cnt.shape
        flags = np.zeros((decider.period, C, n), dtype=np.uint8)
        for c in range(C):
            for i in range(n):
                flags[: cnt[c, i], c, i] = 1
        out += decider.update(flags, np.ones((decider.period, C), bool))
    return out


def test_fig3_set_keep_clear_with_hysteresis():
    d = AnomalyDecider(1, 1, f_r=28.66, c=0.4, period=100)
    # transient, then: 29 >= f_r sets; 20 (between c f_r = 11.46 and f_r) keeps; 11 < 11.46 clears
    seq = [[[50]], [[29]], [[20]], [[12]], [[11]], [[28]], [[29]]]
    decisions = run_counts(d, seq)
    flags = [int(x.anomaly[0, 0]) for x in decisions]
    assert decisions[0].transient and flags[0] == 0
    assert flags[1:] == [1, 1, 1, 0, 0, 1]
    assert [int(x.cnt[0, 0]) for x in decisions] == [50, 29, 20, 12, 11, 28, 29]


def test_severity_index_is_max_of_i_over_n():
    d = AnomalyDecider(2, 10, f_r=10.0, c=0.4, period=100)
    cnt0 = np.zeros((2, 10), int)
    cnt1 = np.zeros((2, 10), int)
    cnt1[0, :4] = 30          # AKF_1..AKF_4 of channel 0 flag: S_idx = 4/10
    cnt1[1, [1, 6]] = 30      # AKF_2 and AKF_7 of channel 1: S_idx = 7/10
    decisions = run_counts(d, [cnt0, cnt1])
    np.testing.assert_allclose(decisions[1].severity, [0.4, 0.7])
    np.testing.assert_allclose(decisions[1].prev_severity, [0.0, 0.0])


def test_missing_slots_count_toward_the_period_and_are_reported():
    d = AnomalyDecider(1, 2, f_r=5.0, c=0.4, period=10)
    flags = np.zeros((25, 1, 2), dtype=np.uint8)
    valid = np.ones((25, 1), bool)
    valid[12:15] = False
    ds = d.update(flags, valid)
    assert [x.slot for x in ds] == [10, 20]
    assert ds[1].missing[0] == 3 and ds[0].missing[0] == 0


def test_a_period_lacking_more_than_half_its_observations_is_not_judged():
    """F_a set in period 1; period 2 has 6 of 10 slots missing (no outlier counted): F_a and
    S_idx held, no_data; period 3 has 5 missing (half): judged, and cleared (0 < c f_r)."""
    d = AnomalyDecider(1, 2, f_r=5.0, c=0.4, period=10, transient_periods=0)
    flags = np.zeros((30, 1, 2), dtype=np.uint8)
    flags[:6, 0, :] = 1
    valid = np.ones((30, 1), bool)
    valid[10:16] = False
    valid[20:25] = False
    ds = d.update(flags, valid)
    assert [x.anomaly[0].tolist() for x in ds] == [[1, 1], [1, 1], [0, 0]]
    assert [float(x.severity[0]) for x in ds] == [1.0, 1.0, 0.0]
    assert [bool(x.no_data[0]) for x in ds] == [False, True, False]


@pytest.mark.parametrize("seed", range(12))
def test_whole_periods_in_one_pass_decide_as_one_period_at_a_time(monkeypatch, seed):
    """AnomalyDecider.update decides a run of whole periods in one pass: every
    decision, field for field and type for type, and the state after, as the period-by-period
    loop gives; with hysteresis (set, kept, cleared), held flags, missing slots, the transient,
    a new f_r in some calls and blocks cut anywhere."""
    from cmsensord.dsp import severity

    rnd = np.random.default_rng(seed)
    C, n, P = 3, 5, 20
    T = 40 * P + int(rnd.integers(0, P))
    rate = np.repeat(rnd.choice([0.05, 0.3, 0.45, 0.8], size=(T // P + 1, C, n)), P, axis=0)[:T]
    flags = (rnd.random((T, C, n)) < rate).astype(np.uint8)
    valid = rnd.random((T, C)) > rnd.choice([0.0, 0.05])
    if seed % 3 == 0:                     # a link down: periods not judged (Decision.no_data)
        valid[5 * P + 3:8 * P, int(rnd.integers(0, C))] = False
    flags[~valid] = 0
    cuts = np.sort(rnd.choice(np.arange(1, T), size=int(rnd.integers(0, 6)), replace=False)).tolist()
    f_rs = [None if rnd.random() < 0.6 else rnd.uniform(3.0, 12.0, size=C) for _ in range(len(cuts) + 1)]

    def decide(one_pass: int):
        monkeypatch.setattr(severity, "ONE_PASS_PERIODS", one_pass)
        d = AnomalyDecider(C, n, f_r=[6.0, 8.0, 10.0], c=0.4, period=P)
        got = []
        for (a, b), fr in zip(zip([0, *cuts], [*cuts, T]), f_rs):
            got += d.update(flags[a:b], valid[a:b], f_r=fr)
        return d, got

    (d1, got), (d0, ref) = decide(1), decide(1 << 60)
    assert len(got) == len(ref) == T // P
    for a, b in zip(got, ref):
        for f in dataclasses.fields(a):
            x, y = getattr(a, f.name), getattr(b, f.name)
            if isinstance(y, np.ndarray):
                assert x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True), f.name
            else:
                assert type(x) is type(y) and x == y, f.name
    for name in ("anomaly", "held", "_last_severity", "cnt", "missing"):
        assert np.array_equal(getattr(d1, name), getattr(d0, name)), name
    assert (d1.periods, d1.slot, d1.phase) == (d0.periods, d0.slot, d0.phase)
    assert {0, 1} <= {int(v) for x in ref for v in x.anomaly.ravel()}          # flags set and clear
    assert any(x.no_data is not None and x.no_data.any() for x in ref) == (seed % 3 == 0)
    assert any(x.held_max > 0 for x in ref)                                    # kept by hysteresis


@pytest.mark.parametrize("level", [False, True])
def test_a_new_period_keeps_the_share_of_the_period_in_progress(level):
    """100 slots a period, 60 in when the rate halves (set_period(50)): the period in progress ends
    20 slots on (its 40 left at half the rate), the next ones are 50 long, in any parts; a level ratio
    (combined mode) is kept across the change."""
    d = AnomalyDecider(1, 1, f_r=5.0, c=0.4, period=100, level_alert=[2.0] if level else None)
    flags = np.zeros((400, 1, 1), dtype=np.uint8)
    valid = np.ones((400, 1), bool)
    lv = np.ones((400, 1)) if level else None
    out = d.update(flags[:160], valid[:160], level=None if lv is None else lv[:160])
    d.set_period(50)
    for a, b in ((160, 170), (170, 181), (181, 300)):
        out += d.update(flags[a:b], valid[a:b], level=None if lv is None else lv[a:b])
    assert [x.slot for x in out] == [100, 180, 230, 280]
    assert (d.period, d.nominal_period, d.phase) == (50, 50, 20)
    if level:
        assert [float(x.level[0]) for x in out] == [1.0] * 4
