"""`cmsensord import` of text tables as loggers write them. A time column (``Time (s),Acc X (g)``,
``t,x,y,z``, or a headerless first column of times) is the time base, gives the sampling rate when
evenly spaced and is no channel; unevenly spaced times ask for --fs in one line. Comments, blank
lines and a preamble of settings before the numbers are skipped (a preamble said once), and a
bad row is named by its line in the file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cmsensord.importing.table import Table
from cmsensord.importing.time_column import with_time_column
from tests.test_import import G, assert_within_one_count, cmd, decode, signal

FS = 25600


def write(path: Path, header: str | None, columns: list[np.ndarray], fmts: list[str], sep: str = ",") -> None:
    lines = [header] if header else []
    lines += [sep.join(f % v for f, v in zip(fmts, row)) for row in zip(*columns)]
    path.write_text("\n".join(lines) + "\n")


def imported(tmp_path: Path, name: str, *args: str) -> tuple[dict, dict, str]:
    """(decoded capture, sidecar, stderr) of ``cmsensord import NAME ARGS --out o.bin``."""
    r = cmd("import", name, *args, "--out", "o.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    return decode(tmp_path / "o.bin"), json.loads((tmp_path / "o.bin.json").read_text()), r.stderr


@pytest.mark.parametrize("label, scale, digits", [("Time (s)", 1.0, 6), ("time_ms", 1e3, 4), ("t [us]", 1e6, 1)])
def test_a_labelled_time_column_gives_the_rate_and_is_not_a_channel(tmp_path, label, scale, digits):
    """Times printed rounded (25.6 kHz at 6 decimals: steps of 39 and 40 us) still give the rate."""
    x = signal(FS, 2, amp=0.3)
    t = np.arange(FS) / FS * scale
    write(tmp_path / "daq.csv", f"{label},Acc X (g),Acc Y (g)", [t, x[0], x[1]], [f"%.{digits}f", "%.6f", "%.6f"])
    cap, side, err = imported(tmp_path, "daq.csv", "--unit", "g")
    note = f"column {label!r} (0) is the time base: 25600 Hz from its steps; it is not imported as a channel"
    assert f"  note: {note}\n" in err and note in side["notes"]
    assert (side["fs"], side["channel_names"]) == (FS, ["Acc_X_g", "Acc_Y_g"])
    assert_within_one_count(cap, np.round(x, 6) * G)


def test_a_headerless_first_column_of_even_times_is_the_time_base(tmp_path):
    x = signal(FS // 2, 3, amp=0.3)
    write(tmp_path / "scope.txt", None, [np.arange(FS // 2) / FS, *x], ["%.7f"] + ["%.6f"] * 3, sep=" ")
    cap, side, err = imported(tmp_path, "scope.txt", "--unit", "g")
    assert "note: column 'col0' (0) is the time base: 25600 Hz from its steps" in err
    assert side["channel_names"] == ["col1", "col2", "col3"]
    assert_within_one_count(cap, np.round(x, 6) * G)


def test_columns_that_are_not_times_stay_channels(tmp_path):
    """A column labelled t that does not increase (a temperature), and a headerless first column
    that is a signal: every column imported, no note of a time base."""
    x = signal(2560, 2, amp=0.3)
    write(tmp_path / "a.csv", "t,x", [20 + x[0], x[1]], ["%.6f", "%.6f"])
    write(tmp_path / "b.csv", None, [x[0], x[1]], ["%.6f", "%.6f"])
    for name in ("a.csv", "b.csv"):
        cap, side, err = imported(tmp_path, name, "--fs", "2560", "--unit", "g")
        assert "time base" not in err and len(side["channel_names"]) == 2


def test_uneven_times_ask_for_the_rate_in_one_line_and_take_it(tmp_path):
    t = np.arange(2560) / 2560
    t[1280:] += 0.5                                   # half a second missing in the middle
    write(tmp_path / "gap.csv", "t,x", [t, signal(2560, 1)[0]], ["%.6f", "%.6f"])
    r = cmd("import", "gap.csv", "--out", "o.bin", cwd=tmp_path)
    what = ("column 't' (0) is the time base, not evenly spaced (a step of 0.500391 s after row 1280, the "
            "median step 0.000391 s): it is not imported as a channel")
    assert (r.returncode, r.stderr) == (2, f"cmsensord import: gap.csv: the file does not say its sampling "
                                           f"rate: {what}; give --fs HZ\n")
    assert not list(tmp_path.glob("o.bin*"))
    _, side, err = imported(tmp_path, "gap.csv", "--fs", "2560")
    assert f"  note: {what}\n" in err and side["channel_names"] == ["x"]


def test_fs_given_against_the_time_column_is_noted(tmp_path):
    write(tmp_path / "d.csv", "time,x", [np.arange(1000) / 1000, signal(1000, 1)[0]], ["%.4f", "%.6f"])
    _, side, err = imported(tmp_path, "d.csv", "--fs", "1024")
    assert "note: fs 1024 Hz from --fs (the file says 1000 Hz)" in err and side["fs"] == 1024


@pytest.mark.parametrize("label", ["t", "Time", "TIME (s)", "time_s", "t[ms]", "Zeit [s]", "timestamp", "elapsed time",
                                   "Time Stamp", "time-stamp", "TimeStamp", "Time_Stamp [ms]"])
def test_labels_of_time(label):
    t = Table("f.csv", np.stack([np.arange(5.0), np.zeros(5)], axis=1)[None], [label, "x"])
    assert with_time_column(t, has_header=True).time_columns == (0,)


@pytest.mark.parametrize("label", ["temp", "tacho", "x", "t_x", "Time of flight", "ts_count", "Stamp", "time stamp id",
                                   "timestamped"])
def test_labels_that_are_not_time(label):
    t = Table("f.csv", np.stack([np.arange(5.0), np.zeros(5)], axis=1)[None], [label, "x"])
    assert with_time_column(t, has_header=True).time_columns == ()


@pytest.mark.parametrize("label", ["Time Stamp", "time-stamp", "TimeStamp"])
def test_a_time_stamp_column_spelt_with_a_space_or_hyphen_is_the_time_base(tmp_path, label):
    """KAIST's files and NI/Excel exports head their time column ``Time Stamp``: the rate from
    it, and no channel of it."""
    x = signal(FS, 1, amp=0.3)[0]
    write(tmp_path / "k.csv", f"{label},x_direction_housing_A", [np.arange(FS) / FS, x], ["%.7f", "%.6f"])
    cap, side, err = imported(tmp_path, "k.csv", "--unit", "g")
    assert (f"  note: column {label!r} (0) is the time base: 25600 Hz from its steps; it is not imported as a "
            "channel\n") in err
    assert (side["fs"], side["channel_names"]) == (FS, ["x_direction_housing_A"])
    assert_within_one_count(cap, np.round(x, 6)[None] * G)


@pytest.mark.parametrize("header", ["", "Unnamed: 0", "index", None])
def test_a_first_column_of_row_numbers_is_a_row_index_not_a_channel_nor_the_time_base(tmp_path, header):
    """pandas' to_csv writes the index first (its header cell empty, or ``Unnamed: 0`` once read
    and written again, or ``index``): not a channel of 1e5 m/s2 peaks, nor a time base of 1 Hz."""
    x = np.round(np.sin(np.arange(10000) / 50), 5)
    y = np.round(x / 2, 5)
    write(tmp_path / "p.csv", None if header is None else f"{header},x,y", [np.arange(10000), x, y],
          ["%d", "%.5f", "%.5f"])
    note = (f"column {header or 'col0'!r} (0) holds the row numbers 0, 1, 2, ...: a row index, not times; it is not "
            "imported as a channel")
    r = cmd("import", "p.csv", "--unit", "g", "--out", "o.bin", cwd=tmp_path)
    assert (r.returncode, r.stderr) == (2, f"cmsensord import: p.csv: the file does not say its sampling rate: "
                                           f"{note}; give --fs HZ\n")
    cap, side, err = imported(tmp_path, "p.csv", "--fs", "10000", "--unit", "g")
    assert f"  note: {note}\n" in err and note in side["notes"]
    assert side["channel_names"] == (["x", "y"] if header is not None else ["col1", "col2"])
    assert_within_one_count(cap, np.stack([x, y]) * G)


def test_a_row_index_beside_a_time_column_and_a_time_column_of_whole_seconds(tmp_path):
    """An index from 1 before a time column: both left out, the rate from the times. A column
    labelled time that holds 0, 1, 2, ... is times (1 Hz), not an index."""
    x = np.round(signal(2000, 1, amp=0.3)[0], 6)
    write(tmp_path / "i.csv", "Unnamed: 0,time,x", [np.arange(1, 2001), np.arange(2000) / 1000, x],
          ["%d", "%.4f", "%.6f"])
    cap, side, err = imported(tmp_path, "i.csv", "--unit", "g")
    assert ("  note: column 'Unnamed: 0' (0) holds the row numbers 1, 2, 3, ...: a row index, not times; it is not "
            "imported as a channel\n") in err
    assert ("  note: column 'time' (1) is the time base: 1000 Hz from its steps; it is not imported as a "
            "channel\n") in err
    assert (side["fs"], side["channel_names"]) == (1000, ["x"])
    assert_within_one_count(cap, x[None] * G)
    write(tmp_path / "s.csv", "time,x", [np.arange(2000), x], ["%d", "%.6f"])
    _, side, err = imported(tmp_path, "s.csv", "--unit", "g", "--block-len", "1")
    assert "  note: column 'time' (0) is the time base: 1 Hz from its steps; it is not imported as a channel\n" in err
    assert (side["fs"], side["channel_names"]) == (1, ["x"])


# --------------------------------------------------------------------------- lines before the numbers
def test_comments_and_blank_lines_before_a_header_are_skipped(tmp_path):
    """`#` lines and blank lines before the column names: the names and every row are read, and
    a note says the comments were skipped."""
    x = signal(2000, 1, amp=0.3)[0]
    write(tmp_path / "c.csv", "# exported by the logger\n# fs = 2000\n\ntime,acc", [np.arange(2000) / 2000, x],
          ["%.4f", "%.6f"])
    cap, side, err = imported(tmp_path, "c.csv", "--unit", "g")
    note = "c.csv: 2 line(s) before the column names skipped (the first: '# exported by the logger')"
    assert side["channel_names"] == ["acc"] and f"  note: {note}\n" in err and note in side["notes"]
    assert_within_one_count(cap, np.round(x, 6)[None] * G)


@pytest.mark.parametrize("mark", ["#", "%"])
def test_comment_lines_before_headerless_numbers_get_the_note_a_preamble_gets(tmp_path, mark):
    """`#` lines are said as `%` lines (a MATLAB export's) are, among the preamble's lines."""
    x = np.round(signal(1000, 2, amp=0.3), 6)
    lines = f"{mark} recorded 2024-03-05\nrig: 3 of 4\n{mark} fs 1000"
    write(tmp_path / "m.txt", lines, [x[0], x[1]], ["%.6f", "%.6f"], sep=" ")
    cap, side, err = imported(tmp_path, "m.txt", "--fs", "1000", "--unit", "g")
    note = f"m.txt: 3 line(s) before the numbers skipped (the first: '{mark} recorded 2024-03-05')"
    assert f"  note: {note}\n" in err and note in side["notes"]
    assert_within_one_count(cap, x * G)


@pytest.mark.parametrize("suffix", [".txt", ".lvm", ""])
def test_a_preamble_of_settings_before_the_numbers_is_skipped_and_said_once(tmp_path, suffix):
    """A LabVIEW text file (.lvm; or named .txt, or without an extension): settings (12 lines that
    are not blank), its line of names with the Comment column the rows leave out, then times
    (X_Value: the time base) and values; two such files in a directory say so once."""
    pre = ("LabVIEW Measurement\nWriter_Version\t2\nReader_Version\t2\nSeparator\tTab\nDecimal_Separator\t.\n"
           "***End_of_Header***\n\nChannels\t1\nSamples\t2000\nX_Dimension\tTime\nX0\t0\nDelta_X\t0.0005\n"
           "***End_of_Header***\nX_Value\tAcc\tComment")
    d = tmp_path / "runs"
    d.mkdir()
    xs = [signal(2000, 1, amp=0.3, seed=k)[0] for k in range(2)]
    for k, x in enumerate(xs):
        write(d / f"run_{k}{suffix}", pre, [np.arange(2000) / 2000, x], ["%.6f", "%.6f"], sep="\t")
    cap, side, err = imported(tmp_path, "runs", "--unit", "g", "--snapshot-interval", "60")
    note = f"run_0{suffix}: 12 line(s) before the column names skipped (the first: 'LabVIEW Measurement')"
    assert err.count("skipped") == 1 and f"  note: {note}\n" in err and note in side["notes"]
    assert side["fs"] == 2000 and side["channel_names"] == ["Acc"]
    assert ("  note: column 'X_Value' (0) is the time base: 2000 Hz from its steps; it is not imported as a "
            "channel\n") in err
    assert_within_one_count(cap, np.round(np.concatenate(xs), 6)[None] * G)


@pytest.mark.parametrize("dates, start", [
    (["Date\t2024/03/05\nTime\t10:15:02.1234567890", "Date\t2024/03/05\nTime\t10:25:02,1234567890"],
     "2024-03-05T10:15:02.123457"),
    (["Start Time: 2024-03-05 23:55:00", "Start Time: 2024-03-06 00:05:00.5"], "2024-03-05T23:55:00"),
])
def test_the_date_and_time_a_preamble_gives_is_each_files_snapshot_time(tmp_path, dates, start):
    """LabVIEW's Date and Time lines (a decimal comma too), or one line of another logger's,
    date each file's snapshot: the sidecar's times and the recording's start."""
    d = tmp_path / "runs"
    d.mkdir()
    for k, when in enumerate(dates):
        pre = f"LabVIEW Measurement\nSeparator\tTab\n{when}\n***End_of_Header***\nX_Value\tAcc\tComment"
        write(d / f"run_{k}.lvm", pre, [np.arange(2000) / 2000, signal(2000, 1, seed=k)[0]], ["%.6f", "%.6f"], sep="\t")
    _, side, err = imported(tmp_path, "runs", "--unit", "g")
    assert side["source_start"] == start
    times = [s["source_time_s"] for s in side["snapshots"]]
    assert times[0] == 0.0 and times[1] == pytest.approx(600.0 + (0.5 if "Start" in dates[1] else 0.0), abs=1e-6)
    assert "  note: snapshot times from the files' dates and times: " in err


def test_a_preamble_without_a_whole_date_and_time_dates_nothing(tmp_path):
    for name, pre in (("a.lvm", "Date\t2024/13/05\nTime\t10:15:02"), ("b.lvm", "Time\t10:15:02"),
                      ("c.lvm", "Start Time: soon")):
        write(tmp_path / name, f"LabVIEW Measurement\n{pre}\nX_Value\tAcc", [np.arange(200) / 200, np.zeros(200)],
              ["%.6f", "%.6f"], sep="\t")
        _, side, _ = imported(tmp_path, name)
        assert side["source_start"] is None and side["snapshots"][0]["source_time_s"] is None, name


def test_a_bad_row_is_named_by_its_line_in_the_file(tmp_path):
    """Line numbers count the preamble, the comments and the header (the file's own lines)."""
    (tmp_path / "b.csv").write_text("# a comment\nsettings: none\nt,x\n0,1\n1,2\n2,3\n3,oops\n")
    r = cmd("import", "b.csv", "--fs", "10", "--out", "o.bin", cwd=tmp_path)
    assert (r.returncode, r.stderr) == (2, "cmsensord import: b.csv: line 7, column 1: 'oops' is not a number "
                                           "(separator ',', a header line); fix the file, or set --separator / "
                                           "--header / --no-header\n")


@pytest.mark.parametrize("bom, encoding", [(b"\xff\xfe", "utf-16-le"), (b"\xfe\xff", "utf-16-be")])
def test_utf16_text_as_excel_saves_unicode_text_is_read(tmp_path, bom, encoding):
    """Excel's "Unicode Text": UTF-16 after a byte order mark, tab-separated, CRLF line ends;
    the same capture when read a chunk of lines at a time."""
    x = np.round(signal(2000, 2, amp=0.3), 6)
    rows = "".join(f"{i / 2000:.4f}\t{a:.6f}\t{b:.6f}\r\n" for i, (a, b) in enumerate(x.T))
    (tmp_path / "u.txt").write_bytes(bom + f"Time (s)\tAcc X (g)\tAcc Y (g)\r\n{rows}".encode(encoding))
    cap, side, err = imported(tmp_path, "u.txt")
    assert (side["fs"], side["channel_names"], side["source_unit"]) == (2000, ["Acc_X_g", "Acc_Y_g"], "g")
    assert ("  note: column 'Time (s)' (0) is the time base: 2000 Hz from its steps; it is not imported as a "
            "channel\n") in err
    assert_within_one_count(cap, x * G)
    r = cmd("import", "u.txt", "--memory-mb", "0.01", "--out", "long.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "long.bin").read_bytes() == (tmp_path / "o.bin").read_bytes()


@pytest.mark.parametrize("name, text, args, message", [
    ("one.csv", "2023-05-01 12:00:00.000,1,2\n", (),
     "one.csv: the file does not say its sampling rate: column 'col0' (0) holds dates and times, not evenly "
     "spaced (a single row): it is not imported as a channel; give --fs HZ"),
    ("nan.csv", "x,rpm\n" + "".join(f"{i % 7},{'nan' if i == 5 else 1500}\n" for i in range(100)),
     ("--fs", "1000", "--speed-column", "rpm"),
     "nan.csv: column 'rpm' (--speed-column) has 1 missing or non-finite value(s) (first at sample 5); clean the file"),
    ("fast.csv", "x,rpm\n" + "".join(f"{i % 7},{90000 if i == 50 else 1500}\n" for i in range(100)),
     ("--fs", "1000", "--speed-column", "rpm", "--ppr", "2"),
     "fast.csv: speed column 'rpm' reaches 90000 rpm, more than one tacho edge a sample at 2 a revolution (at "
     "most 30000 rpm at 1000 Hz); check the column's unit and --ppr"),
    ("names.csv", "# logger\ntime,x\n", ("--fs", "10"), "names.csv: a header but no rows of numbers"),
])
def test_hostile_text_tables_are_one_line(tmp_path, name, text, args, message):
    """Found by feeding the import random tables: each was a traceback or more than one line."""
    (tmp_path / name).write_text(text)
    r = cmd("import", name, *args, "--out", "o.bin", cwd=tmp_path)
    assert (r.returncode, r.stdout, r.stderr) == (2, "", f"cmsensord import: {message}\n")
    assert not list(tmp_path.glob("o.bin*"))


def _with_gaps(tmp_path: Path) -> tuple[Path, np.ndarray]:
    """A logger's CSV with a NaN, an inf and an empty cell in channel a and a NaN in b (blocks 50,
    70, 90 of 100 samples at 10 kHz): the file and its samples (NaN where missing)."""
    x = np.round(np.random.default_rng(3).standard_normal((20000, 2)), 4)
    cells = [[f"{v:.4f}" for v in row] for row in x]
    for (i, c), text in {(5000, 0): "NaN", (7003, 0): "inf", (7050, 1): "nan", (9099, 0): ""}.items():
        cells[i][c], x[i, c] = text, np.nan
    rows = [f"{i / 10000:.4f},{a},{b}\n" for i, (a, b) in enumerate(cells)]
    (tmp_path / "gaps.csv").write_text("t,a,b\n" + "".join(rows))
    return tmp_path / "gaps.csv", x


def test_missing_values_leave_their_blocks_out_as_frames_the_board_lost(tmp_path):
    """NaN, inf and empty cells are not an error: each channel's block that holds one is not
    sent (its seq skipped), the other samples go through unchanged, and a replay counts the
    lost frames and the missing observations."""
    path, x = _with_gaps(tmp_path)
    r = cmd("import", path, "--unit", "g", "--out", "g.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert ("  note: gaps.csv: 4 missing value(s) (NaN, inf or empty cells) in a (3), b (1), the first at sample "
            "5000: the blocks that hold them are left out of the capture, as frames the board lost (a replay "
            "counts their observations missing)\n") in r.stderr
    assert "peak" in r.stderr and ", 3 block(s) left out for missing samples\n" in r.stderr
    meta = json.loads((tmp_path / "g.bin.json").read_text())
    assert meta["missing_blocks"] == [3, 1] and meta["clipped_blocks"] == [0, 0]
    from cmsensord.protocol import FrameType, iter_frames

    frames, counters = iter_frames((tmp_path / "g.bin").read_bytes())
    assert counters.frames_lost == 4 and counters.crc_failures == 0
    sent = {(f.chan, f.t0_unwrapped // 100) for f in frames if f.type == FrameType.RAW}
    assert {(c, b) for c in (0, 1) for b in range(200)} - sent == {(0, 50), (0, 70), (1, 70), (0, 90)}
    kept = np.ones(20000, dtype=bool)
    for b in (50, 70, 90):
        kept[b * 100:(b + 1) * 100] = False
    got = decode_lossy(tmp_path / "g.bin")
    back = got[0] + meta["dc_removed"][0]          # with the mean the import took out
    assert_within_one_count({"x": back[None, :], "status": got[1]}, x[kept, 0][None, :] * G)
    r = cmd("replay", "g.bin", "--out", "logs", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "(396 observations, 4 missing, 4 frames lost)" in r.stderr
    r = cmd("import", path, "--unit", "g", "--memory-mb", "0.1", "--out", "long.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr                  # read a stretch of lines at a time: the same
    assert (tmp_path / "long.bin").read_bytes() == (tmp_path / "g.bin").read_bytes()


def decode_lossy(path: Path):
    """Channel 0's samples in the frames sent (the blocks left out skipped), and the STATUS."""
    from cmsensord.protocol import FrameType, decode_raw, decode_status, iter_frames

    frames, _ = iter_frames(path.read_bytes())
    status = decode_status(next(f for f in frames if f.type == FrameType.STATUS).payload)
    counts = np.concatenate([decode_raw(f.payload) for f in frames if f.type == FrameType.RAW and f.chan == 0])
    return (counts - status.offset[0]) * status.scale[0], status


def test_in_rms_mode_a_missing_value_leaves_the_blocks_rms_frame_out(tmp_path):
    path, _ = _with_gaps(tmp_path)
    r = cmd("import", path, "--unit", "g", "--mode", "rms", "--out", "g.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    meta = json.loads((tmp_path / "g.bin.json").read_text())
    assert meta["missing_blocks"] == [3, 3]               # block 70 of both: one frame holds every channel
    from cmsensord.protocol import FrameType, iter_frames

    frames, counters = iter_frames((tmp_path / "g.bin").read_bytes())
    assert counters.frames_lost == 3
    assert sorted({f.t0_unwrapped // 100 for f in frames if f.type == FrameType.RMS} ^ set(range(200))) == [50, 70, 90]


def _ims_dir(tmp_path: Path) -> Path:
    """Four IMS-like snapshot files (tab-separated, 2048 rows of four channels) named by time."""
    d = tmp_path / "rig"
    d.mkdir()
    rng = np.random.default_rng(8)
    for k in range(4):
        np.savetxt(d / f"2004.02.12.10.{32 + 10 * k}.39", 0.1 * rng.standard_normal((2048, 4)), fmt="%.3f",
                   delimiter="\t")
    return d


@pytest.mark.parametrize("memory_mb", [None, "0.01"])
def test_a_file_whose_writing_stopped_mid_line_is_imported_up_to_its_last_whole_line(tmp_path, memory_mb):
    """The logger stopped while writing the third file: its last line holds 2 of 4 values and no
    line end. That line is left out with a note, and the short snapshot is pointed out; read
    whole or a stretch of lines at a time, the same capture."""
    d = _ims_dir(tmp_path)
    cut = d / "2004.02.12.10.52.39"
    text = cut.read_text()
    at = text.index("\t", text.index("\n", len(text) // 2)) + 3         # two values into a row
    cut.write_text(text[:at])
    whole = text[:at].count("\n")
    more = ("--memory-mb", memory_mb) if memory_mb else ()
    r = cmd("import", d, "--fs", 20480, "--unit", "g", "--block-len", 256, *more, "--out", "r.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert ("  note: 2004.02.12.10.52.39: its last line is cut short (2 of 4 values and no line end, as a file "
            "left when its writing stopped); the lines before it are imported\n") in r.stderr
    assert (f"  note: 1 snapshot(s) hold far fewer samples than most (2,048): 2004.02.12.10.52.39 ({whole:,}); "
            "files cut short?\n") in r.stderr
    meta = json.loads((tmp_path / "r.bin.json").read_text())
    assert [s["length"] + s["dropped"] for s in meta["snapshots"]] == [2048, 2048, whole, 2048]


def test_a_last_line_without_a_line_end_but_whole_is_a_row_like_the_others(tmp_path):
    d = _ims_dir(tmp_path)
    f = d / "2004.02.12.10.42.39"
    f.write_text(f.read_text().rstrip("\n"))
    r = cmd("import", d, "--fs", 20480, "--unit", "g", "--block-len", 256, "--out", "r.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "cut short" not in r.stderr
    assert [s["length"] for s in json.loads((tmp_path / "r.bin.json").read_text())["snapshots"]] == [2048] * 4


def test_a_row_cut_short_inside_the_file_is_still_an_error_naming_its_line(tmp_path):
    d = _ims_dir(tmp_path)
    f = d / "2004.02.12.10.42.39"
    lines = f.read_text().splitlines(keepends=True)
    lines[99] = "0.1\t0.2\n"
    f.write_text("".join(lines))
    r = cmd("import", d, "--fs", 20480, "--unit", "g", "--out", "r.bin", cwd=tmp_path)
    assert r.returncode == 2
    assert r.stderr.startswith(f"cmsensord import: {f}: line 100: 2 column(s) where the lines "
                               "before have 4")


def test_empty_files_in_a_directory_are_left_out_with_a_note(tmp_path):
    """A logger that stopped leaves an empty file named like the others (or a .csv): the other
    files are imported, and the note names it; the same capture as without it."""
    d = _ims_dir(tmp_path)
    r = cmd("import", d, "--fs", 20480, "--unit", "g", "--block-len", 256, "--out", "plain.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    (d / "2004.02.12.11.12.39").write_bytes(b"")
    (d / "2004.02.12.11.22.39.csv").write_bytes(b"")
    r = cmd("import", d, "--fs", 20480, "--unit", "g", "--block-len", 256, "--out", "r.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert f"  note: {d}: left out 2 empty file(s) (2004.02.12.11.12.39, 2004.02.12.11.22.39.csv)\n" in r.stderr
    assert (tmp_path / "r.bin").read_bytes() == (tmp_path / "plain.bin").read_bytes()


def _logger_text(x: np.ndarray, head: str, sep: str = "\t", end: str = "") -> str:
    """``head`` then a time column at 5 kHz and ``x``'s columns, each line ending with ``end``."""
    return head + "".join(f"{i / 5000:.5f}{sep}" + sep.join(f"{v:.4f}" for v in row) + f"{end}\n"
                          for i, row in enumerate(x))


def test_a_units_line_under_the_column_names_names_their_units(tmp_path):
    """catman, DIAdem and the like write a line of units under the column names: the names
    are the line above it, with their units, so 'Time' in s is the time base."""
    x = np.round(np.random.default_rng(9).standard_normal((5000, 2)), 4)
    (tmp_path / "units.txt").write_text(_logger_text(x, "Test rig 3\nTime\tAcc X\tAcc Y\ns\t[g]\t[g]\n"))
    (tmp_path / "plain.txt").write_text(_logger_text(x, "Time (s)\tAcc X (g)\tAcc Y (g)\n"))
    r = cmd("import", "units.txt", "--unit", "g", "--out", "u.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert ("  note: units.txt: the line under the column names gives their units: Time (s), Acc X (g), "
            "Acc Y (g)\n") in r.stderr
    assert "  note: units.txt: 1 line(s) before the column names skipped (the first: 'Test rig 3')\n" in r.stderr
    assert "  note: column 'Time (s)' (0) is the time base: 5000 Hz from its steps" in r.stderr
    assert cmd("import", "plain.txt", "--unit", "g", "--out", "p.bin", cwd=tmp_path).returncode == 0
    assert (tmp_path / "u.bin").read_bytes() == (tmp_path / "p.bin").read_bytes()
    meta = json.loads((tmp_path / "u.bin.json").read_text())
    assert meta["channel_names"] == ["Acc_X_g", "Acc_Y_g"] and meta["fs"] == 5000


def test_lines_that_end_with_the_separator_have_no_empty_last_column(tmp_path):
    x = np.round(np.random.default_rng(10).standard_normal((5000, 2)), 4)
    (tmp_path / "trail.csv").write_text(_logger_text(x, "t,a,b,\n", ",", ","))
    (tmp_path / "plain.csv").write_text(_logger_text(x, "t,a,b\n", ","))
    said = []
    for name in ("trail", "plain"):
        r = cmd("import", f"{name}.csv", "--unit", "g", "--out", f"{name}.bin", cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        said.append(r.stderr)
    assert "missing" not in said[0] and "2 channel(s)" in said[0]
    assert (tmp_path / "trail.bin").read_bytes() == (tmp_path / "plain.bin").read_bytes()


def test_without_unit_the_files_own_unit_is_taken_and_a_different_unit_given_is_pointed_out(tmp_path):
    """The units line (or the names: 'Acc X (g)') says g: without --unit the values are g, not
    m/s2 (9.81 x too small before); with another --unit the user's choice stands, with a note."""
    x = np.round(np.random.default_rng(11).standard_normal((5000, 2)), 4)
    (tmp_path / "units.txt").write_text(_logger_text(x, "Time\tAcc X\tAcc Y\ns\tg\tg\n"))
    r = cmd("import", "units.txt", "--out", "auto.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "  note: unit g from the file (Acc X (g), Acc Y (g)); --unit sets another\n" in r.stderr
    assert cmd("import", "units.txt", "--unit", "g", "--out", "g.bin", cwd=tmp_path).returncode == 0
    assert (tmp_path / "auto.bin").read_bytes() == (tmp_path / "g.bin").read_bytes()
    assert json.loads((tmp_path / "auto.bin.json").read_text())["source_unit"] == "g"
    r = cmd("import", "units.txt", "--unit", "m/s2", "--out", "ms2.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert ("  note: --unit m/s2 given, but the file says g (Acc X (g), Acc Y (g)): the values are taken as m/s2; "
            "check --unit\n") in r.stderr
    assert json.loads((tmp_path / "ms2.bin.json").read_text())["source_unit"] == "m/s2"
    (tmp_path / "plain.csv").write_text(_logger_text(x, "t,a,b\n", ","))
    r = cmd("import", "plain.csv", "--out", "plain.bin", cwd=tmp_path)     # nothing said: m/s2, as before
    assert r.returncode == 0 and f"  note: {_ASSUMED}\n" in r.stderr
    assert "unit" not in r.stderr.replace(_ASSUMED, "").replace("--unit", "")
    assert json.loads((tmp_path / "plain.bin.json").read_text())["source_unit"] == "m/s2"


#: the note of an import whose file says no unit and no --unit given
_ASSUMED = "unit m/s2 assumed: the file does not say its unit; give --unit (g, mg, m/s2, mm/s2, V, Pa)"


def test_without_unit_a_file_that_says_none_is_taken_as_ms2_with_a_note(tmp_path):
    """A file in g imported without --unit would show peaks 9.8 x too small: the import says
    which unit it took and how to give another; with --unit, or a unit in the file, it does not."""
    x = np.round(np.random.default_rng(13).standard_normal((5000, 2)), 4)
    (tmp_path / "plain.csv").write_text(_logger_text(x, "t,a,b\n", ","))
    r = cmd("import", "plain.csv", "--out", "plain.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert f"  note: {_ASSUMED}\n" in r.stderr
    assert _ASSUMED in json.loads((tmp_path / "plain.bin.json").read_text())["notes"]
    r = cmd("import", "plain.csv", "--unit", "m/s2", "--out", "given.bin", cwd=tmp_path)
    assert r.returncode == 0 and "assumed" not in r.stderr, r.stderr
    assert (tmp_path / "plain.bin").read_bytes() == (tmp_path / "given.bin").read_bytes()


def test_a_file_in_volts_without_a_sensitivity_is_one_line_naming_what_the_file_says(tmp_path):
    x = np.round(np.random.default_rng(12).standard_normal((5000, 1)), 4)
    (tmp_path / "volts.txt").write_text(_logger_text(x, "Time\tAccel\ns\tV\n"))
    r = cmd("import", "volts.txt", "--out", "v.bin", cwd=tmp_path)
    assert (r.returncode, r.stderr) == (2, "cmsensord import: volts.txt: the file gives its columns in V (Accel (V)): "
                                           "add the accelerometer's --sensitivity MV_PER_G (e.g. 100), or --unit for "
                                           "another\n")
    r = cmd("import", "volts.txt", "--sensitivity", "100", "--out", "v.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "v.bin.json").read_text())["source_unit"] == "V"
