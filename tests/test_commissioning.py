"""Commissioning (dsp.commissioning) and the combined severity (dsp.severity)."""

import numpy as np
import pytest

from cmsensord.dsp.akf import AkfBank, bank_r
from cmsensord.dsp.commissioning import (
    MARGIN,
    R_GRID,
    SPAN,
    bank_limits,
    critical_r,
    held_flags,
    idle_periods,
    learn_healthy,
    level_rise,
    period_counts,
    run_in_periods,
    steady_length,
)
from cmsensord.dsp.severity import AnomalyDecider, level_severity

KW = dict(period=100, n=10, window=10, z_c=2.8)


def _healthy(seconds, level=3.0, sigma=0.05, seed=0):
    """Block RMS of a healthy machine: a steady level with small relative fluctuation."""
    rng = np.random.default_rng(seed)
    return level * (1.0 + sigma * rng.standard_normal(seconds * 100))


def _run(y, model, f_r, **decider):
    u = y / model.baseline
    bank = AkfBank(bank_r(model.r_min, model.r_max, 10)[None], window=10, z_c=2.8)
    dec = AnomalyDecider(1, 10, f_r=f_r, c=0.4, period=100, **decider)
    out = bank.process(u[:, None])
    level = u[:, None] if decider else None
    return dec.update(out.outlier, out.valid, level=level)


@pytest.mark.parametrize("r_1", [1e-5, 3e-3, 0.2])
def test_bank_limits_give_r1_and_span(r_1):
    r_min, r_max = bank_limits(r_1, 10)
    R = bank_r(r_min, r_max, 10)
    assert R[0] == pytest.approx(r_1, rel=1e-12)
    assert R[-1] == pytest.approx(SPAN * r_1, rel=1e-12)


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5])
def test_bank_limits_keep_r1_for_small_banks(n):
    """n <= SPAN: R_1 stays r_1 (guards against n 2..4 giving AKF_1 a larger R than the one checked)."""
    r_min, r_max = bank_limits(2e-3, n)
    R = bank_r(r_min, r_max, n)
    assert R[0] == pytest.approx(2e-3, rel=1e-12) and 0 < r_min < r_max
    assert R[-1] == pytest.approx(min(SPAN * 2e-3, n * 2e-3 - (n - 1) * 2e-3 / SPAN), rel=1e-12)


def test_critical_r_is_the_first_quiet_r():
    grid = np.array([1e-3, 1e-2, 1e-1])
    counts = np.array([[40, 20, 3], [10, 5, 1], [50, 45, 40]])
    r = critical_r(counts, 30.0, grid)
    assert r.tolist() == [1e-2, 1e-3, np.inf]


def test_counts_fall_with_r():
    c = period_counts(_healthy(5), R_GRID[::10], period=100, window=10, z_c=2.8)
    assert c.shape == (5, R_GRID[::10].size)
    assert np.all(np.diff(c.sum(axis=0)) <= 2)


def test_learned_model_is_quiet_on_new_healthy_data_and_flags_a_change():
    m = learn_healthy(_healthy(60, seed=1), f_r=30.0, **KW)
    assert m.baseline == pytest.approx(3.0, rel=0.01)
    assert m.r_1 == pytest.approx(MARGIN * m.healthy_r)
    assert m.flagged == 0 and m.max_cnt < 30
    quiet = _run(_healthy(60, seed=2), m, 30.0)
    assert max(d.severity[0] for d in quiet) == 0.0
    rough = _healthy(30, sigma=0.25, seed=3)       # the fluctuation grows 5x at the same level
    flagged = _run(np.concatenate([_healthy(30, seed=4), rough]), m, 30.0)
    assert max(d.severity[0] for d in flagged[31:]) >= 0.5


def test_held_flags_are_the_deciders_for_one_akf():
    """Set at f_r, kept while the count stays at c f_r or more, cleared below: the flags the
    monitor's AnomalyDecider shows for the same counts."""
    cnt = np.array([3, 30, 12, 11, 31, 5, 29, 40])
    assert held_flags(cnt, 30.0, 0.4).tolist() == [False, True, True, False, True, False, False, True]
    dec = AnomalyDecider(1, 1, f_r=30.0, c=0.4, period=40)
    outlier = np.zeros((40 * (cnt.size + 1), 1, 1), dtype=bool)
    for k, v in enumerate(cnt):
        outlier[40 * (k + 1):40 * (k + 1) + v] = True
    ds = dec.update(outlier, np.ones((outlier.shape[0], 1), dtype=bool))[1:]
    assert [bool(d.anomaly[0, 0]) for d in ds] == held_flags(cnt, 30.0, 0.4).tolist()


def test_r_scales_with_the_baseline_not_the_unit():
    a = learn_healthy(_healthy(40, seed=5), f_r=30.0, **KW)
    b = learn_healthy(1000.0 * _healthy(40, seed=5), f_r=30.0, **KW)
    assert (a.r_min, a.r_max) == pytest.approx((b.r_min, b.r_max), rel=1e-9)
    assert b.baseline == pytest.approx(1000.0 * a.baseline)


