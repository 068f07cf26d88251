"""Fig. 3 anomaly decisions and eqs. (17)-(18) of Kim et al. 2023."""

from __future__ import annotations

import numpy as np

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
