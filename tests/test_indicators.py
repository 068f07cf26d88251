"""The vibration indicators (cmsensord.dsp.indicators) against analytic and published values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cmsensord.dsp.indicators import Band, Bearing, Setup, compute
from cmsensord.dsp.indicators.bearings import Geometry, defect_frequencies
from cmsensord.dsp.indicators.envelope import default_band, envelope, envelope_spectrum, line_peak
from cmsensord.dsp.indicators.iso_zones import baseline_alarm_mm_s, zone
from cmsensord.dsp.indicators.statistics import waveform_stats
from cmsensord.dsp.indicators.velocity import velocity_band

FS = 25000
T = np.arange(FS) / FS          # one 1-s interval
IMS = Geometry(n=16, d=0.331, D=2.815, contact_angle_deg=15.17)   # Rexnord ZA-2115


def setup(**kw) -> Setup:
    return Setup(FS, (10.0, 1000.0), default_band(FS), **kw)


# --- waveform statistics ------------------------------------------------------


def test_crest_factor_of_a_sine_is_root_two_and_its_kurtosis_one_and_a_half():
    s = waveform_stats(3.0 * np.sin(2 * np.pi * 50 * T + 0.3) + 7.0)   # a DC offset is removed
    assert s.rms == pytest.approx(3.0 / math.sqrt(2), rel=1e-6)
    assert s.peak == pytest.approx(3.0, rel=1e-4)
    assert s.crest_factor == pytest.approx(math.sqrt(2), rel=1e-4)
    assert s.kurtosis == pytest.approx(1.5, rel=1e-6)


def test_kurtosis_of_gaussian_noise_is_three():
    x = np.random.default_rng(3).normal(0.0, 2.0, FS)
    s = waveform_stats(x)
    assert abs(s.kurtosis - 3.0) < 0.15             # its standard error: sqrt(24 / 25000) = 0.03
    assert s.rms == pytest.approx(2.0, rel=0.02)


def test_impacts_raise_kurtosis_and_crest_factor():
    rng = np.random.default_rng(4)
    x = rng.normal(0.0, 1.0, FS)
    x[::1000] += 12.0
    s = waveform_stats(x)
    assert s.kurtosis > 6 and s.crest_factor > 8


# --- velocity -----------------------------------------------------------------


@pytest.mark.parametrize("f0", [12.3, 50.0, 159.15, 730.4, 990.0])
def test_velocity_rms_of_a_sine_within_two_percent(f0):
    v_rms = 4.5e-3                                   # m/s, i.e. 4.5 mm/s
    a = math.sqrt(2) * v_rms * 2 * np.pi * f0 * np.cos(2 * np.pi * f0 * T + 1.1)   # d/dt of the velocity
    r = compute(a, setup())
    assert r.velocity_rms_mm_s == pytest.approx(4.5, rel=0.02)


@pytest.mark.parametrize("f0", [4.0, 1500.0])
def test_velocity_outside_the_band_is_not_counted(f0):
    a = math.sqrt(2) * 4.5e-3 * 2 * np.pi * f0 * np.cos(2 * np.pi * f0 * T)
    assert compute(a, setup()).velocity_rms_mm_s < 0.05


def test_velocity_rms_of_band_limited_noise_of_known_spectrum_within_two_percent():
    """Velocity noise with a flat one-sided PSD 2 sigma^2 / fs over 20-800 Hz (white Gaussian
    noise of variance sigma^2, every other frequency removed): its RMS is
    sqrt(2 sigma^2 (800 - 20) / fs); the acceleration is its derivative.  30 intervals."""
    n, sigma, (f1, f2) = 30 * FS, 0.05, (20.0, 800.0)
    V = np.fft.rfft(np.random.default_rng(5).normal(0.0, sigma, n))
    f = np.fft.rfftfreq(n, 1 / FS)
    V[(f < f1) | (f > f2)] = 0.0
    a = np.fft.irfft(V * (2j * np.pi * f), n)
    expected = 1000 * math.sqrt(2 * sigma ** 2 * (f2 - f1) / FS)
    ms = [compute(a[k * FS:(k + 1) * FS], setup()).velocity_rms_mm_s ** 2 for k in range(30)]
    assert math.sqrt(np.mean(ms)) == pytest.approx(expected, rel=0.02)


def test_velocity_band_is_two_to_thousand_hertz_at_or_below_600_rpm():
    assert velocity_band(1480.0) == velocity_band(600.5) == (10.0, 1000.0)
    assert velocity_band(450.0) == velocity_band(600.0) == (2.0, 1000.0)
    assert velocity_band(None) == (10.0, 1000.0)
    assert velocity_band(450.0, (5.0, 500.0)) == (5.0, 500.0)


# --- ISO 10816-3 zones ----------------------------------------------------------


@pytest.mark.parametrize("group, foundation, ab, bc, cd", [
    (1, "rigid", 2.3, 4.5, 7.1), (1, "flexible", 3.5, 7.1, 11.0),
    (2, "rigid", 1.4, 2.8, 4.5), (2, "flexible", 2.3, 4.5, 7.1)])
def test_iso_zone_boundaries(group, foundation, ab, bc, cd):
    got = [zone(v, group, foundation) for v in (0.0, ab - 1e-9, ab, bc - 1e-9, bc, cd - 1e-9, cd, 50.0)]
    assert got == ["A", "A", "B", "B", "C", "C", "D", "D"]


def test_baseline_relative_alarm_is_capped_at_one_and_a_quarter_b_c():
    assert baseline_alarm_mm_s(1.0, 2, "rigid") == pytest.approx(1.0 + 0.25 * 2.8)
    assert baseline_alarm_mm_s(3.0, 2, "rigid") == pytest.approx(1.25 * 2.8)
    r = compute(np.zeros(FS), setup(velocity_baseline_mm_s=2.0, group=1, foundation="flexible"))
    assert r.velocity_alarm_mm_s == pytest.approx(2.0 + 0.25 * 7.1)


def test_the_record_grades_its_velocity():
    f0 = 80.0
    a = math.sqrt(2) * 3.0e-3 * 2 * np.pi * f0 * np.cos(2 * np.pi * f0 * T)
    r = compute(a, setup(group=2, foundation="rigid"))
    assert r.zone == "C" and r.values()["zone"] == 2.0
    assert compute(a, setup(group=1, foundation="rigid")).zone == "B"


# --- bearing defect frequencies -----------------------------------------------


def test_bearing_frequencies_of_the_ims_rig():
    """Qiu, Lee, Lin & Yu 2006 give for the Rexnord ZA-2115 at 2000 rpm: BPFO 236.4 Hz,
    BPFI 296.9 Hz, BSF 139.9 Hz, FTF 14.8 Hz."""
    d = defect_frequencies(IMS, 2000 / 60)
    assert (round(d.bpfo, 1), round(d.bpfi, 1), round(d.bsf, 1), round(d.ftf, 1)) == (236.4, 296.9, 139.9, 14.8)


def test_bearing_orders_of_the_cwru_drive_end_bearing():
    """Case Western Reserve University bearing data centre, SKF 6205-2RS (9 balls, d 0.3126 in,
    D 1.537 in, 0 deg): BPFI 5.4152, BPFO 3.5848, FTF 0.39828, 'BSF' 4.7135 (= 2 x BSF) x shaft."""
    d = defect_frequencies(Geometry(9, 0.3126, 1.537, 0.0))
    assert d.bpfi == pytest.approx(5.4152, abs=2e-4)
    assert d.bpfo == pytest.approx(3.5848, abs=2e-4)
    assert d.ftf == pytest.approx(0.39828, abs=1e-4)
    assert 2 * d.bsf == pytest.approx(4.7135, abs=2e-4)


# --- envelope -------------------------------------------------------------------


def test_default_envelope_band_is_two_to_ten_kilohertz_at_25_kilohertz():
    assert default_band(25000) == pytest.approx((2000.0, 10000.0))


def test_envelope_of_an_amplitude_modulated_carrier():
    """(1 + 0.5 cos(2 pi 297 t)) sin(2 pi 5000 t): envelope 1 + 0.5 cos(...), a line of 0.5 at 297 Hz."""
    x = (1 + 0.5 * np.cos(2 * np.pi * 297.0 * T)) * np.sin(2 * np.pi * 5000.0 * T)
    e = envelope(x, FS, default_band(FS))
    assert e.fs_env < FS / 1.5                       # decimated
    assert np.allclose(e.env, 1 + 0.5 * np.cos(2 * np.pi * 297.0 * np.arange(e.env.size) / e.fs_env), atol=1e-6)
    f, A = envelope_spectrum(e.env, e.fs_env)
    p = line_peak(f, A, 297.0, 0.02)
    assert p is not None and p.freq_hz == 297.0 and p.amplitude == pytest.approx(0.5, rel=1e-3)


@pytest.mark.parametrize("offset", [0.0, 0.1, 0.25, 0.4, 0.5, 0.63, 0.9])
def test_a_line_between_bins_reads_its_amplitude_within_one_percent(offset):
    """A modulation of 0.5 at 297 + offset Hz (1-Hz bins): the Hann scalloping (up to -15 %
    midway) corrected by the two-bin interpolation (Grandke 1983)."""
    x = (1 + 0.5 * np.cos(2 * np.pi * (297.0 + offset) * T)) * np.sin(2 * np.pi * 5000.0 * T)
    e = envelope(x, FS, default_band(FS))
    f, A = envelope_spectrum(e.env, e.fs_env)
    p = line_peak(f, A, 297.0 + offset, 0.02)
    assert p is not None and p.amplitude == pytest.approx(0.5, rel=0.01)
    assert abs(p.freq_hz - (297.0 + offset)) <= 0.5


def impacts(rate_hz: float, noise: float, seed: int) -> np.ndarray:
    """Decaying 5 kHz ringing started at ``rate_hz`` (a defect struck once per pass), in noise."""
    x = np.random.default_rng(seed).normal(0.0, noise, FS)
    n = np.arange(FS)
    for start in (np.arange(0.0, 1.0, 1 / rate_hz) * FS).astype(int):
        k = n[: FS - start]
        x[start:] += np.exp(-800.0 * k / FS) * np.sin(2 * np.pi * 5000.0 * k / FS)
    return x


@pytest.mark.parametrize("defect", ["bpfo", "bpfi"])
def test_envelope_spectrum_peaks_at_the_modulated_signals_defect_frequency(defect):
    f_r = 2000 / 60
    f_d = getattr(defect_frequencies(IMS, f_r), defect) * 1.01      # 1 % slip
    r = compute(impacts(f_d, 0.3, 6), setup(bearings=(Bearing("de", IMS),)), f_r)
    lines = r.bearings[0].lines
    first = {k: p.amplitude for k, p in lines.items() if not k.endswith("_2x")}
    assert max(first, key=first.__getitem__) == defect
    assert abs(lines[defect].freq_hz - f_d) <= 1.0 and lines[defect].ratio > 10
    assert r.values()[f"de.{defect}"] == lines[defect].amplitude
    quiet = compute(np.random.default_rng(7).normal(0.0, 0.3, FS), setup(bearings=(Bearing("de", IMS),)), f_r)
    assert quiet.envelope_rms < 0.7 * r.envelope_rms
    assert max(p.ratio for p in quiet.bearings[0].lines.values()) < 4


def test_without_a_speed_no_bearing_lines_and_no_order_bands():
    r = compute(np.random.default_rng(8).normal(size=FS),
                setup(bearings=(Bearing("de", IMS),), bands=(Band("1x", 0.8, 1.2, orders=True),)), None)
    assert r.bearings[0].freqs is None and r.bearings[0].lines == {} and r.bands == []
    assert "band.1x" not in r.values() and "accel_rms" in r.values()


# --- band RMS -------------------------------------------------------------------


def test_band_rms_in_hertz_and_in_orders():
    x = 2.0 * np.sin(2 * np.pi * 120.0 * T) + 0.5 * np.sin(2 * np.pi * 3000.0 * T)
    bands = (Band("low", 50.0, 200.0), Band("high", 2000.0, 5000.0), Band("3x", 2.5, 3.5, orders=True))
    r = compute(x, setup(bands=bands), 40.0)
    got = {band.name: (edges, rms) for band, edges, rms in r.bands}
    assert got["low"][1] == pytest.approx(2.0 / math.sqrt(2), rel=1e-3)
    assert got["high"][1] == pytest.approx(0.5 / math.sqrt(2), rel=1e-3)
    assert got["3x"] == (pytest.approx((100.0, 140.0)), pytest.approx(2.0 / math.sqrt(2), rel=1e-3))
