"""`cmsensord import` of small look-alikes of public bearing data sets' files, run as a newcomer
runs it: first with no options, then with the ones the line asks for. The files do not say their
rate: the line names the one the data set publishes (CWRU, Paderborn, XJTU-SY, the IMS rig);
the elements of an array of structs that share a name (Paderborn's) each keep their fields."""

from __future__ import annotations

import numpy as np
import pytest
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


def paderborn_v73(path, signals: dict) -> None:
    """A Paderborn-like file as MATLAB saves it with -v7.3: the struct named after the file, its
    Y an array of structs whose fields (Name, Data) hold references to each element's value
    (text as uint16 characters), each array stored transposed."""
    h5py = pytest.importorskip("h5py", reason="the mat73 extra")
    with h5py.File(path, "w", userblock_size=512) as f:
        refs = f.create_group("#refs#")
        top = f.create_group(path.stem)
        top.attrs["MATLAB_class"] = np.bytes_("struct")
        y = top.create_group("Y")
        y.attrs["MATLAB_class"] = np.bytes_("struct")
        fields = {k: y.create_dataset(k, (len(signals), 1), dtype=h5py.ref_dtype) for k in ("Name", "Data")}
        for i, (name, data) in enumerate(signals.items()):
            text = refs.create_dataset(f"n{i}", data=np.array([[ord(c) for c in name]], dtype=np.uint16).T)
            text.attrs["MATLAB_class"] = np.bytes_("char")
            values = refs.create_dataset(f"d{i}", data=data[None, :].T)
            values.attrs["MATLAB_class"] = np.bytes_("double")
            fields["Name"][i, 0], fields["Data"][i, 0] = text.ref, values.ref
    head = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Nov 30 08:00:00 2026 HDF5 schema 1.00 ."
    with open(path, "r+b") as f:
        f.write(head.ljust(116, b" ") + b"\0" * 8 + b"\x00\x02IM")


def test_an_array_of_structs_in_a_matlab_v73_file_imports_as_its_v7_copy(tmp_path):
    rng = np.random.default_rng(8)
    signals = {"speed": 1500.0 + rng.normal(0.0, 1.0, 100), "vibration_1": np.round(rng.normal(0.0, 1.0, 1600), 4)}
    (tmp_path / "v5").mkdir()
    (tmp_path / "v73").mkdir()
    y = np.zeros((1, 2), dtype=[("Name", "O"), ("Data", "O")])
    for i, (name, data) in enumerate(signals.items()):
        y[0, i] = (name, data[None, :])
    top = np.zeros((1, 1), dtype=[("Y", "O")])
    top[0, 0] = (y,)
    scipy.io.savemat(tmp_path / "v5" / "N15_M07_F10_K001_1.mat", {"N15_M07_F10_K001_1": top})
    paderborn_v73(tmp_path / "v73" / "N15_M07_F10_K001_1.mat", signals)
    r = cmd("import", "v73", "--out", "p.bin", cwd=tmp_path)
    assert (r.returncode, r.stderr) == (2, (
        "cmsensord import: v73/N15_M07_F10_K001_1.mat: several variables to import (variables: "
        "N15_M07_F10_K001_1.Y.speed.Data (1, 100), N15_M07_F10_K001_1.Y.vibration_1.Data (1, 1600); 2 of text or "
        "other types not listed); choose one with --variable (several: --variable A,B)\n")), r.stderr
    for name in ("v5", "v73"):
        r = cmd("import", name, "--variable", "*vibration_1.Data,*speed.Data", "--speed-column", "speed.Data",
                "--fs", "1600", "--unit", "g", "--out", f"{name}.bin", cwd=tmp_path)
        assert r.returncode == 0, r.stderr
    assert (tmp_path / "v5.bin").read_bytes() == (tmp_path / "v73.bin").read_bytes()
    assert sidecar(tmp_path / "v73.bin")["tacho_edges"] > 0
