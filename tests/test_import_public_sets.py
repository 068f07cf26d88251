"""`cmsensord import` of small look-alikes of public bearing data sets' files, run as a newcomer
runs it: first with no options, then with the ones the line asks for. The files do not say their
rate: the line names the one the data set publishes (CWRU, Paderborn, XJTU-SY, the IMS rig);
the elements of an array of structs that share a name (Paderborn's) each keep their fields."""

from __future__ import annotations

import numpy as np
import scipy.io

from tests.test_import import G, assert_within_one_count, cmd, decode, sidecar


def paderborn_with_rasters(path, seed: int) -> dict:
    """A Paderborn-like file: one struct named after the file, whose Y holds named signals and
    whose X holds three time axes all named ``Time`` (one per raster, of other lengths), with text
    fields beside the data; its arrays by the names the import gives them."""
    rng = np.random.default_rng(seed)
    dt = [("Name", "O"), ("Type", "O"), ("Raster", "O"), ("Data", "O")]
    y = np.zeros((1, 2), dtype=dt)
    vib, speed = np.round(rng.normal(0.0, 1.0, (1, 1600)), 4), 1500.0 + np.zeros((1, 100))
    y[0, 0] = ("speed", "", "Mech_4kHz", speed)
    y[0, 1] = ("vibration_1", "", "HostService", vib)
    x = np.zeros((1, 3), dtype=dt)
    axes = [np.arange(n)[None, :] / n for n in (100, 1600, 2)]
    for i, (raster, t) in enumerate(zip(("Mech_4kHz", "HostService", "Temp_1Hz"), axes)):
        x[0, i] = ("Time", "", raster, t)
    top = np.zeros((1, 1), dtype=[("Info", "O"), ("X", "O"), ("Y", "O"), ("Description", "O")])
    top[0, 0] = ("info", x, y, "a healthy bearing")
    scipy.io.savemat(path, {path.stem: top})
    return {"vibration_1": vib.ravel(), **{f"Time_{i}": t.ravel() for i, t in enumerate(axes)}}


