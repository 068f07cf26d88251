"""compute_many(): several records' indicators with their real transforms in one call per
length (numpy's rfft costs ~0.1 ms a call on top of the transform at 25 000 points)
against compute() of each record, bit for bit: records of mixed lengths, channels with a
bearing and bands or none, with and without a shaft speed, strided columns of an interval
buffer; and the daemon's indicator messages of several intervals released at once."""

from __future__ import annotations

from dataclasses import asdict

import numpy as np
import pytest

from cmsensord.dsp.indicators import Band, Bearing, Setup, compute, compute_many
from cmsensord.dsp.indicators.bearings import Geometry
from cmsensord.dsp.indicators.envelope import default_band

FS = 25000.0
PLAIN = Setup(FS, (10.0, 1000.0), default_band(FS))
RICH = Setup(FS, (2.0, 1000.0), (1500.0, 9000.0), bearings=(Bearing("de", Geometry(9, 9.525, 46.0)),),
             bands=(Band("low", 10, 1000), Band("1x", 0.8, 1.2, orders=True)))


def same(a, b) -> bool:
    """Records equal field by field (NaN equal to NaN)."""
    da, db = asdict(a), asdict(b)
    return repr(da) == repr(db)


def test_many_records_at_once_equal_one_at_a_time_bit_for_bit():
    rng = np.random.default_rng(11)
    buf = rng.standard_normal((25000, 4)) * [1.0, 3.0, 0.1, 7.0] + np.sin(np.arange(25000) * 0.07)[:, None]
    items = [
        (buf[:, 0], PLAIN, 28.7),
        (buf[:, 1], RICH, 28.7),             # strided columns of one interval buffer
        (buf[:, 2], RICH, None),
        (buf[:, 3], PLAIN, None),
        (rng.standard_normal(12500), PLAIN, 10.0),     # another length, alone
        (rng.standard_normal(12500) + 5.0, RICH, 10.0),
        (rng.standard_normal(25000), RICH, 55.5),
        (rng.standard_normal(777), PLAIN, 30.0),
    ]
    got = compute_many(items)
    want = [compute(x, s, f) for x, s, f in items]
    assert len(got) == len(items)
    for g, w in zip(got, want):
        assert same(g, w)
        assert g.values() == w.values()
    assert compute_many([]) == []
    assert any(b.lines for r in got for b in r.bearings)           # the lines were read


def test_envelopes_of_one_band_in_one_call_equal_one_at_a_time_bit_for_bit():
    """Rows of one length and one envelope band (the daemon's intervals of one channel, a
    replay's read bringing several): their envelopes' inverse transforms in one call, and a
    band with no bin (beyond Nyquist): the records of compute(), field for field."""
    rng = np.random.default_rng(5)
    t = np.arange(25000) / FS
    burst = (1.0 + 0.5 * np.cos(2 * np.pi * 87.0 * t)) * np.sin(2 * np.pi * 4000.0 * t)
    empty = Setup(FS, (10.0, 1000.0), (13000.0, 14000.0))       # beyond fs / 2: no bin
    items = [(rng.standard_normal(25000) * k + burst, s, f)
             for k, s, f in ((1.0, PLAIN, 28.7), (2.0, PLAIN, None), (0.5, PLAIN, 30.0),
                             (1.0, RICH, 28.7), (3.0, empty, 28.7), (1.0, empty, None))]
    for some in (items[:3], items[3:], items):
        got = compute_many(some)
        for g, (x, s, f) in zip(got, some):
            w = compute(x, s, f)
            assert same(g, w) and g.values() == w.values()
    assert np.isnan(compute_many(items[4:5])[0].envelope_rms)      # nothing to read: no value


@pytest.mark.parametrize("N", [2, 3, 777, 12500, 25000])
def test_row_statistics_and_centred_envelopes_equal_the_per_row_ones_bit_for_bit(N):
    """The passes over all rows of one length (compute_many's): each row's waveform
    statistics, envelope with its mean removed and envelope RMS are those of the row alone,
    bit for bit, whatever the rows' count, scale and offset; a zero row and a band with no
    bin give the per-row numbers too."""
    from cmsensord.dsp.indicators.envelope import centred_envelopes, envelopes_of_rfft
    from cmsensord.dsp.indicators.statistics import centred_stats, centred_stats_rows

    rng = np.random.default_rng(N)
    for R in (1, 2, 3, 5):
        x = rng.standard_normal((R, N)) * rng.uniform(1e-3, 1e3, (R, 1)) + rng.uniform(-50, 50, (R, 1))
        if R == 5:
            x[2] = 4.0                                   # a constant row: zero once centred
        D = np.ascontiguousarray(x - x.mean(axis=1, keepdims=True))
        assert repr(centred_stats_rows(D)) == repr([centred_stats(D[i].copy()) for i in range(R)])
        X = np.fft.rfft(D, axis=-1)
        for band in (default_band(FS), (1500.0, 9000.0), (13000.0, 14000.0)):
            envs, rms = centred_envelopes(X, N, FS, band)
            want = envelopes_of_rfft(X, N, FS, band)
            assert len(envs) == len(rms) == R
            for e, r, w in zip(envs, rms, want):
                ref = w.env - w.env.mean()
                assert e.env.tobytes() == ref.tobytes() and (e.fs_env, e.band) == (w.fs_env, w.band)
                assert repr(r) == repr(float(np.sqrt(np.mean(ref * ref))))


@pytest.mark.parametrize("with_tacho", [False, True])
def test_several_intervals_released_together_give_the_messages_of_one_at_a_time(with_tacho):
    """The RAW chain's intervals released in one call (a replay's read brings ~2.6 s) and one
    per call (a live call): the same /indicators messages (with a tacho: their speeds read
    in one call, the same as one interval at a time)."""
    from cmsensord.config import default_config
    from cmsensord.dsp.tacho import TachoTracker
    from cmsensord.monitor.clock import BlockClock
    from cmsensord.monitor.indicators import IndicatorChain

    tacho = None
    if with_tacho:                                  # 1500-1900 rpm, ppr 1, covering the record
        tacho = TachoTracker(25000.0, 1, block_len=250)
        t = np.cumsum(25000 * 60 / np.linspace(1500.0, 1900.0, 200))
        t0 = np.arange(0, int(t[-1]) + 250, 250)
        edges = [(t[(t >= a) & (t < a + 250)] - a) * 256 for a in t0]     # 1/256 sample
        tacho.update(t0, [e.astype(np.uint32) for e in edges])

    cfg = default_config(2)
    clock = BlockClock()
    clock.set_rate(25000, 250)
    clock.anchor(0, 10**18)
    rng = np.random.default_rng(3)
    y = rng.standard_normal((25000 * 5 + 3000, 2))
    y[60000:60250, 1] = np.nan                                   # a lost frame: partial stats
    outs = []
    for step in (len(y), 2500, 37_500):        # whole intervals kept as given, or gathered
        chain = IndicatorChain(cfg, cfg.channels, fs=25000, clock=clock, tacho=lambda: tacho)
        got = []
        for a in range(0, len(y), step):
            got += chain.add_samples(a, y[a:a + step])
        got += chain.finish()
        outs.append(got)
    assert len(outs[0]) >= 10 and outs[0] == outs[1] == outs[2]
    assert any("unavailable" in m.msg for m in outs[0])
    assert all(("speed_rpm" in m.msg) == with_tacho for m in outs[0])
    if with_tacho:
        assert all(1450 < m.msg["speed_rpm"] < 1950 for m in outs[0])
