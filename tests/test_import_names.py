"""`cmsensord import` of snapshot files under names of no known type (the IMS bearing rig's
files: text tables named by date and time), and snapshot times from the files' names."""

from __future__ import annotations

import json
import math
import os
import re
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from cmsensord.importing.name_times import times_from_names
from cmsensord.sinks.mcap_sink import read_messages
from tests.test_import import G, assert_within_one_count, cmd, decode, sidecar

FS, ROWS = 20480, 2048
#: IMS-style names: the second file 10 min after the first, the third 5 min after it
NAMES = ("2004.02.12.10.32.39", "2004.02.12.10.42.39", "2004.02.12.10.47.39")


def ims_dir(tmp_path: Path) -> tuple[Path, np.ndarray]:
    """A directory as the IMS rig writes it (four tab-separated columns in g, no header, one
    file per snapshot named by its time), with a README and a hidden binary file beside them;
    and the files' first column, end to end."""
    d = tmp_path / "2nd_test"
    d.mkdir()
    rng = np.random.default_rng(7)
    first = []
    for name in NAMES:
        x = np.round(rng.normal(0.0, 0.1, (ROWS, 4)), 3)
        np.savetxt(d / name, x, fmt="%.3f", delimiter="\t")
        first.append(x[:, 0])
    (d / "Readme Document for IMS Bearing Data.txt").write_text("Bearing data, test 2\nNASA\n")
    (d / ".DS_Store").write_bytes(b"\x00\x00\x00\x01Bud1" + bytes(64))
    return d, np.concatenate(first)