def test_elements_of_an_array_of_structs_that_share_a_name_each_keep_their_fields(tmp_path):
    got = paderborn_with_rasters(tmp_path / "N15_M07_F10_K001_1.mat", 1)
    r = cmd("import", "N15_M07_F10_K001_1.mat", "--out", "p.bin", cwd=tmp_path)
    s = "N15_M07_F10_K001_1"
    assert (r.returncode, r.stderr) == (2, (
        f"cmsensord import: N15_M07_F10_K001_1.mat: several variables to import (variables: {s}.X.Time_0.Data "
        f"(1, 100), {s}.X.Time_1.Data (1, 1600), {s}.X.Time_2.Data (1, 2), {s}.Y.speed.Data (1, 100), "
        f"{s}.Y.vibration_1.Data (1, 1600); 17 of text or other types not listed); choose one with --variable "
        "(several: --variable A,B)\n")), r.stderr
    # the time axis of the vibration's raster, not the last element's two samples under one name
    r = cmd("import", "N15_M07_F10_K001_1.mat", "--variable", "*vibration_1.Data,*Time_1.Data", "--fs", "1600",
            "--keep-dc", "--out", "p.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert sidecar(tmp_path / "p.bin")["channel_names"] == ["vibration_1_Data", "Time_1_Data"]
    assert_within_one_count(decode(tmp_path / "p.bin"), np.stack([got["vibration_1"], got["Time_1"]]))
    r = cmd("import", "N15_M07_F10_K001_1.mat", "--variable", "*Time.Data", "--fs", "1600", "--out", "p.bin",
            cwd=tmp_path)
    assert r.returncode == 2 and "--variable *Time.Data: no variable matches it" in r.stderr, r.stderr


def test_the_rate_a_public_data_set_publishes_is_named_where_its_files_do_not_carry_it(tmp_path):
    x = np.round(np.random.default_rng(2).normal(0.0, 0.2, (2, 2400)), 3)
    scipy.io.savemat(tmp_path / "105.mat", {"X105_DE_time": x[0][:, None], "X105_FE_time": x[1][:, None],
                                            "X105RPM": np.array([[1797]])})
    paderborn_with_rasters(tmp_path / "N15_M07_F10_K001_1.mat", 1)
    (tmp_path / "ims").mkdir()
    (tmp_path / "ims" / "2004.02.12.10.32.39").write_text("".join(f"{a:.3f}\t{b:.3f}\n" for a, b in x.T))
    xjtu = tmp_path / "Bearing1_1"
    xjtu.mkdir()
    for k in (1, 2, 3):
        (xjtu / f"{k}.csv").write_text("Horizontal_vibration_signals,Vertical_vibration_signals\n"
                                       + "".join(f"{a:.3f},{b:.3f}\n" for a, b in x.T[(k - 1) * 512:k * 512]))
    cases = {
        ("105.mat", "--variable", "*_DE_time,*_FE_time"):
            "105.mat: the file does not say its sampling rate; give --fs HZ (named as the CWRU bearing data "
            "centre's variables: --fs 12000 for its 12k data, --fs 48000 for its 48k data; the page the file "
            "came from says which)",
        ("N15_M07_F10_K001_1.mat", "--variable", "*vibration_1.Data,*speed.Data", "--speed-column", "speed.Data"):
            "N15_M07_F10_K001_1.mat: the file does not say its sampling rate; give --fs HZ (named as the "
            "Paderborn bearing data centre's signals: --fs 64000, its vibration's and motor currents' rate; its "
            "speed, torque and force are sampled at 4000 Hz)",
        ("Bearing1_1",):
            "Bearing1_1/1.csv: the file does not say its sampling rate; give --fs HZ (named as the XJTU-SY "
            "bearing data set's columns: --fs 25600, and --snapshot-interval 60 for its one file a minute)",
        ("ims",):
            "ims/2004.02.12.10.32.39: the file does not say its sampling rate; give --fs HZ (named as the IMS "
            "bearing rig's files: --fs 20480)",
    }
    for args, message in cases.items():
        r = cmd("import", *args, "--out", "o.bin", cwd=tmp_path)
        assert (r.returncode, r.stdout, r.stderr) == (2, "", f"cmsensord import: {message}\n"), args
    # as the line says: the rate, and the snapshots a minute apart in the recording
    r = cmd("import", "Bearing1_1", "--fs", "25600", "--snapshot-interval", "60", "--unit", "g", "--keep-dc",
            "--out", "x.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    meta = sidecar(tmp_path / "x.bin")
    assert meta["fs"] == 25600 and meta["channel_names"] == ["Horizontal_vibration_signals",
                                                             "Vertical_vibration_signals"]
    assert [(s["source"], s["source_time_s"]) for s in meta["snapshots"]] == [("1.csv", 0), ("2.csv", 60),
                                                                               ("3.csv", 120)]
    assert_within_one_count(decode(tmp_path / "x.bin"), x[:, :1536] * G)
    # without --snapshot-interval the files give no times, and the import says so
    r = cmd("import", "Bearing1_1", "--fs", "25600", "--unit", "g", "--out", "y.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert ("  note: the 3 files carry no times (no time column, no date and time in their names): their "
            "snapshots lie end to end, the time between them in the recording unknown; --snapshot-interval S "
            "gives it\n") in r.stderr
    assert [s["source_time_s"] for s in sidecar(tmp_path / "y.bin")["snapshots"]] == [None, None, None]


def test_a_structs_rate_beside_its_sampling_rate_is_the_shaft_speed_in_hz(tmp_path):
    """MFPT's bearing files hold the shaft's speed in Hz as ``bearing.rate`` beside the sampling
    rate ``bearing.sr``: the capture's speed is 60 x it, said; --rpm gives another, no note."""
    gs = np.round(np.random.default_rng(3).normal(0.0, 1.0, 4883), 4)
    scipy.io.savemat(tmp_path / "OuterRaceFault_1.mat", {"bearing": {"sr": 48828, "gs": gs[:, None], "load": 270,
                                                                     "rate": 25}})
    r = cmd("import", "OuterRaceFault_1.mat", "--unit", "g", "--out", "m.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert ("  speed: 1500 rpm from OuterRaceFault_1.mat (no TACHO frames: replay takes it as indicators.rpm; "
            "--rpm 1500 also sends TACHO frames)\n  note: bearing.rate 25 beside the sampling rate bearing.sr: taken "
            "as the shaft's speed in Hz, 1500 rpm (the MFPT bearing files' layout); --rpm gives another\n") in r.stderr
    meta = sidecar(tmp_path / "m.bin")
    assert (meta["fs"], meta["rpm"], meta["rpm_source"]) == (48828, 1500.0, "OuterRaceFault_1.mat")
    r = cmd("import", "OuterRaceFault_1.mat", "--unit", "g", "--rpm", "1480", "--out", "n.bin", cwd=tmp_path)
    assert r.returncode == 0 and "bearing.rate" not in r.stderr, r.stderr
    assert sidecar(tmp_path / "n.bin")["rpm"] == 1480.0
