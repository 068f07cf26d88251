"""Envelope analysis through `cmsensord import` + `cmsensord replay`, against references written
here from the textbook (Randall & Antoni 2011), not from cmsensord's helpers.

An outer-race fault: impacts at BPFO (of the bearing's geometry at the configured 1800 rpm), each
ringing a 4 kHz resonance that decays with time constant tau, plus noise.  The envelope (band-pass,
analytic signal by scipy.signal.hilbert, magnitude) is a train of exponentials e(t) = A exp(-t/tau)
repeating at BPFO, whose Fourier series has the 0-peak amplitude 2 A tau BPFO / sqrt(1 + (2 pi k BPFO
tau)^2) at k x BPFO: the documented reading of a line (a modulation m cos(2 pi f t) of the envelope
reads m).  A second channel carries the same signal twice as large: every envelope figure doubles.

An envelope band of one bin is a single tone, whose envelope is a constant: it read envelope_rms 0.0
under these 1 g impacts, and the bearing lines were silently absent.  The envelope of a band carries
modulation up to about the band's width: the lines of a bearing above it were left out of the records
without a word (and an alarm rule on them never fired)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mcap.reader import make_reader
from scipy.signal import hilbert

from processes import run_module

FS = 25600
G = 9.80665
SECONDS = 3
RPM = 1800.0
N_BALLS, BALL, PITCH = 9, 7.94, 39.04        # mm, contact angle 0
TAU, CARRIER, IMPACT_G, NOISE_G = 0.0005, 4000.0, 1.0, 0.01
BAND = (0.08 * FS, 0.4 * FS)                 # the documented default envelope band
BEARINGS = "".join(f"  - {{name: {b}, channel: {c}, elements: {N_BALLS}, ball_diameter: {BALL}, "
                   f"pitch_diameter: {PITCH}}}\n" for b, c in (("de", "a"), ("de2", "b")))


def textbook_frequencies(f_r: float, n: int = N_BALLS, d: float = BALL, D: float = PITCH,
                         phi_deg: float = 0.0) -> dict[str, float]:
    """FTF, BPFO, BPFI, BSF [Hz] (Randall & Antoni 2011, eqs. 1-4)."""
    r = d / D * np.cos(np.radians(phi_deg))
    return {"ftf": f_r / 2 * (1 - r), "bpfo": n * f_r / 2 * (1 - r), "bpfi": n * f_r / 2 * (1 + r),
            "bsf": D * f_r / (2 * d) * (1 - r * r)}


BPFO = textbook_frequencies(RPM / 60)["bpfo"]


def _signal() -> np.ndarray:
    t = np.arange(SECONDS * FS) / FS
    since = np.mod(t, 1 / BPFO)                # time since the last impact
    x = IMPACT_G * np.exp(-since / TAU) * np.sin(2 * np.pi * CARRIER * since)
    return x + NOISE_G * np.random.default_rng(7).standard_normal(t.size)


def reference_envelope(x: np.ndarray) -> np.ndarray:
    """The envelope of x's band BAND: FFT band-pass (rectangular), scipy's analytic signal, magnitude."""
    X = np.fft.rfft(x - x.mean())
    f = np.fft.rfftfreq(x.size, 1 / FS)
    X[(f < BAND[0]) | (f > BAND[1])] = 0
    return np.abs(hilbert(np.fft.irfft(X, x.size)))


def line_amplitude(e: np.ndarray, f0: float) -> float:
    """0-peak amplitude of e's component at exactly f0 (a Hann-windowed DFT evaluated at f0)."""
    n = np.arange(e.size)
    w = 0.5 - 0.5 * np.cos(2 * np.pi * n / e.size)
    e = e - e.mean()
    return 2 * abs(np.sum(e * w * np.exp(-2j * np.pi * f0 * n / FS))) / w.sum()


def _replay(tmp_path, indicators: str, rules: str = "") -> tuple[list[str], dict[str, list[dict]]]:
    x = _signal()
    np.save(tmp_path / "x.npy", np.stack([x, 2 * x], axis=1))
    p = run_module("cmsensord", "import", str(tmp_path / "x.npy"), "--fs", str(FS), "--unit", "g", "--names", "a,b",
                   "--out", str(tmp_path / "x.bin"))
    assert p.returncode == 0, p.stderr
    (tmp_path / "site.yaml").write_text(f"output:\n  status_line: false\nindicators:\n  rpm: {RPM:g}\n{indicators}"
                                        f"bearings:\n{BEARINGS}{rules}")
    p = run_module("cmsensord", "replay", str(tmp_path / "x.bin"), "--config", str(tmp_path / "site.yaml"),
                   "--out", str(tmp_path / "out"))
    assert p.returncode == 0, p.stderr
    recs: dict[str, list[dict]] = {"a": [], "b": []}
    with open(next((tmp_path / "out").glob("*.mcap")), "rb") as f:
        for _, c, m in make_reader(f).iter_messages():
            if c.topic.endswith("/indicators"):
                recs[c.topic.split("/")[2]].append(json.loads(m.data))
    return p.stderr.splitlines(), recs