def test_run_in_is_left_out():
    y = _healthy(80, seed=6)
    y[100:1600] *= 1.0 + 0.5 * np.random.default_rng(7).standard_normal(1500).clip(-1, 1)
    m = learn_healthy(y, f_r=30.0, **KW)
    plain = learn_healthy(y[1600:], f_r=30.0, **KW)
    assert m.runin_periods == 19          # the first quarter of the 79 learned periods
    assert m.r_1 == pytest.approx(plain.r_1, rel=0.5)


def test_the_healthy_periods_own_levels_at_level_alert_are_counted_and_placed():
    """A step to 2.5 x the level in the last 5 of 40 s: those decisions are the ones the
    combined severity grades 0.5 (the replay would report them), placed by period number."""
    y = _healthy(40, seed=11)
    y[3500:] *= 2.5
    plain = learn_healthy(y, f_r=30.0, **KW)
    m = learn_healthy(y, f_r=30.0, level_alert=2.0, **KW)
    assert (plain.level_flagged, plain.level_first, plain.any_flagged) == (0, -1, plain.flagged)
    assert (m.level_flagged, m.level_first, m.level_last) == (5, 35, 39)
    assert m.any_flagged >= 5 and m.steady_head == 34
    s = _run(y, m, 30.0, level_alert=2.0, level_danger=4.0)
    assert [d.period for d in s if d.severity[0] >= 0.5 and d.period < 40][:1] == [35]


def test_a_machine_stopped_for_most_of_the_healthy_period_is_learned_from_its_running_seconds():
    """Running 20 of 60 s (at 3.0), stopped the rest (at 0.03): the baseline is the running
    level, not the stopped one (which made every running second 100 x baseline), and the model
    is the running seconds' alone."""
    run = _healthy(60, seed=12)
    y = run.copy()
    for a, b in ((5, 25), (35, 55)):
        y[a * 100:b * 100] *= 0.01
    m = learn_healthy(y, f_r=30.0, level_alert=2.0, **KW)
    alone = learn_healthy(np.concatenate([run[100:500], run[2600:3400], run[5600:]]), f_r=30.0, **KW)
    assert m.baseline == pytest.approx(3.0, rel=0.02)
    assert m.idle_periods == 40 + 4 and m.level_flagged == 0          # 40 stopped, 4 beside them
    assert m.r_1 == pytest.approx(alone.r_1, rel=1.0)
    assert m.learned == 59 - m.idle_periods


def test_idle_periods_are_the_stopped_and_their_neighbours_only():
    level = np.r_[np.ones(10), np.full(5, 0.01), np.ones(10), np.nan, np.ones(3)]
    assert np.flatnonzero(idle_periods(level)).tolist() == list(range(9, 16))
    assert not idle_periods(np.r_[np.ones(20), 0.3 * np.ones(20)]).any()       # a lower load is running
    assert not idle_periods(np.full(4, np.nan)).any()


def test_steady_length_cuts_until_no_level_is_at_alert_x_its_own_median():
    step = np.r_[np.ones(30), np.full(10, 2.5)]
    assert steady_length(step, 2.0) == 30
    start = step[::-1]                                   # a loud start-up, then steady
    assert steady_length(start, 2.0) == 0 and steady_length(start[::-1], 2.0) == 30
    assert steady_length(np.ones(12), 2.0) == 12
    growth = 1.03 ** np.arange(100)                      # a level growing 3 % a second
    k = steady_length(growth, 2.0)
    assert 0 < k < 100 and growth[:k].max() < 2.0 * np.median(growth[:k])
    assert growth[:k + 1].max() >= 2.0 * np.median(growth[:k + 1]) or k + 1 > 100
    assert steady_length(np.full(5, np.nan), 2.0) == 0


def test_run_in_periods_needs_a_clear_step():
    level = np.ones(40)
    rstar = np.full(40, 1e-4)
    assert run_in_periods(level, rstar) == 0
    level[:10] = 1.5
    assert run_in_periods(level, rstar) == 10


def test_a_few_outlier_seconds_do_not_set_r():
    y = _healthy(100, seed=8)
    ref = learn_healthy(y, f_r=30.0, **KW)
    y[5000:5100:2] *= 3.0           # one loud second
    m = learn_healthy(y, f_r=30.0, **KW)
    assert m.r_1 <= 2.0 * ref.r_1


def test_faulty_capture_sets_r_max_the_papers_way():
    healthy = _healthy(40, seed=9)
    faulty = _healthy(20, sigma=0.3, seed=10)
    m = learn_healthy(healthy, f_r=30.0, faulty=faulty, **KW)
    plain = learn_healthy(healthy, f_r=30.0, **KW)
    assert m.r_1 == pytest.approx(plain.r_1)
    assert m.r_max > plain.r_max
    assert bank_r(m.r_min, m.r_max, 10)[0] == pytest.approx(m.r_1)
    last = _run(faulty, m, 30.0)[1:]
    assert np.mean([d.anomaly[0, -1] for d in last]) >= 0.5


