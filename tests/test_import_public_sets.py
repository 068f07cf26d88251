"""`cmsensord import` of small look-alikes of public bearing data sets' files, run as a newcomer
runs it: first with no options, then with the ones the line asks for. The elements of an array
of structs that share a name (Paderborn's) each keep their fields."""

from __future__ import annotations

import numpy as np
import scipy.io

from tests.test_import import assert_within_one_count, cmd, decode, sidecar


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
