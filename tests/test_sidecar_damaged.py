"""A capture's sidecar that is JSON but damaged (a field of the wrong type, missing, an
impossible date) is checked where it is read: each field that cannot be used is said on one
warning line naming it, and replay and calibrate go on without it. The capture's STATUS frames
say its sampling rate: a sidecar ``fs`` that differs is said and not used."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from processes import run_module

FS = 2000
N = 2000        # a snapshot: 1 s, 100 blocks of 20
SNAPSHOTS = "its snapshots (the records' length, the times in the recording) are not used"


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    """Four 1-s snapshots in files named by their date and time, 5 minutes apart, imported
    at 1800 rpm (no tacho frames: the speed is the sidecar's)."""
    d = tmp_path_factory.mktemp("rig")
    rng = np.random.default_rng(0)
    for k in range(4):
        np.savetxt(d / f"2004.02.12.10.{5 * k:02d}.39", rng.standard_normal(N) * (1 + k), fmt="%.5f")
    p = run_module("cmsensord", "import", str(d), "--fs", str(FS), "--unit", "m/s2", "--out", str(d / "r.bin"))
    assert p.returncode == 0, p.stderr
    p = run_module("cmsensord", "import", str(d), "--fs", str(FS), "--unit", "m/s2", "--rpm", "1800",
                   "--out", str(d / "t.bin"))
    assert p.returncode == 0, p.stderr
    return d


def _damaged(imported, tmp_path, edit, name="r.bin"):
    """A copy of the imported capture whose sidecar ``edit(meta)`` changed."""
    cap = tmp_path / name
    shutil.copy(imported / name, cap)
    meta = json.loads((imported / f"{name}.json").read_text())
    edit(meta)
    (tmp_path / f"{name}.json").write_text(json.dumps(meta))
    return cap


def _warnings(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("warning: ")]


def _set(key, value):
    return lambda meta: meta.__setitem__(key, value)


def _snap(k, key, value):
    return lambda meta: meta["snapshots"][k].__setitem__(key, value)


@pytest.mark.parametrize("edit, said", [
    (_set("fs", float("nan")), "fs is NaN (not a positive number): the STATUS frames' 2000 Hz is used"),
    (_set("fs", "abc"), "fs is \"abc\" (not a positive number): the STATUS frames' 2000 Hz is used"),
    (lambda m: m["snapshots"][1].pop("start_s"), f"snapshots[1].start_s is missing: {SNAPSHOTS}"),
    (lambda m: m["snapshots"].__setitem__(1, None), f"snapshots[1] is null (not an object): {SNAPSHOTS}"),
    (_snap(1, "source_time_s", "n/a"), f"snapshots[1].source_time_s is \"n/a\" (not a number of seconds): {SNAPSHOTS}"),
    (_snap(1, "source", None), f"snapshots[1].source is null (not a text): {SNAPSHOTS}"),
    (_set("source_start", "2004-02-30T10:00:39"),
     "source_start is \"2004-02-30T10:00:39\" (day is out of range for month): its date is not used"),
    (_set("source_start", "9999-12-31T23:59:59"),
     "source_start is \"9999-12-31T23:59:59\" (its snapshots' times run past the year 9999): its date is not used"),
    (_set("unit", "furlong"), "unit is \"furlong\" (not m/s2 or Pa, one or one per channel): its units are not used"),
    (_set("channel_names", [1, 2]), "channel_names is [1, 2] (not a list of texts): its channel names are not used"),
])
def test_a_damaged_field_is_one_warning_and_the_replay_goes_on(imported, tmp_path, edit, said):
    cap = _damaged(imported, tmp_path, edit)
    p = run_module("cmsensord", "replay", str(cap), "--out", str(tmp_path / "out"))
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr
    assert _warnings(p.stderr) == [f"warning: {cap}.json: the capture's sidecar's {said}"], p.stderr
    assert "400 observations, 0 missing" in p.stderr and "None" not in p.stderr, p.stderr


def test_calibrate_leaves_out_a_speed_that_is_not_a_number(imported, tmp_path):
    cap = _damaged(imported, tmp_path, _set("rpm", "1800 rpm"), "t.bin")
    p = run_module("cmsensord", "calibrate", str(cap), "--to", "50%", "--out", str(tmp_path / "site.yaml"))
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr
    assert _warnings(p.stdout + p.stderr) == [f"warning: {cap}.json: the capture's sidecar's rpm is \"1800 rpm\" "
                                              "(not a speed in rpm): its speed is not used"], p.stderr


def test_the_status_frames_rate_is_used_over_the_sidecars(imported, tmp_path):
    """A sidecar fs of twice the STATUS frames' rate would cut records of half a snapshot."""
    cap = _damaged(imported, tmp_path, _set("fs", 2 * FS))
    p = run_module("cmsensord", "replay", str(cap), "--out", str(tmp_path / "out"))
    assert p.returncode == 0, p.stderr
    assert _warnings(p.stderr) == [f"warning: {cap}.json: the capture's sidecar's fs is 4000 Hz, its STATUS "
                                   "frames' 2000 Hz: the STATUS rate is used"], p.stderr
    assert "interval_s" not in p.stderr, p.stderr       # 1-s records: one a snapshot
    p = run_module("cmsensord", "calibrate", str(cap), "--to", "50%", "--out", str(tmp_path / "site.yaml"))
    assert p.returncode == 0, p.stderr
    assert "interval_s" not in (tmp_path / "site.yaml").read_text()


def test_snapshots_that_rest_on_another_rate_are_left_out(imported, tmp_path):
    def edit(meta):
        meta["fs"] = 2 * FS
        for s in meta["snapshots"]:
            s["start_s"] /= 2
    cap = _damaged(imported, tmp_path, edit)
    p = run_module("cmsensord", "replay", str(cap), "--out", str(tmp_path / "out"))
    assert p.returncode == 0, p.stderr
    assert _warnings(p.stderr) == [
        f"warning: {cap}.json: the capture's sidecar's fs is 4000 Hz, its STATUS frames' 2000 Hz: the STATUS rate "
        "is used",
        f"warning: {cap}.json: the capture's sidecar's snapshots[1].start_s is 0.5 (snapshot 0 of 2000 samples from "
        f"0 s ends at 1 s at 2000 Hz): {SNAPSHOTS}"], p.stderr


def test_what_the_importer_writes_is_never_warned_of(tmp_path):
    """A file cut shorter than a block among the snapshots (a snapshot of length 0) and a speed
    column stopped most of the time (no median speed) are what the importer writes: their
    replay says nothing of the sidecar, and takes the records from the snapshots."""
    d = tmp_path / "rig"
    d.mkdir()
    rng = np.random.default_rng(1)
    for k, n in enumerate((200, 200, 7, 200)):             # 0.1-s snapshots, as FEMTO's
        np.savetxt(d / f"acc_{k}.csv", rng.standard_normal(n), fmt="%.5f")
    run = np.where(np.arange(4 * N) < 2.4 * N, 0.0, 1200.0)
    np.savetxt(tmp_path / "runup.csv", np.c_[rng.standard_normal(4 * N), run], fmt="%.5f", delimiter=",",
               header="acc,speed", comments="")
    for args in ((str(d), "--snapshot-interval", "10"),
                 (str(tmp_path / "runup.csv"), "--channels", "acc", "--speed-column", "speed")):
        cap = tmp_path / "c.bin"
        p = run_module("cmsensord", "import", *args, "--fs", str(FS), "--unit", "m/s2", "--out", str(cap))
        assert p.returncode == 0, p.stderr
        p = run_module("cmsensord", "replay", str(cap), "--out", str(tmp_path / "out"))
        assert p.returncode == 0 and not _warnings(p.stderr), p.stderr
        assert args[1] != "--snapshot-interval" or "(200 samples, one record a snapshot)" in p.stderr, p.stderr
