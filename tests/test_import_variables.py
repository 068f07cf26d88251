"""`cmsensord import` of MATLAB and NumPy files laid out as public bearing data sets lay them
out: several variables side by side, variable names that carry the record number (CWRU),
a struct holding the signal and its rate (MFPT)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.io

from cmsensord.sinks.mcap_read import read_messages
from tests.test_import import G, assert_within_one_count, cmd, decode, sidecar

N = 4800


def cwru(path, record: int, seed: int) -> np.ndarray:
    """A file as the CWRU bearing data centre writes it (drive end, fan end, speed); its two
    signals in g, (2, N)."""
    x = np.round(np.random.default_rng(seed).normal(0.0, 0.2, (2, N)), 4)
    scipy.io.savemat(path, {f"X{record:03d}_DE_time": x[0][:, None], f"X{record:03d}_FE_time": x[1][:, None],
                            f"X{record:03d}RPM": np.array([[1797]])})
    return x


def test_cwru_files_by_variable_patterns_side_by_side_with_their_speed(tmp_path):
    x97, x98 = cwru(tmp_path / "97.mat", 97, 1), cwru(tmp_path / "98.mat", 98, 2)
    r = cmd("import", "97.mat", "98.mat", "--variable", "*_DE_time,*_FE_time", "--fs", "12000", "--unit", "g",
            "--out", "c.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert ("  speed: 1797 rpm from 97.mat (no TACHO frames: replay takes it as indicators.rpm; --rpm 1797 also "
            "sends TACHO frames)\n") in r.stderr
    meta = sidecar(tmp_path / "c.bin")
    assert meta["channel_names"] == ["DE_time", "FE_time"] and meta["rpm"] == 1797
    assert_within_one_count(decode(tmp_path / "c.bin"), np.concatenate([x97, x98], axis=1) * G)
    # by name, one file: the same channels, named as the file names them
    r = cmd("import", "97.mat", "--variable", "X097_FE_time,X097_DE_time", "--fs", "12000", "--unit", "g",
            "--out", "n.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert sidecar(tmp_path / "n.bin")["channel_names"] == ["X097_FE_time", "X097_DE_time"]
    assert_within_one_count(decode(tmp_path / "n.bin"), x97[::-1] * G)


def test_a_cwru_file_that_also_holds_another_records_signals_gives_its_own(tmp_path):
    """CWRU's 99.mat holds record 98's drive-end and fan-end signals beside its own 99's: the
    pattern takes the variables of the record the file is named by."""
    x98 = cwru(tmp_path / "98.mat", 98, 2)
    x99 = cwru(tmp_path / "99.mat", 99, 3)
    both = {**scipy.io.loadmat(tmp_path / "98.mat"), **scipy.io.loadmat(tmp_path / "99.mat"), "X099RPM": 1750.0}
    scipy.io.savemat(tmp_path / "99.mat", {k: v for k, v in both.items() if not k.startswith("__")})
    r = cmd("import", "98.mat", "99.mat", "--variable", "*_DE_time,*_FE_time", "--fs", "12000", "--unit", "g",
            "--out", "c.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert_within_one_count(decode(tmp_path / "c.bin"), np.concatenate([x98, x99], axis=1) * G)
    assert ("  note: the files give different speeds (98.mat 1797 rpm; 99.mat 1750 rpm): the capture keeps 1797 "
            "rpm; import each speed on its own, or give --rpm\n") in r.stderr
    # its speed too: record 99's 1750 rpm, not 98's 1797 stored first
    r = cmd("import", "99.mat", "--variable", "*_DE_time", "--fs", "12000", "--out", "s.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert sidecar(tmp_path / "s.bin")["rpm"] == 1750.0


def test_mfpt_struct_fields_give_the_signal_and_its_rate(tmp_path):
    gs = np.round(np.random.default_rng(3).normal(0.0, 1.0, 9766), 4)
    scipy.io.savemat(tmp_path / "baseline_1.mat", {"bearing": {"sr": 97656, "gs": gs[:, None], "load": 270,
                                                               "rate": 25}})
    r = cmd("import", "baseline_1.mat", "--unit", "g", "--out", "m.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    meta = sidecar(tmp_path / "m.bin")
    assert (meta["fs"], meta["channel_names"]) == (97656, ["bearing_gs"])     # a channel name: no "."
    L = meta["block_len"]
    assert_within_one_count(decode(tmp_path / "m.bin"), gs[None, :gs.size // L * L] * G)


def paderborn(path, seed: int) -> np.ndarray:
    """A file as the Paderborn bearing data centre writes it: one struct named after the file,
    whose Y is an array of structs, each a named signal (Name, Raster, Data); its vibration."""
    rng = np.random.default_rng(seed)
    y = np.zeros((1, 3), dtype=[("Name", "O"), ("Raster", "O"), ("Data", "O")])
    for i, (name, n) in enumerate([("force", 400), ("phase_current_1", 6400), ("vibration_1", 6400)]):
        y[0, i] = (name, "HostService", np.round(rng.normal(0.0, 1.0, (1, n)), 4))
    top = np.zeros((1, 1), dtype=[("Info", "O"), ("Y", "O")])
    top[0, 0] = ("info", y)
    scipy.io.savemat(path, {path.stem: top})
    return y[0, 2]["Data"].ravel()


def test_paderborn_files_by_the_name_of_a_signal_in_an_array_of_structs(tmp_path):
    d = tmp_path / "K001"
    d.mkdir()
    x = [paderborn(d / f"N15_M07_F10_K001_{k}.mat", k) for k in (1, 2, 10)]
    r = cmd("import", d, "--variable", "*vibration_1.Data", "--fs", "6400", "--out", "p.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    meta = sidecar(tmp_path / "p.bin")
    assert meta["channel_names"] == ["vibration_1_Data"]
    assert [s["source"] for s in meta["snapshots"]] == [f"N15_M07_F10_K001_{k}.mat" for k in (1, 2, 10)]
    assert_within_one_count(decode(tmp_path / "p.bin"), np.concatenate(x)[None])


def paderborn_run_up(path, rpm0: float, fs: int, n: int) -> np.ndarray:
    """A Paderborn-like file whose speed (rpm, rising 60 rpm a second) is sampled 16 x slower
    than its vibration, one sample more than a whole factor (16015 against 256823 in the real
    files); the speed at each vibration sample, as the import should read it."""
    m = n // 16 + 1
    speed = rpm0 + 60.0 * np.arange(m) * (n / m) / fs
    y = np.zeros((1, 2), dtype=[("Name", "O"), ("Raster", "O"), ("Data", "O")])
    y[0, 0] = ("speed", "Mech_4kHz", speed[None, :])
    y[0, 1] = ("vibration_1", "HostService", np.round(np.random.default_rng(3).normal(0.0, 1.0, (1, n)), 4))
    top = np.zeros((1, 1), dtype=[("Info", "O"), ("Y", "O")])
    top[0, 0] = ("info", y)
    scipy.io.savemat(path, {path.stem: top})
    return np.interp(np.arange(n) * m / n, np.arange(m), speed)


def test_a_speed_sampled_slower_than_the_vibration_gives_the_tacho_over_the_same_time(tmp_path):
    fs, n = 6400, 12800
    rpm = [paderborn_run_up(tmp_path / f"N15_M07_F10_K001_{k}.mat", 1500.0 + 120 * k, fs, n) for k in (1, 2)]
    args = ("import", ".", "--variable", "*vibration_1.Data,*speed.Data", "--fs", fs, "--out", "p.bin")
    r = cmd(*args, cwd=tmp_path)
    assert r.returncode == 2 and r.stderr.endswith(
        "variable 'N15_M07_F10_K001_1.Y.speed.Data' holds 801 samples x 1 snapshot(s), "
        "'N15_M07_F10_K001_1.Y.vibration_1.Data' 12800 x 1; --variable takes variables of the same length; "
        "a speed sampled slower: name it with --speed-column\n"), r.stderr
    r = cmd(*args, "--speed-column", "speed.Data", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert ("  note: speed.Data: 801 samples beside 12800 of vibration_1.Data: taken as the same time "
            "sampled 15.98 x slower, interpolated linearly\n") in r.stderr
    cap = decode(tmp_path / "p.bin")
    assert cap["status"].n_channels == 1 and cap["status"].tacho_inputs == 1
    # each file's revolutions, from its first sample: the trapezoid sum of its speed / 60 / fs
    expected = []
    for k, v in enumerate(rpm):
        revs = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) / 60 / fs)])
        expected += [k * n + np.interp(e, revs, np.arange(n)) for e in range(int(revs[-1]) + 1)]
    assert cap["edges"].size == len(expected) == 116   # from 1620 and 1740 rpm, rising, 2 s each
    assert np.allclose(cap["edges"], expected, atol=1 / 256)
    assert sidecar(tmp_path / "p.bin")["tacho_from"] == "speed"


def test_npz_arrays_side_by_side(tmp_path):
    a, b = np.random.default_rng(4).normal(0.0, 1.0, (2, 3000))
    np.savez(tmp_path / "r.npz", acc_x=a, acc_y=b, fs=10000)
    r = cmd("import", "r.npz", "--array", "acc_y,acc_x", "--out", "r.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert sidecar(tmp_path / "r.bin")["channel_names"] == ["acc_y", "acc_x"]
    assert_within_one_count(decode(tmp_path / "r.bin"), np.stack([b, a]))


def test_variable_choices_that_do_not_fit_are_one_line_errors(tmp_path):
    cwru(tmp_path / "97.mat", 97, 1)
    scipy.io.savemat(tmp_path / "odd.mat", {"a": np.zeros((100, 1)), "b": np.zeros((90, 1))})
    scipy.io.savemat(tmp_path / "s.mat", {"bearing": {"sr": 1000, "gs": np.zeros((100, 1))}})
    cases = {
        ("97.mat",): "97.mat: several variables to import (variables: X097_DE_time (4800, 1), "
                     "X097_FE_time (4800, 1), X097RPM (1, 1)); choose one with --variable (several: --variable A,B)",
        ("97.mat", "--variable", "*_time"):
            "97.mat: --variable *_time: 2 variables match it (X097_DE_time, X097_FE_time) (variables: "
            "X097_DE_time, X097_FE_time, X097RPM); give a pattern that matches one",
        ("97.mat", "--variable", "*_BA_time"):
            "97.mat: --variable *_BA_time: no variable matches it (variables: X097_DE_time, X097_FE_time, "
            "X097RPM); give a pattern that matches one",
        ("odd.mat", "--variable", "a,b"):
            "odd.mat: variable 'b' holds 90 samples x 1 snapshot(s), 'a' 100 x 1; --variable takes "
            "variables of the same length",
        ("s.mat", "--variable", "bearing"): "s.mat: no variable 'bearing' (variables: bearing.sr, bearing.gs); "
                                            "use --variable",
    }
    for args, message in cases.items():
        r = cmd("import", *args, "--fs", "1000", "--out", "o.bin", cwd=tmp_path)
        assert (r.returncode, r.stdout, r.stderr) == (2, "", f"cmsensord import: {message}\n"), args
        assert not list(tmp_path.glob("o.bin*")), args


def encoder_run_up(path, fs: int, n: int, ppr: int) -> np.ndarray:
    """A file as the University of Ottawa's time-varying-speed set writes one: the vibration
    (Channel_1) beside an encoder's square wave (Channel_2) of ``ppr`` pulses a revolution, the
    shaft speeding up from 10 to 12 revolutions a second; the encoder's rising crossings."""
    revs = np.cumsum(10.0 + 2.0 * np.arange(n) / n) / fs
    square = (np.sin(2 * np.pi * ppr * revs - 0.1) > 0).astype(np.float64) * 5.0
    scipy.io.savemat(path, {"Channel_1": np.sin(2 * np.pi * revs)[:, None], "Channel_2": square[:, None]})
    up = np.flatnonzero((square[:-1] < 2.5) & (square[1:] >= 2.5))
    return up + (2.5 - square[up]) / (square[up + 1] - square[up])