@pytest.fixture(scope="module")
def impacts(tmp_path_factory):
    return _replay(tmp_path_factory.mktemp("env_ref"), "")[1]


def test_the_bearing_frequencies_are_the_textbook_ones(impacts):
    ref = textbook_frequencies(RPM / 60)
    for m in impacts["a"]:
        b = m["bearings"][0]
        assert {k: b[f"{k}_hz"] for k in ref} == pytest.approx(ref, rel=1e-9)


def test_the_envelope_spectrum_peaks_at_bpfo_and_its_harmonic(impacts):
    for m in impacts["a"]:
        lines = m["bearings"][0]["lines"]
        firsts = {k: lines[k]["amplitude"] for k in ("ftf", "bpfo", "bpfi", "bsf") if k in lines}
        assert max(firsts, key=firsts.__getitem__) == "bpfo", firsts
        assert abs(lines["bpfo"]["freq_hz"] - BPFO) <= 1 and abs(lines["bpfo_2x"]["freq_hz"] - 2 * BPFO) <= 1
        assert lines["bpfo"]["ratio"] > 50 and lines["bpfo_2x"]["ratio"] > 50


def test_line_amplitudes_and_envelope_rms_are_the_references(impacts):
    x = _signal() * G
    assert len(impacts["a"]) == SECONDS
    for k, m in enumerate(impacts["a"]):
        e = reference_envelope(x[k * FS:(k + 1) * FS])
        lines = m["bearings"][0]["lines"]
        for name, h in (("bpfo", 1), ("bpfo_2x", 2)):
            assert lines[name]["amplitude"] == pytest.approx(line_amplitude(e, h * BPFO), rel=0.02), name
            series = 2 * IMPACT_G * G * TAU * BPFO / np.sqrt(1 + (2 * np.pi * h * BPFO * TAU) ** 2)
            assert lines[name]["amplitude"] == pytest.approx(series, rel=0.06), name   # the band cuts the ringing
        assert m["envelope_rms"] == pytest.approx(np.std(e), rel=0.02)


def test_twice_the_signal_reads_twice_the_envelope(impacts):
    for a, b in zip(impacts["a"], impacts["b"]):
        assert b["envelope_rms"] == pytest.approx(2 * a["envelope_rms"], rel=0.005)
        for name in ("bpfo", "bpfo_2x"):
            assert b["bearings"][0]["lines"][name]["amplitude"] == pytest.approx(
                2 * a["bearings"][0]["lines"][name]["amplitude"], rel=0.005)


def test_an_envelope_band_of_one_bin_is_unavailable_and_said(tmp_path):
    lines, recs = _replay(tmp_path, "  envelope_band_hz: [4000, 4000.5]\n")
    told = [ln for ln in lines if ln.startswith("WARNING band_too_narrow: ")]
    assert told == [
        f"WARNING band_too_narrow: {c}: indicators.envelope_band_hz 4000-4000.5 Hz holds one bin of the record's "
        "spectrum (1-Hz bins, records of 1 s), a single tone whose envelope is a constant: envelope_rms, bearings "
        "listed unavailable; widen the band to at least 2 Hz (wider than the bearing lines to read), or lengthen "
        "indicators.interval_s" for c in ("a", "b")], lines
    for m in recs["a"] + recs["b"]:
        assert "envelope_rms" not in m and m["unavailable"] == ["envelope_rms", "bearings"], m


def test_lines_past_the_envelope_of_a_narrow_band_are_unavailable_and_said(tmp_path):
    rule = "alarms:\n  rules:\n    - {name: bp, indicator: de.bpfo, alert: 1.0}\n"
    lines, recs = _replay(tmp_path, "  envelope_band_hz: [4000, 4050]\n", rule)
    past = "bpfo 107.5 Hz, bpfo_2x 215.1 Hz, bpfi 162.5 Hz, bpfi_2x 324.9 Hz, bsf 70.7 Hz, bsf_2x 141.4 Hz"
    told = [ln for ln in lines if ln.startswith("WARNING band_too_narrow: ")]
    assert told == [
        f"WARNING band_too_narrow: {c}: indicators.envelope_band_hz 4000-4050 Hz is too narrow for bearing {b}'s "
        f"line(s) {past}: the envelope of a band carries modulation up to about its width; listed unavailable in "
        f"/cm/{c}/indicators, no number; {fire}; widen the band to a width of at least 357 Hz"
        for c, b, fire in (("a", "de", "rule(s) bp on them do not fire"),
                           ("b", "de2", "an alarm rule on them would never fire"))], lines
    for c, b in (("a", "de"), ("b", "de2")):
        for m in recs[c]:
            assert m["unavailable"] == [f"{b}.{k}" for k in ("bpfo", "bpfo_2x", "bpfi", "bpfi_2x", "bsf", "bsf_2x")]
            assert set(m["bearings"][0]["lines"]) == {"ftf", "ftf_2x"} and m["envelope_rms"] > 0, m
