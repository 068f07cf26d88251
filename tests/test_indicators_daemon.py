"""The indicators through the commands a user types: a simulated board's capture replayed,
`cmsensord --simulate` in RMS mode, and the IMS rig's real bearing recordings imported and
replayed (inner race, outer race, healthy)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cmsensord.sinks.mcap_sink import read_messages
from processes import run_module

IMS = Path(__file__).parent / "data" / "ims"
#: a 6206-like bearing whose BPFO is the simulated motor's 3.58 x f_r (9 balls, 9.525 on 46 mm)
SIM_BEARING = "  - {name: de, channel: ch0, elements: 9, ball_diameter: 9.525, pitch_diameter: 46.0}\n"
#: the IMS rig's Rexnord ZA-2115 at 2000 rpm (no tacho in the recordings)
IMS_SITE = ("indicators:\n  rpm: 2000\nchannels:\n  - name: bearing\nbearings:\n"
            "  - {name: za2115, channel: bearing, elements: 16, ball_diameter: 0.331, "
            "pitch_diameter: 2.815, contact_angle_deg: 15.17}\n")
FIRST = ("ftf", "bpfo", "bpfi", "bsf")


def ok(module: str, *args: str):
    p = run_module(module, *args)
    assert p.returncode == 0, p.stderr
    return p


def indicators(out: Path, channel: str) -> list[dict]:
    return [m for t, _, m in read_messages(next(out.glob("*.mcap"))) if t == f"/cm/{channel}/indicators"]


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """8 s of the healthy and the faulty motor (RAW, tacho) replayed with one bearing on ch0."""
    work = tmp_path_factory.mktemp("ind_sim")
    (work / "site.yaml").write_text("output:\n  status_line: false\nbearings:\n" + SIM_BEARING)
    got = {}
    for sc in ("healthy", "faulty"):
        ok("firmware_sim", "--scenario", sc, "--mode", "raw", "--tacho", "--duration", "8",
           "--out", str(work / f"{sc}.bin"))
        ok("cmsensord", "replay", str(work / f"{sc}.bin"), "--config", str(work / "site.yaml"),
           "--out", str(work / sc))
        got[sc] = indicators(work / sc, "ch0")
    return got


def test_replayed_raw_capture_has_a_record_per_second_with_plausible_values(simulated):
    healthy, faulty = simulated["healthy"], simulated["faulty"]
    assert len(healthy) == len(faulty) == 8
    for m in healthy + faulty:
        assert m["mode"] == "raw" and m["speed_source"] == "tacho" and m["speed_rpm"] == pytest.approx(1720, rel=0.01)
    # the simulator's motor: ~1.8 mm/s healthy (zone B of a 15-300 kW rigid machine), ~8.3 faulty (D)
    v_h = np.mean([m["velocity_rms_mm_s"] for m in healthy])
    v_f = np.mean([m["velocity_rms_mm_s"] for m in faulty])
    assert v_h == pytest.approx(1.8, rel=0.1) and {m["zone"] for m in healthy} == {"B"}
    assert v_f == pytest.approx(8.3, rel=0.1) and {m["zone"] for m in faulty} == {"D"}
    assert all(2.5 < m["kurtosis"] < 3.5 for m in healthy) and all(m["kurtosis"] > 10 for m in faulty)
    assert min(m["envelope_rms"] for m in faulty) > 5 * max(m["envelope_rms"] for m in healthy)


def test_the_simulated_outer_race_defect_shows_at_bpfo(simulated):
    for m in simulated["faulty"]:
        lines = m["bearings"][0]["lines"]
        assert max(FIRST, key=lambda k: lines[k]["amplitude"]) == "bpfo" and lines["bpfo"]["ratio"] > 3
    for m in simulated["healthy"]:
        assert max(m["bearings"][0]["lines"][k]["ratio"] for k in FIRST) < 3


def test_a_bearing_line_between_bins_reads_its_0_peak_amplitude(tmp_path):
    """An imported 1 g carrier at 5 kHz modulated 50 % at the BPFO of 1800 rpm (107.54 Hz, 0.46 of
    a 1-Hz bin off): the line reads the modulation's 0-peak 0.5 g within 1 % (not 4.279 m/s^2,
    -13 %, the Hann window's scalloping)."""
    fs, g = 25600, 9.80665
    t = np.arange(4 * fs) / fs
    bpfo = 9 / 2 * 30.0 * (1 - 7.94 / 39.04)
    np.save(tmp_path / "am.npy", (1 + 0.5 * np.cos(2 * np.pi * bpfo * t)) * np.cos(2 * np.pi * 5000 * t))
    ok("cmsensord", "import", str(tmp_path / "am.npy"), "--fs", str(fs), "--unit", "g", "--names", "ch",
       "--out", str(tmp_path / "am.bin"))
    (tmp_path / "site.yaml").write_text("output:\n  status_line: false\nindicators:\n  rpm: 1800\nbearings:\n"
                                        "  - {name: de, channel: ch, elements: 9, ball_diameter: 7.94, "
                                        "pitch_diameter: 39.04}\n")
    ok("cmsensord", "replay", str(tmp_path / "am.bin"), "--config", str(tmp_path / "site.yaml"),
       "--out", str(tmp_path / "out"))
    recs = indicators(tmp_path / "out", "ch")[1:-1]
    assert recs
    for m in recs:
        line = m["bearings"][0]["lines"]["bpfo"]
        assert line["freq_hz"] == 108.0 and line["amplitude"] == pytest.approx(0.5 * g, rel=0.01)


