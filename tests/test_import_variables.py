"""`cmsensord import` of MATLAB and NumPy files laid out as public bearing data sets lay them
out: several variables side by side, variable names that carry the record number (CWRU),
a struct holding the signal and its rate (MFPT)."""

from __future__ import annotations

import numpy as np
import scipy.io

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
    assert "  speed: 1797 rpm from 97.mat (sidecar only; --rpm 1797 also sends TACHO frames)\n" in r.stderr
    meta = sidecar(tmp_path / "c.bin")
    assert meta["channel_names"] == ["DE_time", "FE_time"] and meta["rpm"] == 1797
    assert_within_one_count(decode(tmp_path / "c.bin"), np.concatenate([x97, x98], axis=1) * G)
    # by name, one file: the same channels, named as the file names them
    r = cmd("import", "97.mat", "--variable", "X097_FE_time,X097_DE_time", "--fs", "12000", "--unit", "g",
            "--out", "n.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert sidecar(tmp_path / "n.bin")["channel_names"] == ["X097_FE_time", "X097_DE_time"]
    assert_within_one_count(decode(tmp_path / "n.bin"), x97[::-1] * G)


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
