"""The analyst's indicators through `cmsensord import` + `cmsensord replay`, against references
written here from the textbook and the standard, not from cmsensord's helpers.

* velocity RMS of a sine of acceleration amplitude a at f: a / (2 pi f) / sqrt(2), in mm/s from a
  recording in g (g = 9.80665 m/s^2), inside the ISO 10816-3 band of 10-1000 Hz, on its edges (the
  Hann window's side bins beyond an edge are not counted: 10 Hz -10.3 %, 1000 Hz -8.7 %), and
  outside it (5 Hz, 1500 Hz: the band is rectangular, nothing counted);
* the ISO 10816-3 zone of each velocity for every machine group and foundation (Annex A,
  Tables A.1 and A.2);
* kurtosis mean(x^4) / mean(x^2)^2 and crest factor of a sine (1.5, sqrt 2) and of Gaussian noise
  (3, and the crest factor numpy gives of the same samples);
* with a tacho (`import --speed-column`) on a run-up, each record's bearing frequencies are the
  textbook ones at the record's speed (Randall & Antoni 2011), and its BPFO line is read at the
  bin of the BPFO the shaft actually turned at."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mcap.reader import make_reader

from processes import run_module

FS = 25600
G = 9.80665
EDGE_TONES = (5.0, 10.0, 12.0, 50.0, 159.2, 500.0, 999.5, 1000.0, 1500.0)    # Hz, 0.5 g peak each
EDGE_G = 0.5
LADDER = (1.0, 2.0, 2.6, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 12.0)             # mm/s RMS at 50 Hz
#: ISO 10816-3 Annex A: zone boundaries A/B, B/C, C/D [mm/s RMS]
ISO = {(1, "rigid"): (2.3, 4.5, 7.1), (1, "flexible"): (3.5, 7.1, 11.0),
       (2, "rigid"): (1.4, 2.8, 4.5), (2, "flexible"): (2.3, 4.5, 7.1)}


def true_velocity_mm_s(a_peak_ms2: float, f: float) -> float:
    return 1000 * a_peak_ms2 / (2 * np.pi * f) / np.sqrt(2)


def iso_zone(v: float, group: int, foundation: str) -> str:
    """A below A/B, B below B/C, C below C/D, else D (a value on a boundary is in the higher zone)."""
    return "ABCD"[sum(v >= b for b in ISO[(group, foundation)])]


def _snapshots() -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(FS) / FS
    tones = [EDGE_G * np.sin(2 * np.pi * f * t + 0.3) for f in EDGE_TONES]
    ladder = [v / 1000 * np.sqrt(2) * 2 * np.pi * 50 / G * np.sin(2 * np.pi * 50 * t) for v in LADDER]
    noise = 0.3 * np.random.default_rng(3).standard_normal(FS)
    return np.array(tones + ladder + [noise])[:, :, None], noise


def _records(tmp_path, src, import_args, yaml: str, channel: str = "ch") -> list[dict]:
    p = run_module("cmsensord", "import", str(src), "--fs", str(FS), "--unit", "g", *import_args,
                   "--out", str(tmp_path / "x.bin"))
    assert p.returncode == 0, p.stderr
    out = tmp_path / f"out{len(list(tmp_path.glob('out*')))}"
    (tmp_path / "site.yaml").write_text("output:\n  status_line: false\n" + yaml)
    p = run_module("cmsensord", "replay", str(tmp_path / "x.bin"), "--config", str(tmp_path / "site.yaml"),
                   "--out", str(out))
    assert p.returncode == 0, p.stderr
    with open(next(out.glob("*.mcap")), "rb") as f:
        return [json.loads(m.data) for _, c, m in make_reader(f).iter_messages()
                if c.topic == f"/cm/{channel}/indicators"]


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    """The snapshots' records under each machine group and foundation."""
    work = tmp_path_factory.mktemp("textbook")
    x, _ = _snapshots()
    np.save(work / "x.npy", x)
    return {(g, fd): _records(work, work / "x.npy", ("--names", "ch", "--range", "2g"),
                              f"indicators:\n  machine_group: {g}\n  foundation: {fd}\n") for g, fd in ISO}