def test_an_encoder_of_more_pulses_than_the_board_carries_keeps_every_kth_edge_of_each_snapshot(tmp_path):
    fs, n = 20000, 20000
    rising = [encoder_run_up(tmp_path / f"I-A-{k}.mat", fs, n, 360) for k in (1, 2)]
    r = cmd("import", "I-A-1.mat", "I-A-2.mat", "--variable", "Channel_1,Channel_2", "--tacho-column", "Channel_2",
            "--ppr", "360", "--fs", fs, "--unit", "g", "--out", "e.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert ("  note: --ppr 360: the board protocol carries at most 255 pulses a revolution: 180 a revolution "
            "(one edge in 2, at the same angles)\n") in r.stderr
    cap = decode(tmp_path / "e.bin")
    assert cap["status"].tacho_ppr == 180
    expected = np.concatenate([k * n + e[::2] for k, e in enumerate(rising)])
    assert expected.size > 3900 and cap["edges"].size == expected.size
    assert np.allclose(cap["edges"], expected, atol=1 / 256)
    # the replay's shaft speed from them: 10 -> 12 revolutions a second in each file
    r = cmd("replay", "e.bin", "--out", "logs", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    (log,) = (tmp_path / "logs").glob("*.mcap")
    rpm = [m["speed_rpm"] for topic, _, m in read_messages(log) if topic.endswith("/orders") and m["valid"]]
    assert rpm and 600 * 0.99 < min(rpm) and max(rpm) < 720 * 1.01


def test_an_encoder_ppr_with_a_constant_speed_and_a_ppr_the_board_cannot_take_at_all(tmp_path):
    np.save(tmp_path / "x.npy", np.zeros(20000))
    r = cmd("import", "x.npy", "--fs", 20000, "--rpm", "600", "--ppr", "1000", "--out", "c.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    cap = decode(tmp_path / "c.bin")
    assert cap["status"].tacho_ppr == 250 and np.allclose(cap["edges"], np.arange(2500) * 8.0)
    r = cmd("import", "x.npy", "--fs", 20000, "--rpm", "600", "--ppr", "0", "--out", "c.bin", cwd=tmp_path)
    assert r.returncode == 2 and r.stderr.startswith("cmsensord import: error: argument --ppr: expected an integer "
                                                     "1..65536, got 0"), r.stderr


def mat73(path, variables: dict) -> None:
    """A MATLAB v7.3 file as MATLAB writes one: HDF5 behind a 512-byte MAT header, each
    variable transposed, a MATLAB_class on each; a dict is a struct, a str a char array."""
    h5py = pytest.importorskip("h5py", reason="the mat73 extra")

    def put(group, name, v):
        d = group.create_dataset(name, data=np.atleast_2d(np.asarray(v, dtype=np.float64)).T)
        d.attrs["MATLAB_class"] = np.bytes_("double")

    with h5py.File(path, "w", userblock_size=512) as f:
        for name, v in variables.items():
            if isinstance(v, dict):
                g = f.create_group(name)
                g.attrs["MATLAB_class"] = np.bytes_("struct")
                for k, x in v.items():
                    put(g, k, x)
            elif isinstance(v, str):
                d = f.create_dataset(name, data=np.array([[ord(c) for c in v]], dtype=np.uint16).T)
                d.attrs["MATLAB_class"] = np.bytes_("char")
            else:
                put(f, name, v)
    head = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Nov 30 08:00:00 2026 HDF5 schema 1.00 ."
    with open(path, "r+b") as f:
        f.write(head.ljust(116, b" ") + b"\0" * 8 + b"\x00\x02IM")


def test_a_matlab_v73_file_imports_as_the_same_variables_saved_as_v7(tmp_path):
    """CWRU's variables (a signal, its speed, a note) saved as v7.3 and as v5: the same capture;
    an MFPT-like struct's signal and rate in v7.3 too."""
    x = np.round(np.random.default_rng(6).normal(0.0, 0.3, (N, 1)), 5)
    scipy.io.savemat(tmp_path / "v5.mat", {"X097_DE_time": x, "X097RPM": 1796.0, "note": "healthy"})
    mat73(tmp_path / "v73.mat", {"X097_DE_time": x, "X097RPM": 1796.0, "note": "healthy"})
    for name in ("v5", "v73"):
        r = cmd("import", f"{name}.mat", "--variable", "*_DE_time", "--fs", "12000", "--unit", "g",
                "--out", f"{name}.bin", cwd=tmp_path)
        assert r.returncode == 0, r.stderr
    assert (tmp_path / "v5.bin").read_bytes() == (tmp_path / "v73.bin").read_bytes()
    assert sidecar(tmp_path / "v73.bin")["rpm"] == 1796.0
    mat73(tmp_path / "mfpt.mat", {"bearing": {"gs": x[:, 0], "sr": 48828.0}})
    r = cmd("import", "mfpt.mat", "--variable", "bearing.gs", "--unit", "g", "--out", "m.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert sidecar(tmp_path / "m.bin")["fs"] == 48828


def test_a_matlab_v73_file_without_h5py_or_cut_short_is_one_line(tmp_path, monkeypatch, capsys):
    import sys

    from cmsensord.cli import main

    mat73(tmp_path / "v73.mat", {"x": np.zeros(N)})
    data = (tmp_path / "v73.mat").read_bytes()
    (tmp_path / "cut.mat").write_bytes(data[:len(data) // 2])
    # bytes of the superblock's neighbourhood damaged: h5py says so as OSError, RuntimeError, KeyError
    for at in (512, 640, 1344):
        (tmp_path / f"bad{at}.mat").write_bytes(data[:at] + b"\xff" * 16 + data[at + 16:])
    for name in ("cut", "bad512", "bad640", "bad1344"):
        assert main(["import", str(tmp_path / f"{name}.mat"), "--fs", "100", "--out", str(tmp_path / "o.bin")]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"cmsensord import: {tmp_path / name}.mat: a MATLAB v7.3 (HDF5) file that cannot be "
                              "read (") and err.count("\n") == 1, err
    monkeypatch.setitem(sys.modules, "h5py", None)
    assert main(["import", str(tmp_path / "v73.mat"), "--fs", "100", "--out", str(tmp_path / "o.bin")]) == 2
    assert capsys.readouterr().err == (f"cmsensord import: {tmp_path / 'v73.mat'}: a MATLAB v7.3 (HDF5) file: "
                                       "reading it needs h5py (pip install 'cmsensord[mat73]'); or in MATLAB "
                                       "re-save it with save(FILE, VAR, '-v7'), or export it as CSV\n")
    assert not list(tmp_path.glob("o.bin*"))
