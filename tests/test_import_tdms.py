"""`cmsensord import` of National Instruments' TDMS files (the ``tdms`` extra): the rate and each
file's start from its waveform channels, a logger's directory of snapshot files dated by them,
channels shorter than the others left out but a speed column sampled slower, and a file that is
not TDMS, or no npTDMS, in one line."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest

from tests.test_import import G, assert_within_one_count, cmd, decode, sidecar

nptdms = pytest.importorskip("nptdms", reason="the tdms extra")

FS = 10000


def write_tdms(path, k: int, speed: np.ndarray | None = None, speed_first: bool = False) -> np.ndarray:
    """One snapshot file as a logger writes it: two accelerometers (g) in one group, a slow
    temperature in another, the snapshot's start 10 minutes after the one before (a speed
    channel after them, or before); its samples."""
    rng = np.random.default_rng(k)
    x = np.round(0.2 * rng.standard_normal((2, FS)), 5)
    wave = {"wf_increment": 1.0 / FS, "wf_start_time": np.datetime64("2024-03-05T10:15:00")
            + np.timedelta64(600 * k, "s"), "unit_string": "g"}
    objs = [nptdms.RootObject({}), nptdms.GroupObject("Vibration"),
            nptdms.ChannelObject("Vibration", "Accel DE", x[0], wave),
            nptdms.ChannelObject("Vibration", "Accel FE", x[1], wave),
            nptdms.ChannelObject("Environment", "Temperature", np.array([21.5, 21.6, 21.7]), {"wf_increment": 1.0})]
    if speed is not None:
        objs.insert(2 if speed_first else len(objs),
                    nptdms.ChannelObject("Vibration", "speed", speed, {"wf_increment": 1.0 / speed.size}))
    with nptdms.TdmsWriter(str(path)) as w:
        w.write_segment(objs)
    return x


def test_a_directory_of_tdms_snapshots_gives_its_rate_times_and_channels(tmp_path):
    d = tmp_path / "run"
    d.mkdir()
    xs = [write_tdms(d / f"vib_{k:03d}.tdms", k) for k in range(3)]
    r = cmd("import", "run", "--unit", "g", "--out", "r.bin", cwd=tmp_path, env=dict(os.environ, TZ="UTC"))
    assert r.returncode == 0, r.stderr
    meta = sidecar(tmp_path / "r.bin")
    assert (meta["fs"], meta["channel_names"], meta["source_start"]) == (FS, ["Accel_DE", "Accel_FE"],
                                                                          "2024-03-05T10:15:00")
    assert r.stderr.count("  note: the files' start times (wf_start_time) are UTC: taken in this computer's "
                          "local time (UTC), as LabVIEW shows them; TZ=Area/City sets another zone\n") == 1
    assert [s["source_time_s"] for s in meta["snapshots"]] == [0.0, 600.0, 1200.0]
    assert r.stderr.count("  note: channel(s) Temperature (3) hold fewer samples than the others' 10000: "
                          "not imported\n") == 1
    assert_within_one_count(decode(tmp_path / "r.bin"), np.concatenate(xs, axis=1) * G)


@pytest.mark.parametrize("zone, offset_h, said", [
    ("Europe/Berlin", 1, "CET, UTC+01:00"),         # 5 March: winter time
    ("America/New_York", -5, "EST, UTC-05:00"),
])
def test_tdms_start_times_in_utc_are_read_in_the_local_time_as_labview_shows_them(tmp_path, zone, offset_h, said):
    """wf_start_time is UTC (10:15 in the files): the recording's own time is the computer's local
    one (TZ), as the logger and LabVIEW showed it to the engineer, and the import says so."""
    d = tmp_path / "run"
    d.mkdir()
    for k in range(2):
        write_tdms(d / f"vib_{k}.tdms", k)
    r = cmd("import", "run", "--unit", "g", "--out", "r.bin", cwd=tmp_path, env=dict(os.environ, TZ=zone))
    assert r.returncode == 0, r.stderr
    assert sidecar(tmp_path / "r.bin")["source_start"] == f"2024-03-05T{10 + offset_h:02d}:15:00"
    assert (f"  note: the files' start times (wf_start_time) are UTC: taken in this computer's local time "
            f"({said}), as LabVIEW shows them; TZ=Area/City sets another zone\n") in r.stderr
    assert f"2024-03-05 {10 + offset_h:02d}:15:00 to 2024-03-05 {10 + offset_h:02d}:25:00" in r.stderr


@pytest.mark.parametrize("speed_first", [False, True])
def test_a_speed_channel_sampled_slower_gives_the_tacho(tmp_path, speed_first):
    """The file's rate is the vibration's, wherever the speed channel is listed."""
    rpm = np.full(FS // 10, 1500.0)
    write_tdms(tmp_path / "s.tdms", 0, speed=rpm, speed_first=speed_first)
    r = cmd("import", "s.tdms", "--unit", "g", "--speed-column", "speed", "--out", "s.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    cap = decode(tmp_path / "s.bin")
    assert sidecar(tmp_path / "s.bin")["fs"] == FS
    assert cap["status"].n_channels == 2 and cap["edges"].size == 25     # 25 revolutions in its second
    assert np.allclose(np.diff(cap["edges"]), FS / 25, atol=1 / 256)


def test_a_file_that_is_not_tdms_is_one_line(tmp_path):
    (tmp_path / "bad.tdms").write_bytes(b"TDSm" + bytes(range(200)))
    r = cmd("import", "bad.tdms", "--out", "o.bin", cwd=tmp_path)
    assert r.returncode == 2 and r.stderr.startswith("cmsensord import: bad.tdms: not a readable TDMS file (")
    assert r.stderr.endswith("; export it again from LabVIEW, or as CSV\n") and r.stderr.count("\n") == 1
    assert not list(tmp_path.glob("o.bin*"))


def test_a_tdms_file_cut_short_is_imported_as_far_as_it_goes_and_says_so(tmp_path):
    """Two segments written, the second cut inside its data: npTDMS's own words in a note (not
    its log lines on stderr), the first segment's samples imported."""
    x = np.round(0.2 * np.random.default_rng(1).standard_normal(2 * FS), 5)
    wave = {"wf_increment": 1.0 / FS}
    with nptdms.TdmsWriter(str(tmp_path / "c.tdms")) as w:
        for half in (x[:FS], x[FS:]):
            w.write_segment([nptdms.ChannelObject("Vibration", "acc", half, wave)])
    data = (tmp_path / "c.tdms").read_bytes()
    (tmp_path / "c.tdms").write_bytes(data[:-4000])
    r = cmd("import", "c.tdms", "--unit", "g", "--out", "c.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "nptdms" not in r.stderr and "WARNING" not in r.stderr
    [note] = [ln for ln in r.stderr.splitlines() if "npTDMS" in ln]
    assert note.startswith("  note: c.tdms: npTDMS: ") and note.endswith("; the channels' samples there are imported")
    cap = decode(tmp_path / "c.bin")
    assert cap["x"].shape[1] >= FS
    assert_within_one_count(cap, x[None, :cap["x"].shape[1]] * G)


def test_without_nptdms_a_tdms_file_says_which_extra_reads_it(tmp_path, monkeypatch, capsys):
    from cmsensord.cli import main

    write_tdms(tmp_path / "v.tdms", 0)
    monkeypatch.setitem(sys.modules, "nptdms", None)
    assert main(["import", str(tmp_path / "v.tdms"), "--out", str(tmp_path / "o.bin")]) == 2
    assert capsys.readouterr().err == (f"cmsensord import: {tmp_path / 'v.tdms'}: reading TDMS files needs npTDMS: "
                                       "pip install 'cmsensord[tdms]'\n")


def test_a_tdms_channels_unit_string_is_the_unit_without_unit(tmp_path):
    """The logger's unit_string (g) is what the values are in: the same capture as --unit g."""
    write_tdms(tmp_path / "v.tdms", 0)
    r = cmd("import", "v.tdms", "--out", "auto.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "  note: unit g from the file (Accel DE, Accel FE); --unit sets another\n" in r.stderr
    assert cmd("import", "v.tdms", "--unit", "g", "--out", "g.bin", cwd=tmp_path).returncode == 0
    assert (tmp_path / "auto.bin").read_bytes() == (tmp_path / "g.bin").read_bytes()
