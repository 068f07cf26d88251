"""compute() (one shared transform, power read only where used) against a plain reference of
each indicator: the formulas of the module docstrings, one transform per quantity.

Where the new path only reorders a computation (the waveform statistics, the line search)
it must give the reference's numbers bit for bit; where it derives the Hann spectrum from
the unwindowed transform it must agree to 1e-9 relative, or, for a number at the
floating-point noise floor of the record (a band or a line with nothing in it), to 1e-12
of the record's RMS.
"""

from __future__ import annotations

import numpy as np
import pytest

from cmsensord.dsp.indicators import Band, Bearing, Setup, compute
from cmsensord.dsp.indicators.bearings import DEFECTS, Geometry, defect_frequencies
from cmsensord.dsp.indicators.envelope import default_band, envelope, envelope_of_rfft, line_peak
from cmsensord.dsp.indicators.spectrum import hann, hann_power_bins
from cmsensord.dsp.indicators.statistics import waveform_stats

FS = 25000
BEARING = Bearing("de", Geometry(9, 9.525, 46.0))
BANDS = (Band("low", 10, 1000), Band("1x", 0.8, 1.2, orders=True), Band("all", 0, 20000),
         Band("top", 12000, 12500), Band("dc", 0, 3), Band("empty", 700, 600), Band("3x", 2.9, 3.1, orders=True))


# ------------------------------------------------------------------ the plain reference
def plain_stats(x):
    d = x - x.mean()
    m2 = np.mean(d ** 2)
    peak = np.max(np.abs(d))
    return np.sqrt(m2), peak, peak / np.sqrt(m2), np.mean(d ** 4) / m2 ** 2