def test_f_r_at_or_above_the_period_is_rejected():
    with pytest.raises(ValueError, match="below the 100 observations"):
        learn_healthy(_healthy(10), f_r=100.0, **KW)


def test_too_short_is_rejected():
    with pytest.raises(ValueError, match="at least 2 decision periods"):
        learn_healthy(_healthy(1), f_r=30.0, **KW)


def test_level_severity_grades():
    s = level_severity(np.array([np.nan, 1.0, 1.99, 2.0, 2.9, 4.0, 9.0]), 10, 2.0, 4.0)
    assert s.tolist() == [0.0, 0.0, 0.0, 0.5, 0.7, 1.0, 1.0]


def test_combined_severity_is_the_max_and_split_invariant():
    m = learn_healthy(_healthy(30, seed=11), f_r=30.0, **KW)
    y = np.concatenate([_healthy(20, seed=12), _healthy(10, level=7.5, seed=13)])
    whole = _run(y, m, 30.0, level_alert=2.0, level_danger=4.0)
    assert whole[-1].level[0] == pytest.approx(2.5, rel=0.02)
    for d in whole:
        assert d.severity[0] == max(d.severity_akf[0], d.severity_level[0])
    assert whole[-1].severity_level[0] == 0.6
    u = y / m.baseline
    bank = AkfBank(bank_r(m.r_min, m.r_max, 10)[None], window=10, z_c=2.8)
    dec = AnomalyDecider(1, 10, f_r=30.0, c=0.4, period=100, level_alert=2.0, level_danger=4.0)
    parts = []
    for chunk in np.array_split(np.arange(u.size), 7):
        out = bank.process(u[chunk, None])
        parts += dec.update(out.outlier, out.valid, level=u[chunk, None])
    assert [d.severity[0] for d in parts] == [d.severity[0] for d in whole]
    assert [d.prev_severity[0] for d in parts[1:]] == [d.severity[0] for d in whole[:-1]]


def test_paper_mode_has_no_level_part():
    m = learn_healthy(_healthy(10, seed=14), f_r=30.0, **KW)
    for d in _run(_healthy(10, level=9.0, seed=15), m, 30.0):
        assert np.isnan(d.level[0]) and np.isnan(d.severity_level[0])
        assert d.severity[0] == d.severity_akf[0]


def test_held_counts_decisions_kept_by_hysteresis_alone():
    dec = AnomalyDecider(1, 1, f_r=10.0, c=0.4, period=10, transient_periods=0)
    one = np.ones((10, 1, 1), np.uint8)
    valid = np.ones((10, 1), bool)
    assert dec.update(one, valid)[0].held[0, 0] == 0          # cnt 10 >= f_r: set
    some = one.copy()
    some[:5] = 0                                              # cnt 5: 4 <= 5 < 10, kept
    assert [dec.update(some, valid)[0].held[0, 0] for _ in range(3)] == [1, 2, 3]
    assert dec.update(one, valid)[0].held[0, 0] == 0


def test_a_level_rising_through_the_period_is_found_where_it_starts():
    """Flat at 1 for 60 decisions, then a ramp to 1.8 over the last 40: the last quarter is
    well above the first, and the rise is placed at the start of the first quarter-long window
    that holds enough of it: before the ramp, never after its start (a --to there ends the
    period before it); a flat series and a run-in are no rise."""
    rng = np.random.default_rng(2)
    flat = 1.0 + 0.02 * rng.standard_normal(100)
    ramp = flat.copy()
    ramp[60:] += np.linspace(0.0, 0.8, 40)
    rise = level_rise(ramp, 0)
    assert rise is not None and 1.5 < rise[0] < 1.6 and 35 <= rise[1] <= 60, rise
    assert level_rise(flat, 0) is None
    runin = flat.copy()
    runin[:20] *= 1.5                                   # loud at the start: the run-in rule's, not a rise
    assert level_rise(runin, 0) is None


def test_a_rise_within_the_noise_of_quarter_medians_is_no_rise():
    """Decisions scattered by 60 % about their level: quarter medians of 5 decisions differ by
    25 % by chance, which their scatter from one decision to the next says; the same step in a
    quiet series is a rise."""
    rng = np.random.default_rng(4)
    step = np.r_[np.ones(10), np.full(10, 1.3)]
    assert level_rise(step * np.exp(0.6 * rng.standard_normal(20)), 0) is None
    assert level_rise(step * (1.0 + 0.01 * rng.standard_normal(20)), 0) is not None


def test_a_ramp_from_the_start_is_placed_near_its_start():
    """The scatter is taken from one decision to the next: a steady ramp is no part of it, so the
    rise is found where it starts, not half way."""
    rng = np.random.default_rng(3)
    ramp = np.linspace(1.0, 2.0, 60) * (1.0 + 0.02 * rng.standard_normal(60))
    rise = level_rise(ramp, 0)
    assert rise is not None and rise[1] <= 5, rise
