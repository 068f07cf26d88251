"""`cmsensord import` of text tables whose rows carry the time of day (the PRONOSTIA rig's
files) or dates and times (loggers' exports): the rate from their steps, each snapshot's time,
and files whose times cannot be the snapshots'."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.test_import import G, assert_within_one_count, cmd, signal
from tests.test_import_text_tables import FS, imported


# --------------------------------------------------------------------------- time-of-day columns
def femto_like(d: Path, starts: list[tuple[int, int, int]], seed: int = 0) -> np.ndarray:
    """Snapshot files as the PRONOSTIA rig writes them: hour, minute, second, microsecond (5
    significant digits past 1e5: ``1.6527e+005``), then two accelerations in g; 2560 samples at
    25.6 kHz each, starting at ``starts``. Returns the accelerations (2, files x 2560)."""
    d.mkdir()
    x = signal(2560 * len(starts), 2, amp=0.5, seed=seed)
    for k, (h, m, s) in enumerate(starts):
        us = 65664 + np.arange(2560) * 1e6 / 25600
        rows = [f"{h},{m},{s},{float(f'{u:.5g}'):.5g}".replace("e+05", "e+005") + f",{a:.3f},{b:.3f}"
                for u, a, b in zip(us, x[0, k * 2560:(k + 1) * 2560], x[1, k * 2560:(k + 1) * 2560])]
        (d / f"acc_{k + 1:05d}.csv").write_text("\n".join(rows) + "\n")
    return x


def test_time_of_day_columns_give_the_rate_and_the_snapshot_times_past_midnight(tmp_path):
    x = femto_like(tmp_path / "b", [(23, 59, 45), (23, 59, 55), (0, 0, 5), (0, 10, 5)])
    cap, side, err = imported(tmp_path, "b", "--unit", "g", "--names", "horizontal,vertical")
    assert ("  note: columns 0-3 are the time of day (hour, minute, second, microsecond): 25600 Hz from "
            "their steps; they are not imported as channels\n") in err
    assert ("  note: snapshot times from the files' time-of-day columns: 23:59:45 to 00:10:05 (0.1722 h, past "
            "midnight); --snapshot-interval S sets them instead\n") in err
    assert side["fs"] == FS and side["channel_names"] == ["horizontal", "vertical"]
    times = [s["source_time_s"] for s in side["snapshots"]]
    assert times == pytest.approx([0.0, 10.0, 20.0, 620.0], abs=1e-6)
    assert_within_one_count(cap, np.round(x, 3) * G)
    # the interval given instead: the times it makes
    _, side, _ = imported(tmp_path, "b", "--unit", "g", "--snapshot-interval", "10")
    assert [s["source_time_s"] for s in side["snapshots"]] == [0.0, 10.0, 20.0, 30.0]


def test_the_rigs_own_files_import_without_options(tmp_path):
    """Three of the PRONOSTIA rig's own files (tests/data/femto_csv): 25600 Hz, two channels,
    the snapshot times of the rig's clock."""
    src = Path(__file__).parent / "data" / "femto_csv"
    _, side, err = imported(tmp_path, str(src), "--unit", "g")
    assert side["fs"] == FS and len(side["channel_names"]) == 2
    assert [s["source_time_s"] for s in side["snapshots"]] == pytest.approx([0.0, 10.0, 28020.0], abs=1e-6)
    assert "09:39:39 to 17:26:39 (7.783 h)" in err


def test_a_file_whose_clock_does_not_run_evenly_leaves_the_snapshots_without_times(tmp_path):
    """One file of three with its microseconds restarting half way: the rate and the channels
    stay those of the others, the snapshots get no times, and a note names the file."""
    x = femto_like(tmp_path / "b", [(9, 39, 39), (9, 39, 49), (9, 39, 59)])
    f = tmp_path / "b" / "acc_00002.csv"
    rows = f.read_text().splitlines()
    f.write_text("\n".join(rows[:1280] + [r.replace("9,39,49,", "9,39,50,", 1) for r in rows[1280:]]) + "\n")
    cap, side, err = imported(tmp_path, "b", "--unit", "g")
    assert ("  note: acc_00002.csv: no time of day that increases evenly, as the other files have: the "
            "snapshots have no times; --snapshot-interval S gives them\n") in err
    assert [s["source_time_s"] for s in side["snapshots"]] == [None, None, None]
    assert side["fs"] == FS and len(side["channel_names"]) == 2
    assert_within_one_count(cap, np.round(x, 3) * G)


