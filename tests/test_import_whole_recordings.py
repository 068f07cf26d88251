"""`cmsensord import` of several files that each hold many snapshots (whole recordings, as
FEMTO's archive of each bearing's life): refused, naming the files and how to import each one,
unless ``--join-recordings`` lays them end to end on purpose; a directory of one-snapshot files
(the IMS rig's layout) stays one recording."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from processes import cmsensord


def _bearings(tmp_path: Path) -> Path:
    """Two bearings' archives in one directory, FEMTO's layout: 4 and 3 snapshots of 2560 samples
    at 25.6 kHz in milli-g, 10 s apart, at one speed (nothing tells them apart but the files)."""
    d = tmp_path / "femto"
    d.mkdir()
    rng = np.random.default_rng(3)
    for name, n in (("Bearing1_1", 4), ("Bearing1_2", 3)):
        np.savez(d / f"{name}.npz", acc_mg=rng.integers(-500, 500, (n, 2560, 2)).astype(np.int32),
                 t_s=np.arange(n) * 10.0, fs_hz=np.array(25600), rpm=np.array(1800))
    return d


def test_a_directory_of_whole_recordings_is_refused_naming_them_and_how_to_import_each(tmp_path):
    d = _bearings(tmp_path)
    p = cmsensord("import", str(d), "--unit", "mg", "--out", "dir.bin", cwd=tmp_path)
    assert (p.returncode, p.stdout, p.stderr) == (2, "", (
        "cmsensord import: Bearing1_1.npz (4 snapshots) and Bearing1_2.npz (3) each hold a whole recording; "
        f"import each of the 2 files on its own (cmsensord import {d / 'Bearing1_1.npz'} ... --out Bearing1_1.bin), "
        "or give --join-recordings to lay them end to end as one machine's history\n"))
    assert sorted(f.name for f in tmp_path.iterdir()) == ["femto"]          # nothing written beside --out
    p = cmsensord("import", str(d / "Bearing1_1.npz"), str(d / "Bearing1_2.npz"), "--unit", "mg",
                  "--out", "two.bin", cwd=tmp_path)
    assert p.returncode == 2 and "each hold a whole recording" in p.stderr


def test_join_recordings_lays_them_end_to_end_on_purpose(tmp_path):
    d = _bearings(tmp_path)
    p = cmsensord("import", str(d), "--unit", "mg", "--join-recordings", "--out", "dir.bin", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    snaps = json.loads((tmp_path / "dir.bin.json").read_text())["snapshots"]
    assert [s["source"] for s in snaps] == [f"Bearing1_1.npz[{k}]" for k in range(4)] + \
        [f"Bearing1_2.npz[{k}]" for k in range(3)]


def test_a_directory_of_one_snapshot_files_is_one_recording(tmp_path):
    d = tmp_path / "acc"
    d.mkdir()
    rng = np.random.default_rng(4)
    for k in range(3):
        np.savetxt(d / f"acc_{k + 1}.csv", rng.standard_normal((2560, 1)), fmt="%.4f")
    p = cmsensord("import", str(d), "--fs", "25600", "--unit", "g", "--out", "acc.bin", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    snaps = json.loads((tmp_path / "acc.bin.json").read_text())["snapshots"]
    assert [s["source"] for s in snaps] == ["acc_1.csv", "acc_2.csv", "acc_3.csv"]