def test_ims_files_named_by_time_import_with_their_times(tmp_path):
    d, x = ims_dir(tmp_path)
    r = cmd("import", d, "--fs", FS, "--channels", "0", "--unit", "g", "--block-len", "256",
            "--out", "ims.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert ("  note: snapshot times from the file names: 2004-02-12 10:32:39 to 2004-02-12 10:47:39 "
            "(0.25 h); --snapshot-interval S sets them instead\n") in r.stderr
    assert_within_one_count(decode(tmp_path / "ims.bin"), x[None] * G)
    meta = sidecar(tmp_path / "ims.bin")
    assert meta["source_start"] == "2004-02-12T10:32:39"
    snaps = meta["snapshots"]
    assert [s["source"] for s in snaps] == list(NAMES)
    assert [s["source_time_s"] for s in snaps] == [0.0, 600.0, 900.0]
    assert [s["gap_before_s"] for s in snaps] == [None, 599.9, 299.9]    # each snapshot is 0.1 s
    # the same files by a glob: the same capture, byte for byte
    r = cmd("import", d / "2004.*", "--fs", FS, "--channels", "0", "--unit", "g", "--block-len", "256",
            "--out", "glob.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "glob.bin").read_bytes() == (tmp_path / "ims.bin").read_bytes()


def test_snapshots_within_a_named_file_and_the_interval_option(tmp_path):
    d, _ = ims_dir(tmp_path)
    args = ("--fs", FS, "--channels", "0", "--unit", "g", "--block-len", "256")
    r = cmd("import", d, *args, "--snapshot-len", "1024", "--out", "s.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    times = [s["source_time_s"] for s in sidecar(tmp_path / "s.bin")["snapshots"]]
    assert times == [0.0, 0.05, 600.0, 600.05, 900.0, 900.05]    # 1024 samples at 20480 Hz: 0.05 s
    r = cmd("import", d, *args, "--snapshot-interval", "10", "--out", "i.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "from the file names" not in r.stderr
    assert [s["source_time_s"] for s in sidecar(tmp_path / "i.bin")["snapshots"]] == [0.0, 10.0, 20.0]


@pytest.mark.parametrize("names, seconds", [
    (["rec_2024-01-05_23-59-30.csv", "rec_2024-01-06_00-00-10.csv"], [0.0, 40.0]),
    (["20240105T235930.wav", "20240106T000010.wav"], [0.0, 40.0]),
    (["a/20240105_235930", "b/20240106_000010"], [0.0, 40.0]),
    (["acc_1.csv", "acc_2.csv"], None),                                     # no time in the names
    (["2004.02.12.10.42.39", "2004.02.12.10.32.39"], None),                 # not increasing
    (["2004.02.12.10.32.39", "2004.02.30.10.42.39"], None),                 # not a date
    (["2004.02.12.10.32.39_2004.02.12.10.33.39", "2004.02.12.10.42.39"], None),   # two in one name
    (["2004.02.12.10.32.39"], None),                                        # one file
])
def test_times_from_names(names, seconds):
    got = times_from_names(names)
    assert (None if got is None else got.seconds) == seconds


def test_a_directory_of_files_not_in_series_takes_them_all(tmp_path):
    """Files named each its own way (and one series beside them) are all taken, in name order."""
    d = tmp_path / "week"
    d.mkdir()
    for i, name in enumerate(["monday.csv", "tuesday.csv", "run1.csv", "run2.csv"]):
        (d / name).write_text(f"{i}\n{i}\n")
    r = cmd("import", d, "--fs", "100", "--block-len", "2", "--out", "w.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "left out" not in r.stderr
    assert [s["source"] for s in sidecar(tmp_path / "w.bin")["snapshots"]] == \
        ["monday.csv", "run1.csv", "run2.csv", "tuesday.csv"]


def test_files_of_no_known_type_that_are_not_text_tables_are_one_line_errors(tmp_path):
    (tmp_path / "blob").write_bytes(bytes(range(256)))
    (tmp_path / "words").write_text("not a number\nnor this\n")
    d = tmp_path / "notes"
    d.mkdir()
    (d / "log").write_text("started at 10:32\n")
    cases = {
        "blob": "blob: unknown file type (no extension), and not a text table of numbers; supported: "
                ".wav, .csv, .tsv, .txt, .lvm, .npy, .npz, .mat, .tdms",
        "words": "words: unknown file type (no extension), and not a text table of numbers; supported: "
                 ".wav, .csv, .tsv, .txt, .lvm, .npy, .npz, .mat, .tdms",
        "notes": "notes: no recording files (.wav, .csv, .tsv, .txt, .lvm, .npy, .npz, .mat, .tdms, or text tables of "
                 "numbers) in this directory; give the files or a --glob pattern",
    }
    for src, message in cases.items():
        r = cmd("import", src, "--fs", "100", "--out", "o.bin", cwd=tmp_path)
        assert (r.returncode, r.stdout, r.stderr) == (2, "", f"cmsensord import: {message}\n"), src
        assert not list(tmp_path.glob("o.bin*")), src


def test_a_directory_takes_its_largest_series_of_files_and_says_what_it_left(tmp_path):
    """FEMTO's bearing directories hold acc_NNNNN.csv snapshots and, beside them, fewer
    temp_NNNNN.csv temperature files of another layout."""
    d = tmp_path / "Bearing1_1"
    d.mkdir()
    rng = np.random.default_rng(3)
    x = np.round(rng.normal(0.0, 0.5, (3, 2560)), 3)
    for k in range(3):
        rows = [f"9,39,{39 + 10 * k},{65664 + 39 * i},{v:.3f},0.1" for i, v in enumerate(x[k])]
        (d / f"acc_{k + 1:05d}.csv").write_text("\n".join(rows) + "\n")
    for k in (1, 2):
        (d / f"temp_{k:05d}.csv").write_text("9,39,39,6.5e+05,29.8\n9,39,39,7.5e+05,29.8\n")
    (d / "notes.csv").write_text("1,2\n")      # alone: no series, left out with the temperatures
    r = cmd("import", d, "--fs", "25600", "--channels", "4", "--unit", "g", "--out", "b.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    note = (f"{d}: took the 3 file(s) named like acc_#.csv; left out 3 other(s) (notes.csv, temp_#.csv): "
            "name them to import them")
    assert f"  note: {note}\n" in r.stderr
    meta = sidecar(tmp_path / "b.bin")
    assert [s["source"] for s in meta["snapshots"]] == ["acc_00001.csv", "acc_00002.csv", "acc_00003.csv"]
    assert note in meta["notes"]
    assert_within_one_count(decode(tmp_path / "b.bin"), x.reshape(1, -1) * G)


@pytest.mark.parametrize("names, order", [
    (["20.48.csv", "9.8304.csv", "20.0704.csv", "10.csv"], ["9.8304.csv", "10.csv", "20.0704.csv", "20.48.csv"]),
    (["run1.10.csv", "run1.9.csv", "run1.2.csv"], ["run1.2.csv", "run1.9.csv", "run1.10.csv"]),
])
def test_files_named_by_a_decimal_number_are_in_the_order_of_its_value(tmp_path, names, order):
    """MAFAULDA names each file by its speed in Hz: 20.0704 before 20.48. Names that are more
    than one number keep the order of their runs of digits."""
    d = tmp_path / "speeds"
    d.mkdir()
    for name in names:
        (d / name).write_text("0.1\n-0.1\n0.2\n-0.2\n")
    r = cmd("import", d, "--fs", "100", "--block-len", "2", "--out", "w.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert [s["source"] for s in sidecar(tmp_path / "w.bin")["snapshots"]] == order


def _snapshot_files(d: Path, names: list[str], level: dict[str, float]) -> None:
    """One four-sample snapshot file per name, written in the order of ``names``, each its own level."""
    d.mkdir()
    for name in names:
        v = level[name]
        (d / name).write_text(f"{v}\n{-v}\n{2 * v}\n{-2 * v}\n")


@pytest.mark.parametrize("order, taken", [("name", "abc"), ("mtime", "cab"), ("given", "bca")])
def test_order_option_takes_snapshot_files_by_name_mtime_or_as_given(tmp_path, order, taken):
    """`--order`: natural name order (the default), the files' modification times (oldest first), or
    the order they are given in; the sidecar lists the snapshots, and the capture holds their samples,
    in that order.  Names a, b, c; modified c, then a, then b; given b, c, a."""
    level = {"a.csv": 0.1, "b.csv": 0.2, "c.csv": 0.3}
    _snapshot_files(tmp_path / "set", list(level), level)
    for i, name in enumerate(("c.csv", "a.csv", "b.csv")):
        os.utime(tmp_path / "set" / name, (1_600_000_000 + 60 * i,) * 2)
    r = cmd("import", "set/b.csv", "set/c.csv", "set/a.csv", "--order", order, "--fs", "100", "--block-len", "2",
            "--unit", "m/s2", "--out", "o.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    want = [f"{k}.csv" for k in taken]
    assert [s["source"] for s in sidecar(tmp_path / "o.bin")["snapshots"]] == want
    said = [ln.strip() for ln in (r.stdout + r.stderr).splitlines() if "order given" in ln]
    assert said == (["note: the files are taken in name order: a.csv before b.csv, not in the order given "
                     "(--order given keeps it)"] if order == "name" else []), r.stdout + r.stderr
    x = np.concatenate([level[n] * np.array([1.0, -1.0, 2.0, -2.0]) for n in want])
    assert_within_one_count(decode(tmp_path / "o.bin"), x[None])


def test_files_a_shell_pattern_expanded_are_taken_in_name_order_without_a_note(tmp_path):
    """The shell lists ``acc_*.csv`` by character (acc_10 before acc_2): name order puts them in
    their numbers' order, which the user meant, so nothing is said."""
    names = [f"acc_{k}.csv" for k in (1, 10, 2)]
    _snapshot_files(tmp_path / "set", names, dict.fromkeys(names, 0.1))
    r = cmd("import", *[f"set/{n}" for n in names], "--fs", "100", "--block-len", "2", "--unit", "m/s2",
            "--out", "o.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert [s["source"] for s in sidecar(tmp_path / "o.bin")["snapshots"]] == ["acc_1.csv", "acc_2.csv", "acc_10.csv"]
    assert "order given" not in r.stdout + r.stderr


@pytest.mark.parametrize("given, said", [
    (["set/B.csv", "set/a.csv"], "a.csv before B.csv"),                         # character order, not the shell's
    (["run2/data.csv", "run1/data.csv"], "run1/data.csv before run2/data.csv"),  # one name, two directories
])
def test_files_given_out_of_name_order_are_named_in_the_note(tmp_path, given, said):
    for path in given:
        (tmp_path / path).parent.mkdir(exist_ok=True)
        (tmp_path / path).write_text("0.1\n-0.1\n0.2\n-0.2\n")
    r = cmd("import", *given, "--fs", "100", "--block-len", "2", "--unit", "m/s2", "--out", "o.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    notes = [ln.strip() for ln in (r.stdout + r.stderr).splitlines() if "order given" in ln]
    assert notes == [f"note: the files are taken in name order: {said}, not in the order given (--order given "
                     "keeps it)"], r.stdout + r.stderr


def test_given_order_takes_sources_in_turn_a_directorys_files_in_name_order(tmp_path):
    """`--order given` with a directory and then a pattern: the pattern's files after the
    directory's, the files of each in natural name order (not the order the file system lists
    them in)."""
    names = {d: [f"{d}_{k}.csv" for k in (5, 12, 1, 30, 2, 7)] for d in ("late", "early")}
    for d, files in names.items():
        _snapshot_files(tmp_path / d, files, dict.fromkeys(files, 0.1))
    r = cmd("import", "late", "early/*.csv", "--order", "given", "--fs", "100", "--block-len", "2", "--unit", "m/s2",
            "--out", "o.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert [s["source"] for s in sidecar(tmp_path / "o.bin")["snapshots"]] == [
        f"{d}_{k}.csv" for d in ("late", "early") for k in (1, 2, 5, 7, 12, 30)]

def _snapshot_dir(d: Path) -> None:
    """Two snapshot files as the XJTU-SY bearing set writes them, 1.csv and 2.csv."""
    d.mkdir()
    for k in (1, 2):
        rows = "".join(f"{v:.4f},{v / 2:.4f}\n" for v in np.sin(np.arange(1000) / 50 + k))
        (d / f"{k}.csv").write_text("Horizontal_vibration_signals,Vertical_vibration_signals\n" + rows)


@pytest.mark.parametrize("summary, what", [
    ("file,rms\n1,0.1\n2,0.2\n3,0.3\n",
     "other columns (file, rms) than 1.csv (Horizontal_vibration_signals, Vertical_vibration_signals)"),
    ("file,rms,peak\n1,0.1,1\n2,0.2,2\n3,0.3,3\n",
     "3 columns (file, rms, peak) where 1.csv has 2 (Horizontal_vibration_signals, Vertical_vibration_signals)"),
])
def test_a_file_of_another_layout_in_a_directory_is_named_with_how_to_leave_it_out(tmp_path, summary, what):
    """A dataset's summary.csv beside its snapshots: the error says which columns differ and a
    --glob pattern that leaves the file out, and that pattern imports the snapshots."""
    _snapshot_dir(tmp_path / "mix4")
    (tmp_path / "mix4" / "summary.csv").write_text(summary)
    r = cmd("import", "mix4", "--fs", "1000", "--out", "o.bin", cwd=tmp_path)
    assert (r.returncode, r.stderr) == (2, f"cmsensord import: mix4/summary.csv: {what}; every snapshot file must "
                                           "have the same layout: leave it out (move it away, or import --glob "
                                           "'mix4/[0-9]*.csv' instead)\n")
    r = cmd("import", "--glob", "mix4/[0-9]*.csv", "--fs", "1000", "--out", "o.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert [s["source"] for s in sidecar(tmp_path / "o.bin")["snapshots"]] == ["1.csv", "2.csv"]


def test_files_of_another_type_in_a_directory_are_left_out_with_a_note(tmp_path):
    """A README.txt and a README.md beside the .csv snapshots are named in a note (a hidden
    file is not)."""
    _snapshot_dir(tmp_path / "set")
    (tmp_path / "set" / "README.txt").write_text("The dataset's description.\n")
    (tmp_path / "set" / "README.md").write_text("# The dataset\n")
    (tmp_path / "set" / ".DS_Store").write_bytes(b"\0\1")
    r = cmd("import", "set", "--fs", "1000", "--out", "o.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    note = "set: took the 2 .csv file(s); left out 2 of another type (README.md, README.txt)"
    assert f"  note: {note}\n" in r.stderr and note in sidecar(tmp_path / "o.bin")["notes"]
    assert [s["source"] for s in sidecar(tmp_path / "o.bin")["snapshots"]] == ["1.csv", "2.csv"]


#: how the tests import :func:`run_to_failure`'s files
R2F = ("--fs", "2560", "--block-len", "32", "--unit", "g", "--names", "bearing", "--rpm", "1800")


def run_to_failure(tmp_path: Path) -> Path:
    """40 one-second snapshots at 2560 Hz, one every 10 minutes, named by time: quiet for 28,
    then louder and rougher each time (imported in 32-sample blocks: each snapshot is one
    board second)."""
    d = tmp_path / "r2f"
    d.mkdir()
    rng = np.random.default_rng(11)
    t = np.arange(2560) / 2560
    for k in range(40):
        grow = max(0, k - 27)
        x = 0.05 * rng.standard_normal(2560) + 0.05 * np.sin(2 * np.pi * 30 * t) \
            + 0.03 * grow * rng.standard_normal(2560) * (np.sin(2 * np.pi * 97 * t) > 0.9)
        stamp = 1_076_582_400 + 600 * k        # 2004-02-12 10:40:00 UTC
        name = time.strftime("%Y.%m.%d.%H.%M.%S", time.gmtime(stamp))
        np.savetxt(d / name, x[:, None], fmt="%.4f")
    return d


@pytest.mark.parametrize("times", ["names", "interval"])
def test_replay_says_where_in_the_recording_each_severity_level_was_first_reached(tmp_path, times):
    d = run_to_failure(tmp_path)
    more = ["--snapshot-interval", "600"] if times == "interval" else []
    r = cmd("import", d, *R2F, *more, "--out", "r.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = cmd("calibrate", "r.bin", "--to", "25%", "--out", "site.yaml", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    # 25 % of the 40 one-second snapshots: the first ten, to the end of the tenth
    last = "2004-02-12 12:10:01" if times == "names" else "1.5 h in"
    first = "2004-02-12 10:40:00" if times == "names" else "0 h in"
    assert (f"healthy period in the recording: 2004.02.12.10.40.00 (0.0 % of the record, {first}) to "
            f"the end of 2004.02.12.12.10.00 (25.0 % of the record, {last})\n") in r.stdout
    r = cmd("replay", "r.bin", "--config", "site.yaml", "--out", "logs", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    firsts = re.search(r"  bearing: \|.*\| [\d-]+ s; first (.*)\n", r.stderr)
    assert firsts, r.stderr
    reached = [(lv, float(t)) for lv, t in re.findall(r"([\d.]+) at (\d+) s", firsts[1])]
    assert [lv for lv, _ in reached] == ["0.1", "0.5", "1"]     # the recording does fail
    # a plain re-statement: the decision ending at board second t is snapshot t - 1 (1-s snapshots)
    at: dict[str, list[str]] = {}
    for lv, t in reached:
        k = int(t) - 1
        name = time.strftime("%Y.%m.%d.%H.%M.%S", time.gmtime(1_076_582_400 + 600 * k))
        when = f"{time.strftime('%Y-%m-%d %H:%M:%S', time.gmtime(1_076_582_400 + 600 * k))}" \
            if times == "names" else f"{600 * k / 3600:.4g} h in"
        at.setdefault(f"{name} ({100 * k / 40:.1f} % of the record, {when})", []).append(lv)
    line = "; ".join(f"{' and '.join(lvs)} at {where}" for where, lvs in at.items())
    assert f"  bearing: in the recording: {line}\n" in r.stderr
    assert reached[0][1] > 28       # not before the snapshots grow


def test_column_labels_become_channel_names_that_calibrate_and_the_topics_take(tmp_path):
    rng = np.random.default_rng(5)
    x = rng.normal(0.0, 1.0, (3000, 3))
    (tmp_path / "h.csv").write_text("Acc X (g),Acc-Y,Acc X g\n" + "\n".join(f"{a:.4f},{b:.4f},{c:.4f}"
                                                                          for a, b, c in x) + "\n")
    r = cmd("import", "h.csv", "--fs", "100", "--unit", "g", "--out", "h.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert ("  note: channel 'Acc X (g)' is named Acc_X_g (letters, digits and _ only: the MCAP topics "
            "/cm/Acc_X_g/...); --names sets other names\n") in r.stderr
    assert sidecar(tmp_path / "h.bin")["channel_names"] == ["Acc_X_g", "Acc_Y", "Acc_X_g_2"]
    r = cmd("calibrate", "h.bin", "--out", "site.yaml", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    site = yaml.safe_load((tmp_path / "site.yaml").read_text())
    assert [ch["name"] for ch in site["channels"]] == ["Acc_X_g", "Acc_Y", "Acc_X_g_2"]
    # a capture imported before: its sidecar's labels are made channel names the same way
    meta = sidecar(tmp_path / "h.bin")
    meta["channel_names"] = ["Acc X (g)", "Acc-Y", "Acc X g"]
    (tmp_path / "h.bin.json").write_text(json.dumps(meta))
    r = cmd("calibrate", "h.bin", "--out", "old.yaml", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "old.yaml").read_text() == (tmp_path / "site.yaml").read_text()


@pytest.mark.parametrize("names, message", [
    ("a b,c,d", "--names: 'a b' is not a channel name: letters, digits and _ only (the MCAP topics /cm/<name>/...)"),
    ("x,y,x", "--names: x given twice; every channel needs its own name"),
])
def test_names_that_are_not_channel_names_are_one_line_errors(tmp_path, names, message):
    (tmp_path / "h.csv").write_text("1,2,3\n4,5,6\n")
    r = cmd("import", "h.csv", "--fs", "100", "--names", names, "--out", "o.bin", cwd=tmp_path)
    assert (r.returncode, r.stdout, r.stderr) == (2, "", f"cmsensord import: {message}\n")
    assert not list(tmp_path.glob("o.bin*"))


MOTOR = """alarms:
  rules:
    - name: rms_trend
      indicator: accel_rms
      alert_x_baseline: 2.0
      danger_x_baseline: 4.0
      on_delay_s: 2
"""


def test_calibrate_learns_indicator_baselines_for_the_channels_named_at_import(tmp_path):
    """An import's channel names (not the board's ch0) carry the learned indicator baselines,
    so k x baseline alarms rise on the replay."""
    d = run_to_failure(tmp_path)
    (tmp_path / "motor.yaml").write_text(MOTOR)
    r = cmd("import", d, *R2F, "--out", "r.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = cmd("calibrate", "r.bin", "--to", "25%", "--config", "motor.yaml", "--out", "site.yaml", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    baselines = yaml.safe_load((tmp_path / "site.yaml").read_text())["alarms"]["baselines"]
    rms = [b for b in baselines if b["indicator"] == "accel_rms"]
    assert [b["channel"] for b in rms] == ["bearing"] and rms[0]["value"] > 0
    r = cmd("replay", "r.bin", "--config", "site.yaml", "--out", "logs", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert re.search(r"events: .*alarm_alert 1\b", r.stderr), r.stderr


def test_replay_says_where_in_the_recording_each_alarm_first_rose(tmp_path):
    d = run_to_failure(tmp_path)
    (tmp_path / "motor.yaml").write_text(MOTOR)
    assert cmd("import", d, *R2F, "--out", "r.bin", cwd=tmp_path).returncode == 0
    assert cmd("calibrate", "r.bin", "--to", "25%", "--config", "motor.yaml", "--out", "site.yaml",
               cwd=tmp_path).returncode == 0
    r = cmd("replay", "r.bin", "--config", "site.yaml", "--out", "logs", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    (log,) = (tmp_path / "logs").glob("*.mcap")
    msgs = read_messages(log)
    # board second 0 is 1 s before the first indicator record's stamp (its 1-s interval's end)
    t0 = next(stamp for topic, stamp, _ in msgs if topic == "/cm/bearing/indicators") - 1_000_000_000
    alerts = [stamp for topic, stamp, m in msgs if topic == "/cm/events" and m["kind"] == "alarm_alert"]
    assert alerts, r.stderr
    k = math.ceil((alerts[0] - t0) / 1e9) - 1          # the snapshot whose second ends there
    name = time.strftime("%Y.%m.%d.%H.%M.%S", time.gmtime(1_076_582_400 + 600 * k))
    clock = time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(1_076_582_400 + 600 * k))
    assert (f"  alarm rms_trend/bearing: in the recording: alert at {name} ({100 * k / 40:.1f} % of the "
            f"record, {clock})\n") in r.stderr


def test_names_given_stay_as_typed_in_calibrate_and_replay(tmp_path):
    """``--names x_,x``: each channel keeps its own name downstream (made names again, x_ was
    x and x became x_2: the topics of the two channels swapped)."""
    t = np.arange(20000) / 1000.0
    (tmp_path / "z.csv").write_text("".join(f"{2 * np.sin(30 * a):.5f},{np.sin(30 * a):.5f}\n" for a in t))
    r = cmd("import", "z.csv", "--fs", "1000", "--block-len", "10", "--names", "x_,x", "--out", "z.bin",
            cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = cmd("calibrate", "z.bin", "--out", "site.yaml", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert ("x: highest outlier count per decision on the healthy period at R_1: 0 against f_r 28.7 "
            "(no outlier at all); 0 healthy decision(s) would be flagged") in r.stdout     # a sine: none
    site = yaml.safe_load((tmp_path / "site.yaml").read_text())
    baselines = {ch["name"]: ch["baseline"] for ch in site["channels"]}
    assert list(baselines) == ["x_", "x"]
    assert baselines["x_"] == pytest.approx(2 * baselines["x"], rel=0.01)     # x_ is the louder one
    r = cmd("replay", "z.bin", "--config", "site.yaml", "--out", "logs", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    (log,) = (tmp_path / "logs").glob("*.mcap")
    assert {topic.split("/")[2] for topic, _, _ in read_messages(log) if topic.endswith("/severity")} == {"x_", "x"}