@pytest.mark.parametrize("starts, said", [
    ([(10, 0, 0), (9, 0, 0), (11, 0, 0)], "acc_00002.csv: its time of day (09:00:00) is not after acc_00001.csv's "
                                          "(10:00:00), at 1 place(s)"),
    ([(10, 0, 0), (10, 0, 0), (10, 0, 0)], "acc_00002.csv: its time of day (10:00:00) is not after acc_00001.csv's "
                                           "(10:00:00), at 2 place(s)"),
])
def test_files_whose_times_do_not_increase_in_their_order_leave_the_snapshots_without_times(tmp_path, starts, said):
    """Files named in another order than their times, or a logger that stamps every file alike:
    no times (not gaps of -3602 s in the sidecar), and a note names the first such file."""
    femto_like(tmp_path / "b", starts)
    _, side, err = imported(tmp_path, "b", "--unit", "g")
    assert f"  note: {said}: the snapshots have no times; --snapshot-interval S gives them\n" in err
    assert [s["source_time_s"] for s in side["snapshots"]] == [None, None, None]
    assert "snapshot times from" not in err


# --------------------------------------------------------------------------- dates and times
def test_a_first_column_of_dates_and_times_gives_the_rate_and_the_recordings_date(tmp_path):
    """Three logger files of 3 s at 1 kHz, 10 minutes apart across midnight, each row stamped
    ``2023-05-01 23:50:00.001``: 1000 Hz, the snapshots' times and the recording's start."""
    d = tmp_path / "logs"
    d.mkdir()
    x = signal(9000, 2, amp=0.3)
    start = np.datetime64("2023-05-01T23:50:00.000")
    for k in range(3):
        stamps = start + np.timedelta64(600 * k, "s") + np.arange(3000) * np.timedelta64(1, "ms")
        rows = [f"{str(s).replace('T', ' ')},{a:.6f},{b:.6f}"
                for s, a, b in zip(stamps, x[0, 3000 * k:3000 * (k + 1)], x[1, 3000 * k:3000 * (k + 1)])]
        (d / f"log_{k}.csv").write_text("Timestamp,x,y\n" + "\n".join(rows) + "\n")
    cap, side, err = imported(tmp_path, "logs", "--unit", "g")
    assert ("  note: column 'Timestamp' (0) holds dates and times: 1000 Hz from their steps; it is not "
            "imported as a channel\n") in err
    assert ("  note: snapshot times from the files' dates and times: 2023-05-01 23:50:00 to 2023-05-02 "
            "00:10:00 (0.3333 h); --snapshot-interval S sets them instead\n") in err
    assert (side["fs"], side["channel_names"], side["source_start"]) == (1000, ["x", "y"], "2023-05-01T23:50:00")
    assert [s["source_time_s"] for s in side["snapshots"]] == [0.0, 600.0, 1200.0]
    assert_within_one_count(cap, np.round(x, 6) * G)
    # one file: when it starts, not a span of nothing
    _, side, err = imported(tmp_path, "logs/log_1.csv", "--unit", "g")
    assert "  note: the recording starts at 2023-05-02 00:00:00 (the file's dates and times)\n" in err
    assert "snapshot times from" not in err and side["source_start"] == "2023-05-02T00:00:00"


def test_a_row_whose_date_is_not_one_is_named_by_its_line(tmp_path):
    rows = [f"2023-05-01 12:00:0{i}.000,{i}" for i in range(5)]
    rows[3] = "2023-13-45 12:00:03.000,3"
    (tmp_path / "d.csv").write_text("# logger 7\ntime,x\n" + "\n".join(rows) + "\n")
    r = cmd("import", "d.csv", "--out", "o.bin", cwd=tmp_path)
    assert (r.returncode, r.stderr) == (2, "cmsensord import: d.csv: line 6, column 0: '2023-13-45 12:00:03.000' is "
                                           "not a date and time (separator ',', a header line); fix the file, or "
                                           "set --separator / --header / --no-header\n")