def plain_power(x):
    """The one-sided Hann power spectrum: P_k = c_k |X_k|^2 / (N sum w^2), X of the windowed,
    mean-removed record."""
    N = x.size
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(N) / N)
    P = np.abs(np.fft.rfft((x - x.mean()) * w)) ** 2 / (N * np.sum(w ** 2))
    P[1:(N + 1) // 2] *= 2
    return np.fft.rfftfreq(N, 1 / FS), P


def plain_line(f, A, f0, slip):
    df = f[1] - f[0]
    half = max(slip * f0, df)
    if not (f0 > 0 and f0 + half <= f[-1]):
        return None
    win = np.flatnonzero((f >= f0 - half) & (f <= f0 + half))
    i = win[np.argmax(A[win])]
    floor = np.median(A[(f >= 0.5 * f0) & (f <= 1.5 * f0)])
    amp = plain_hann_peak(A, i)
    return amp, f[i], amp / floor if floor > 0 else np.nan


def plain_hann_peak(A, i):
    """Grandke 1983 for the Hann window: the offset delta from the ratio of the larger
    neighbour to bin i, the amplitude A[i] over the Hann kernel at delta."""
    side = max(A[i - 1] if i > 0 else 0.0, A[i + 1] if i + 1 < A.size else 0.0)
    if A[i] <= 0 or side > A[i]:
        return A[i]
    alpha = side / A[i]
    delta = float(np.clip((2 * alpha - 1) / (alpha + 1), 0.0, 0.5))
    if delta == 0:
        return A[i]
    return A[i] * np.pi * delta * (1 - delta ** 2) / np.sin(np.pi * delta)


def plain_unresolved(name, lines, slip, df):
    """Line ``name`` of ``lines`` (name -> Hz) is not resolved by bins of df: its window
    +/- max(slip f0, df) is wider than +/- max(slip, 10 %) of f0, or overlaps another line's."""
    f0 = lines[name]
    h0 = max(slip * f0, df)
    return h0 > max(slip, 0.10) * f0 or any(abs(f1 - f0) < h0 + max(slip * f1, df)
                                           for k, f1 in lines.items() if k != name)


def plain_record(x, setup, shaft_hz):
    """Every number of compute(x, setup, shaft_hz).values(), one transform per quantity."""
    rms, peak, crest, kurt = plain_stats(x)
    f, P = plain_power(x)
    vm = (f >= setup.velocity_band[0]) & (f <= setup.velocity_band[1]) & (f > 0)
    out = {"accel_rms": rms, "accel_peak": peak, "crest_factor": crest, "kurtosis": kurt}
    if vm.any():                                        # a band that holds no bin has no value
        out["velocity_rms_mm_s"] = 1000 * np.sqrt(np.sum(P[vm] / (2 * np.pi * f[vm]) ** 2))
    env = envelope(x, FS, setup.envelope_band)
    e = env.env - env.env.mean()
    if env.band[0] < env.band[1]:                       # one bin is a tone: a constant envelope, none
        out["envelope_rms"] = np.sqrt(np.mean(e ** 2))
    if shaft_hz is not None:
        A = np.abs(np.fft.rfft(e * hann(e.size))) * 2 / hann(e.size).sum()
        fe = np.fft.rfftfreq(e.size, 1 / env.fs_env)
        for b in setup.bearings:
            lines = {name + ("" if h == 1 else f"_{h}x"): h * f0
                     for name, f0 in zip(DEFECTS, defect_frequencies(b.geometry, shaft_hz)) for h in (1, 2)}
            for name, f0 in lines.items():
                line = None if plain_unresolved(name, lines, setup.slip, fe[1]) else \
                    plain_line(fe, A, f0, setup.slip)
                if line is not None:
                    out[f"{b.name}.{name}"] = line[0]
                if line is not None and line[2] == line[2]:     # how far it stands out (NaN: no floor)
                    out[f"{b.name}.{name}_ratio"] = line[2]
    for band in setup.bands:
        if band.orders and shaft_hz is None:
            continue
        lo, hi = (band.lo * shaft_hz, band.hi * shaft_hz) if band.orders else (band.lo, band.hi)
        if ((f >= lo) & (f <= hi)).any():
            out[f"band.{band.name}"] = np.sqrt(np.sum(P[(f >= lo) & (f <= hi)]))
    return out


# ------------------------------------------------------------------ records
def records():
    rng = np.random.default_rng(13)
    t = np.arange(FS) / FS
    bpfo = defect_frequencies(BEARING.geometry, 28.66).bpfo
    carrier = np.sin(2 * np.pi * 4100 * t) * (1 + 0.6 * np.cos(2 * np.pi * bpfo * t))
    impacts = rng.normal(0, 0.3, FS)
    impacts[::733] += 9.0
    return {
        "noise with a DC offset": rng.normal(0, 2.0, FS) + 9.81,
        "modulated carrier": 3 * carrier + 0.05 * rng.normal(size=FS),
        "impacts": impacts,
        "tones and noise": np.sin(2 * np.pi * 28.66 * t) + 0.4 * np.sin(2 * np.pi * 86 * t) + rng.normal(0, .1, FS),
        "pure sine": np.sin(2 * np.pi * 5000 * t),
        "odd length": rng.normal(size=FS - 1) + 1.0,
        "short": rng.normal(size=1001),
        "four samples": rng.normal(size=4),
    }


@pytest.mark.filterwarnings("ignore:Mean of empty slice", "ignore:invalid value encountered")  # "short": a floor
@pytest.mark.parametrize("shaft_hz", [28.66, None])                        # with no bin, in both
@pytest.mark.parametrize("name", list(records()))
def test_compute_equals_the_plain_reference(name, shaft_hz):
    x = records()[name]
    setup = Setup(FS, (10.0, 1000.0), default_band(FS), bearings=(BEARING,), bands=BANDS)
    got = compute(x, setup, shaft_hz).values()
    ref = plain_record(x, setup, shaft_hz)
    floor = 1e-12 * np.sqrt(np.mean((x - x.mean()) ** 2))
    assert got.keys() - {"zone"} == ref.keys()
    for k, v in ref.items():
        if k.endswith("_ratio") and ref[k.removesuffix("_ratio")] <= 1e3 * floor:
            continue                                  # a ratio of two numbers at the noise floor: any
        assert abs(got[k] - v) <= 1e-9 * abs(v) + floor, (k, got[k], v)
    if name == "modulated carrier" and shaft_hz:      # the reference is not vacuous: the line is there
        assert ref["de.bpfo"] > 0.5 and ref["de.bpfo_ratio"] > 10


@pytest.mark.parametrize("name", list(records()))
def test_waveform_statistics_are_the_plain_ones_bit_for_bit_and_compute_reads_them(name):
    x = records()[name]
    s = waveform_stats(x)
    d = x - x.mean()
    assert s.peak == np.max(np.abs(d)) and s.rms == (float((d * d).sum()) / d.size) ** 0.5
    assert compute(x, Setup(FS, (10.0, 1000.0), default_band(FS))).accel == s
    y = x.copy()
    y[3] = np.nan                                    # the finite samples only
    assert waveform_stats(y) == waveform_stats(np.delete(x, 3))


@pytest.mark.parametrize("N", [2, 3, 4, 5, 64, 1001, 25000])
def test_hann_power_of_any_bin_range_equals_the_windowed_transform(N):
    x = np.random.default_rng(N).normal(size=N) + 2.0
    _, P = plain_power(x)
    X = np.fft.rfft(x - x.mean())
    K = N // 2 + 1
    for a, b in {(0, K), (0, 1), (K - 1, K), (1, K - 1), (0, min(3, K)), (K // 2, K), (1, 1)}:
        got = hann_power_bins(X, N, a, b)
        assert got.shape == (max(0, b - a),)
        np.testing.assert_allclose(got, P[a:b], rtol=1e-9, atol=1e-12 * P.sum())


def test_envelope_of_the_shared_transform_equals_the_envelope_of_the_record():
    x = records()["modulated carrier"]
    for band in (default_band(FS), (3000.0, 3000.0), (5000.0, 4000.0), (0.0, 20000.0)):
        ref = envelope(x, FS, band)
        got = envelope_of_rfft(np.fft.rfft(x), x.size, FS, band)
        assert (got.fs_env, got.band) == (ref.fs_env, ref.band)
        np.testing.assert_allclose(got.env, ref.env, rtol=1e-9, atol=1e-12 * np.abs(x).max())


def test_the_line_search_is_the_plain_one_bit_for_bit():
    x = records()["modulated carrier"]
    e = envelope(x, FS, default_band(FS)).env
    e = e - e.mean()
    A = np.abs(np.fft.rfft(e * hann(e.size)))
    f = np.fft.rfftfreq(e.size, 1 / 16200)
    for f0 in (0.7, 1.0, 35.2, 102.9, 301.0, 8000.0, 8099.0):
        for slip in (0.0, 0.02, 0.1):
            got, ref = line_peak(f, A, f0, slip), plain_line(f, A, f0, slip)
            assert (got is None) == (ref is None)
            if got is not None:
                assert got == ref