def test_simulate_in_rms_mode_reports_the_overall_rms_and_the_rest_unavailable(tmp_path):
    ok("cmsensord", "--simulate", "--scenario", "healthy", "--duration", "4", "--out", str(tmp_path))
    recs = indicators(tmp_path, "ch0")
    assert len(recs) >= 3
    for m in recs:
        assert m["mode"] == "rms" and 0.6 < m["accel_rms"] < 0.8       # the healthy motor: 0.68 m/s^2
        assert "velocity_rms_mm_s" not in m and "velocity_rms_mm_s" in m["unavailable"]


# --- the IMS rig -------------------------------------------------------------------


@pytest.fixture(scope="module")
def ims(tmp_path_factory):
    """NA (healthy), IF (inner race), OF (outer race): six 1-s snapshots each, imported as one
    recording (no --snapshot-len) of 122,880 samples, which 640 blocks of 192 fill with none
    dropped (192 does not divide a snapshot's 20,480), so each 1-s interval of 20,480 samples
    from the start is one whole snapshot; replayed at 2000 rpm."""
    work = tmp_path_factory.mktemp("ind_ims")
    (work / "site.yaml").write_text(IMS_SITE)
    got = {}
    for name in ("NA", "IF", "OF"):
        ok("cmsensord", "import", str(IMS / f"{name}.mat"), "--variable", "data", "--fs", "20480",
           "--unit", "g", "--names", "bearing", "--block-len", "192", "--out", str(work / f"{name}.bin"))
        ok("cmsensord", "replay", str(work / f"{name}.bin"), "--config", str(work / "site.yaml"),
           "--out", str(work / name))
        got[name] = indicators(work / name, "bearing")
    return got


def mean_lines(recs: list[dict], key: str) -> dict[str, float]:
    """Per defect frequency, the mean over the snapshots of its line's ``key``."""
    return {k: float(np.mean([m["bearings"][0]["lines"][k][key] for m in recs])) for k in FIRST}


def test_ims_bearing_frequencies_at_2000_rpm(ims):
    b = ims["NA"][0]["bearings"][0]
    assert [round(b[f"{k}_hz"], 1) for k in ("bpfo", "bpfi", "bsf", "ftf")] == [236.4, 296.9, 139.9, 14.8]
    assert all(m["speed_source"] == "config" and m["missing_fraction"] == 0 for m in ims["NA"])


def test_ims_inner_race_segment_peaks_at_bpfi(ims):
    amp = mean_lines(ims["IF"], "amplitude")
    assert max(amp, key=amp.__getitem__) == "bpfi"
    assert mean_lines(ims["IF"], "ratio")["bpfi"] > 5


def test_ims_outer_race_segment_peaks_at_bpfo(ims):
    amp = mean_lines(ims["OF"], "amplitude")
    assert max(amp, key=amp.__getitem__) == "bpfo"
    assert mean_lines(ims["OF"], "ratio")["bpfo"] > 20
    for m in ims["OF"]:                          # in every snapshot
        lines = m["bearings"][0]["lines"]
        assert max(FIRST, key=lambda k: lines[k]["amplitude"]) == "bpfo"


def test_ims_healthy_segment_has_no_line_standing_out(ims):
    ratio = mean_lines(ims["NA"], "ratio")
    assert max(ratio.values()) < 4, ratio
    assert max(ratio.values()) < mean_lines(ims["IF"], "ratio")["bpfi"] < mean_lines(ims["OF"], "ratio")["bpfo"]
    env = {k: np.mean([m["envelope_rms"] for m in ims[k]]) for k in ims}
    assert env["NA"] < env["IF"] and env["NA"] < env["OF"]