def test_velocity_of_a_sine_in_on_the_edges_of_and_outside_the_band(graded):
    recs = graded[(2, "rigid")][:len(EDGE_TONES)]
    read = {f: m["velocity_rms_mm_s"] for f, m in zip(EDGE_TONES, recs)}
    true = {f: true_velocity_mm_s(EDGE_G * G, f) for f in EDGE_TONES}
    assert all(m["velocity_band_hz"] == [10.0, 1000.0] for m in recs)
    for f in (12.0, 50.0, 159.2, 500.0):                    # inside: within 0.5 %
        assert read[f] == pytest.approx(true[f], rel=0.005), f
    deviation = {f: round(100 * (read[f] / true[f] - 1), 1) for f in (10.0, 999.5, 1000.0)}
    assert deviation == {10.0: -10.3, 999.5: -1.0, 1000.0: -8.7}   # the README's edge figures
    for f in (5.0, 1500.0):                                 # outside: rectangular, nothing counted
        assert read[f] < 0.005 * true[f], (f, read[f])   # the 12-bit counts' noise in the band


def test_iso_zones_of_every_machine_group_and_foundation(graded):
    for (g, fd), recs in graded.items():
        ladder = recs[len(EDGE_TONES):len(EDGE_TONES) + len(LADDER)]
        for v, m in zip(LADDER, ladder):
            assert m["velocity_rms_mm_s"] == pytest.approx(v, rel=0.002)
            assert m["zone"] == iso_zone(v, g, fd), (g, fd, v, m["zone"])
            assert m["zone_boundaries_mm_s"] == list(ISO[(g, fd)])


def test_kurtosis_and_crest_factor_of_a_sine_and_of_gaussian_noise(graded):
    recs = graded[(2, "rigid")]
    for m in recs[:len(EDGE_TONES)]:
        assert m["kurtosis"] == pytest.approx(1.5, abs=0.003) and m["crest_factor"] == pytest.approx(
            np.sqrt(2), rel=0.005)
    _, noise = _snapshots()
    d = noise - noise.mean()
    kurtosis, crest = np.mean(d ** 4) / np.mean(d ** 2) ** 2, np.max(np.abs(d)) / np.sqrt(np.mean(d ** 2))
    m = recs[-1]
    assert m["kurtosis"] == pytest.approx(kurtosis, rel=0.005) and m["kurtosis"] == pytest.approx(3, abs=0.1)
    assert m["crest_factor"] == pytest.approx(crest, rel=0.01) and 3 < m["crest_factor"] < 5


def test_bearing_frequencies_follow_the_tacho_speed(tmp_path):
    """A run-up from 1200 to 1800 rpm over 5 s (a speed column, so TACHO frames), the carrier
    modulated at the BPFO of the instantaneous speed."""
    t = np.arange(5 * FS) / FS
    rpm = 1200 + 120 * t
    r = 7.94 / 39.04
    bpfo = 9 / 2 * (1 - r) * rpm / 60
    x = (1 + 0.5 * np.cos(2 * np.pi * np.cumsum(bpfo) / FS)) * np.cos(2 * np.pi * 5000 * t)
    np.save(tmp_path / "run.npy", np.stack([x, rpm], axis=1))
    recs = _records(tmp_path, tmp_path / "run.npy", ("--channels", "0", "--names", "ch", "--speed-column", "1"),
                    "bearings:\n  - {name: de, channel: ch, elements: 9, ball_diameter: 7.94, pitch_diameter: 39.04}\n")
    assert len(recs) == 5
    for k, m in enumerate(recs):
        assert m["speed_source"] == "tacho"
        assert m["speed_rpm"] == pytest.approx(rpm[k * FS:(k + 1) * FS].mean(), rel=0.005)
        f_r = m["speed_rpm"] / 60
        b = m["bearings"][0]
        textbook = {"ftf": f_r / 2 * (1 - r), "bpfo": 9 * f_r / 2 * (1 - r), "bpfi": 9 * f_r / 2 * (1 + r),
                    "bsf": 39.04 * f_r / (2 * 7.94) * (1 - r * r)}
        assert {k: b[f"{k}_hz"] for k in textbook} == pytest.approx(textbook, rel=1e-9)
        assert abs(b["lines"]["bpfo"]["freq_hz"] - bpfo[k * FS:(k + 1) * FS].mean()) <= 1.0
