"""``cmsensord report`` of a replayed import: drawn over the recording's own time (its date and
time from the file names, or hours into it), gaps between snapshots included; the timeline the
replay writes into the log; logs of different recordings drawn apart, each over its own time."""

from __future__ import annotations

import calendar
import html
import json
import re
import time
from pathlib import Path

import numpy as np
import pytest

from cmsensord.importing.timeline import Timeline
from cmsensord.report.fast_read import head_metadata
from processes import cmsensord, run_module
from tests.test_import_names import R2F, run_to_failure

pytest.importorskip("matplotlib", reason="the report extra")

START = 1_076_582_400          # the first snapshot's name: 2004-02-12 10:40:00; one every 600 s
#: a run's identity in its files' metadata (its UTC start, 8 random hex digits)
RUN = r"\d{8}T\d{6}Z-[0-9a-f]{8}"


def clock(k: int, plus_s: int = 0) -> str:
    """Snapshot k's start (+ ``plus_s``) as the file names give it."""
    return time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(START + 600 * k + plus_s))


def replayed_import(tmp_path: Path, *more: str) -> tuple[Path, str]:
    """The run-to-failure recording imported (40 one-second snapshots, 10 minutes apart),
    calibrated on its first quarter and replayed: (log directory, the replay's stderr)."""
    d = run_to_failure(tmp_path)
    for args in (("import", str(d), *R2F, *more, "--out", "r.bin"),
                 ("calibrate", "r.bin", "--to", "25%", "--out", "site.yaml")):
        p = cmsensord(*args, cwd=tmp_path)
        assert p.returncode == 0, p.stderr
    p = cmsensord("replay", "r.bin", "--config", "site.yaml", "--out", "logs", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    return tmp_path / "logs", p.stderr


def report(tmp_path: Path, *logs: Path) -> tuple[str, dict[str, dict]]:
    out = tmp_path / "report.html"
    p = cmsensord("report", *map(str, logs), "--out", str(out), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    page = out.read_text(encoding="utf-8")
    metas = {m["id"]: m for m in json.loads(re.search(
        r'<script type="application/json" id="figures">(.*?)</script>', page, re.S).group(1))}
    return page, metas


def event_rows(page: str) -> list[tuple[str, str]]:
    return re.findall(r'<tr class="kind-([a-z_]+)"><td class="t">([^<]*)</td>', page)


def test_a_replayed_import_of_files_named_by_time_is_drawn_in_the_recording_time(tmp_path):
    logs, stderr = replayed_import(tmp_path)
    page, metas = report(tmp_path, logs)
    assert ("A replay of an imported recording: times are the recording's own date and time (from "
            "2004-02-12T10:40:00), gaps between its snapshots included.") in html.unescape(page)
    assert f"<title>cmsensord report {clock(0)[:16]} – {clock(39, 1)[:16]}</title>" in page
    sev = metas["bearing-severity"]["axes"][0]
    assert metas["bearing-severity"]["axes"][-1]["xlabel"] == "recording time (from the import)"
    # one decision a board second, each the end of one snapshot: the first and the last of them
    assert sev["xlim_local"][0] in {clock(k, 1).replace(" ", "T") for k in range(3)}
    assert sev["xlim_local"][1] == clock(39, 1).replace(" ", "T")
    # each severity level's first decision: the end of the snapshot the replay names
    line = re.search(r"  bearing: in the recording: (.*)\n", stderr)[1]
    placed = re.findall(r"([\d.]+(?: and [\d.]+)*) at \S+ \([\d.]+ % of the record, ([\d-]+ [\d:]+)\)", line)
    assert " and ".join(levels for levels, _ in placed).split(" and ") == ["0.1", "0.5", "1"]
    changes = [t for kind, t in event_rows(page) if kind == "severity_change"]
    for _, start in placed:
        k = (calendar.timegm(time.strptime(start, "%Y-%m-%d %H:%M:%S")) - START) // 600
        assert f"{clock(k, 1)}.000" in changes, (start, changes)


def test_an_import_without_a_date_is_drawn_in_hours_into_the_recording(tmp_path):
    logs, _ = replayed_import(tmp_path, "--snapshot-interval", "600")
    page, metas = report(tmp_path, logs)
    assert "times are hours into the recording" in html.unescape(page)
    assert "<title>cmsensord report 0.000 h – 6.500 h</title>" in page
    for fid in ("bearing-severity", "bearing-indicators"):
        ax = metas[fid]["axes"][-1]
        assert ax["xlabel"] == "hours into the recording" and "xlim_local" not in ax
    lo, hi = metas["bearing-severity"]["axes"][0]["xlim"]
    assert 0 < lo < 0.4 and hi == pytest.approx(39 * 600 / 3600 + 1 / 3600)
    assert '<th>hours in</th>' in page
    assert all(re.fullmatch(r"\d\.\d{5} h", t) for _, t in event_rows(page))


def test_logs_of_an_import_and_of_a_board_are_drawn_apart_each_in_its_own_time(tmp_path):
    logs, _ = replayed_import(tmp_path)
    p = run_module("firmware_sim", "--scenario", "healthy", "--out", str(tmp_path / "sim.cap"),
                   "--duration", "5")
    assert p.returncode == 0, p.stderr
    p = cmsensord("replay", "sim.cap", "--out", "sim", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    page, metas = report(tmp_path, logs, tmp_path / "sim")
    assert ("these logs hold 2 different recordings, drawn apart, each over its own time: r.bin (1 file(s)), "
            "board logs (1 file(s)).") in html.unescape(page)
    assert "not all of one imported recording" not in page
    assert metas["r.bin-bearing-severity"]["axes"][-1]["xlabel"] == "recording time (from the import)"
    assert metas["board-logs-ch0-severity"]["axes"][-1]["xlabel"].startswith("local time (UTC")
    recording, board = page.split('<h2 class="recording" id="board-logs-recording">Logs of a board (no imported '
                                  'recording)</h2>')
    assert "<th>recording time</th>" in recording and "<th>local time</th>" in board


def test_the_replay_writes_the_timeline_and_stamps_board_zero_at_it(tmp_path):
    logs, _ = replayed_import(tmp_path)
    (log,) = logs.glob("*.mcap")
    timeline, zero = Timeline.from_json(head_metadata(log)["cmsensord"]["recording_timeline"])
    assert timeline.start_s.tolist() == [float(k) for k in range(40)]
    assert timeline.source_s.tolist() == [600.0 * k for k in range(40)]
    assert (timeline.source_start, timeline.repaired) == ("2004-02-12T10:40:00", 0)
    summary = json.loads(cmsensord("summary", "--json", str(log)).stdout)
    assert summary["end_ns"] - zero == pytest.approx(40e9, abs=0.05e9)   # the last decision: board 40 s


def sidecar(times: list[float | None], start: str | None = None) -> dict:
    return {"format": "cmsensord import", "source_start": start,
            "snapshots": [{"start_s": 0.5 * k, "source_time_s": t} for k, t in enumerate(times)]}


def test_board_seconds_to_recording_seconds_and_snapshot_times_that_go_back():
    tl = Timeline.from_sidecar(sidecar([0.0, 10.0, 20.0, 30.0], "2004-02-12T10:40:00"))
    assert tl is not None and tl.source_start == "2004-02-12T10:40:00"
    # inside a snapshot, on a start (the end of the one before), before the first, past the last
    np.testing.assert_allclose(tl.at([0.2, 0.5, 0.75, 1.5, -0.1, 9.0]), [0.2, 0.5, 10.25, 20.5, -0.1, 37.5])
    # FEMTO Bearing1_1's two snapshots stamped -52.2 s between 21190 and 21220 s
    tl = Timeline.from_sidecar(sidecar([21180.0, 21190.0, -52.2, -52.2, 21220.0]))
    assert tl is not None and tl.repaired == 2 and tl.source_start is None
    assert tl.source_s.tolist() == [21180.0, 21190.0, 21200.0, 21210.0, 21220.0]
    again, zero = Timeline.from_json(tl.to_json(123))
    assert zero == 123 and again.source_s.tolist() == tl.source_s.tolist() and again.repaired == 2


@pytest.mark.parametrize("meta", [{}, {**sidecar([0.0, 10.0]), "format": "something else"},
                                  sidecar([None, None])])
def test_no_timeline_but_of_an_import_with_its_length(meta):
    assert Timeline.from_sidecar(meta) is None


@pytest.mark.parametrize("times", [[None, None, None, None], [0.0, None, 20.0, 30.0], [100.0, 1.0, 2.0, 3.0]])
def test_snapshots_without_times_or_mostly_out_of_order_are_placed_by_their_share_of_the_record(times):
    tl = Timeline.from_sidecar({**sidecar(times), "board_seconds": 2.0})
    assert tl is not None and tl.unit == "%" and tl.span == 100.0
    np.testing.assert_allclose(tl.at([0.0, 0.5, 1.25, 2.0, 2.2]), [0.0, 25.0, 62.5, 100.0, 100.0])
    again, zero = Timeline.from_json(tl.to_json(7))
    assert (zero, again.unit, again.end_s) == (7, "%", 2.0)
    np.testing.assert_allclose(again.at([1.25]), [62.5])


def test_one_snapshot_without_a_time_is_a_continuous_recording_from_its_second_0():
    tl = Timeline.from_sidecar({**sidecar([None]), "board_seconds": 40.0})
    assert tl is not None and (tl.unit, tl.span) == ("s", 40.0)
    np.testing.assert_allclose(tl.at([0.0, 12.5, 40.0]), [0.0, 12.5, 40.0])


@pytest.mark.parametrize("text", ["", "{", "[]", '{"start_s":[0,1],"source_time_s":[0],"board_zero_ns":0}',
                                  '{"start_s":[0,1],"source_time_s":[0,"x"],"board_zero_ns":0}',
                                  '{"start_s":[0,NaN],"source_time_s":[0,1],"board_zero_ns":0}',
                                  '{"start_s":[1,0],"source_time_s":[0,1],"board_zero_ns":0}',
                                  '{"start_s":[0,1],"source_time_s":[0,1e300],"board_zero_ns":0}',
                                  '{"start_s":[0,1],"source_time_s":[0,1],"board_zero_ns":1e30}',
                                  '{"start_s":[0,1],"source_time_s":[0,1],"board_zero_ns":0,"unit":"min"}',
                                  '{"start_s":[0,1],"source_time_s":[0,1],"board_zero_ns":0,"unit":"%"}',
                                  '{"start_s":[0,1],"source_time_s":[0,1],"board_zero_ns":0,"end_s":-2}'])
def test_a_timeline_that_cannot_be_read_is_none(text):
    assert Timeline.from_json(text) is None


def test_the_replay_places_levels_in_snapshots_stamped_out_of_order_as_the_report_does(tmp_path):
    """The run-to-failure recording as one archive whose snapshots 28-36 carry a wrong time
    (-5 s, as two of FEMTO Bearing1_1's do): the replay's summary gives those snapshots the time
    between their neighbours (600 s apart), the report's timeline too."""
    d = run_to_failure(tmp_path)
    x = np.stack([np.loadtxt(f) for f in sorted(d.iterdir())])[:, :, None]      # (40, 2560, 1)
    t_s = 600.0 * np.arange(40)
    t_s[28:37] = -5.0
    np.savez(tmp_path / "r.npz", x=x, t_s=t_s)
    for args in (("import", "r.npz", "--array", "x", *R2F, "--out", "r.bin"),
                 ("calibrate", "r.bin", "--to", "25%", "--out", "site.yaml")):
        p = cmsensord(*args, cwd=tmp_path)
        assert p.returncode == 0, p.stderr
    p = cmsensord("replay", "r.bin", "--config", "site.yaml", "--out", "logs", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    line = re.search(r"  bearing: in the recording: (.*)\n", p.stderr)[1]
    placed = re.findall(r"r\.npz\[(\d+)\] \([\d.]+ % of the record, (-?[\d.]+) h in\)", line)
    assert placed and any(28 <= int(k) <= 36 for k, _ in placed), line
    for k, hours in placed:
        assert hours == f"{600 * int(k) / 3600:.4g}", line
    page, _ = report(tmp_path, tmp_path / "logs")
    assert "9 snapshot(s) whose recorded time went back are placed between their neighbours." in page


def test_the_summary_of_a_replayed_import_gives_each_event_its_time_in_the_recording(tmp_path):
    logs, _ = replayed_import(tmp_path)
    (log,) = logs.glob("*.mcap")
    p = cmsensord("summary", str(log), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    lines = p.stdout.splitlines()
    assert re.fullmatch(r"start: \S+ \(2004-02-12 10:40:0[01] in the recording\)", lines[[
        ln.startswith("start:") for ln in lines].index(True)])
    assert any(re.fullmatch(r"end: \S+ \(2004-02-12 17:10:01 in the recording\)", ln) for ln in lines)
    changes = [ln for ln in lines if " severity_change " in ln]
    assert changes and all(re.fullmatch(r"  \S+ \(2004-02-12 \d\d:\d0:01 in the recording\) severity_change .*", ln)
                           for ln in changes), changes
    assert [ln for ln in lines if re.fullmatch(re.escape(
        f"  cmsensord: {{'source': '{tmp_path.resolve() / 'r.bin'}', 'recording_timeline': '40 snapshots over 6.5 h "
        "of the recording "
        "from 2004-02-12T10:40:00', 'run': '") + RUN + "'}",
        ln)], lines
    assert lines[-1] == ("  healthy period (baselines): 0.0-10.0 board s of the capture, 2004-02-12 10:40:00 to "
                         "2004-02-12 12:10:01 in the recording (the site file's commissioned section)"), lines
    assert max(map(len, lines)) < 300                    # no 60-kB line of the timeline


def replayed(tmp_path: Path, source: str, *more: str) -> tuple[Path, str]:
    """``source`` imported as the run-to-failure recording is (``R2F``), calibrated on its first
    quarter and replayed: (log directory, the replay's stderr)."""
    for args in (("import", source, *R2F, *more, "--out", "r.bin"),
                 ("calibrate", "r.bin", "--to", "25%", "--out", "site.yaml"),
                 ("replay", "r.bin", "--config", "site.yaml", "--out", "logs")):
        p = cmsensord(*args, cwd=tmp_path)
        assert p.returncode == 0, p.stderr
    return tmp_path / "logs", p.stderr


def test_snapshots_without_times_are_drawn_in_percent_of_the_record_not_the_replays_clock(tmp_path):
    """The run-to-failure snapshots as files named 1.csv ... 40.csv (no times, as XJTU-SY's):
    the report, its events and `cmsensord summary` place them by their share of the record,
    where the replay's summary names each severity level's first snapshot."""
    d = run_to_failure(tmp_path)
    (tmp_path / "xj").mkdir()
    for k, f in enumerate(sorted(d.iterdir())):
        f.rename(tmp_path / "xj" / f"{k + 1}.csv")
    logs, stderr = replayed(tmp_path, "xj")
    page, metas = report(tmp_path, logs)
    assert ("A replay of an imported recording whose snapshots have no times: places are % of the "
            "record (the share of its recorded signal, snapshots end to end).") in html.unescape(page)
    assert "<title>cmsensord report 0.0 % – 100.0 %</title>" in page
    sev = metas["bearing-severity"]["axes"][0]
    assert metas["bearing-severity"]["axes"][-1]["xlabel"] == \
        "% of the record (snapshots end to end; the import has no times)"
    assert "xlim_local" not in sev and 0 < sev["xlim"][0] <= 7.5 and sev["xlim"][1] == pytest.approx(100.0)
    assert "<th>% of the record</th>" in page
    # each level's first decision: the end of the snapshot the replay names (2.5 % of the record each)
    line = re.search(r"  bearing: in the recording: (.*)\n", stderr)[1]
    placed = re.findall(r"at (\d+)\.csv \(([\d.]+) % of the record\)", line)
    assert placed, line
    changes = [t for kind, t in event_rows(page) if kind == "severity_change"]
    for name, pct in placed:
        assert float(pct) == pytest.approx(2.5 * (int(name) - 1))
        assert f"{2.5 * int(name):.3f} %" in changes, (name, changes)
    (log,) = logs.glob("*.mcap")
    lines = cmsensord("summary", str(log), cwd=tmp_path).stdout.splitlines()
    assert any(re.fullmatch(r"end: \S+ \(100\.0 % of the record\)", ln) for ln in lines), lines
    assert [ln for ln in lines if re.fullmatch(re.escape(
        f"  cmsensord: {{'source': '{tmp_path.resolve() / 'r.bin'}', 'recording_timeline': '40 snapshot(s) "
        "without times, "
        "40 s of signal end to end', 'run': '") + RUN + "'}",
        ln)], lines
    assert lines[-1] == ("  healthy period (baselines): 0.0-10.0 board s of the capture, 0.0 % to 25.0 % of the "
                         "record (the site file's commissioned section)"), lines


def test_one_continuous_file_is_drawn_in_seconds_into_it(tmp_path):
    d = run_to_failure(tmp_path)
    x = np.concatenate([np.loadtxt(f) for f in sorted(d.iterdir())])
    np.savetxt(tmp_path / "run.csv", x, fmt="%.5f")
    logs, _ = replayed(tmp_path, "run.csv")
    page, metas = report(tmp_path, logs)
    assert "A replay of an imported recording: times are seconds into the recording." in page
    assert "<title>cmsensord report 0.0 s – 40.0 s</title>" in page
    sev = metas["bearing-severity"]["axes"][0]
    assert metas["bearing-severity"]["axes"][-1]["xlabel"] == "seconds into the recording"
    assert sev["xlim"][1] == pytest.approx(40.0)
    assert "<th>seconds in</th>" in page
    assert all(re.fullmatch(r"\d+\.\d{3} s", t) for _, t in event_rows(page))


def test_a_calibrated_replay_draws_the_level_against_its_baseline_under_the_severity(tmp_path):
    """The combined severity's level / healthy baseline under the index, on a log scale with the
    baseline, level_alert and level_danger (the 2 x baseline rule), as the log's messages say."""
    from cmsensord.sinks.mcap_sink import read_messages

    logs, _ = replayed_import(tmp_path)
    _, metas = report(tmp_path, logs)
    top, below = metas["bearing-severity"]["axes"]
    assert top["ylabel"] == "severity index" and top["xlabel"] == ""
    assert below["ylabel"] == "level / baseline"
    assert below["lines"] == ["level / baseline", "level_alert 2 x (severity 0.5)", "level_danger 4 x (severity 1)"]
    sev = [m for topic, _, m in read_messages(next(logs.glob("*.mcap"))) if topic == "/cm/bearing/severity"]
    assert {(m["level_alert"], m["level_danger"]) for m in sev} == {(2.0, 4.0)}
    ratios = [m["level_ratio"] for m in sev if "level_ratio" in m]
    assert max(ratios) > 2.0 and below["ylim"][0] <= min(ratios) and max(ratios, default=0) < 4.0 < below["ylim"][1]
    assert below["xlim"] == top["xlim"]


def test_an_import_replayed_twice_into_one_directory_is_drawn_once_over_its_recording_time(tmp_path):
    """The same capture replayed again into the same directory (after a new calibration, say):
    the report draws the newest replay over the recording's time and says in one line that it
    left the older one out (guards against local time, "not all of one imported recording", and
    each trace drawn back from the end of one replay to the start of the other)."""
    logs, _ = replayed_import(tmp_path)
    (first,) = logs.glob("*.mcap")
    p = cmsensord("replay", "r.bin", "--config", "site.yaml", "--out", "logs", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    (second,) = set(logs.glob("*.mcap")) - {first}
    _, alone = report(tmp_path, second)                  # the newest replay alone
    out = tmp_path / "both.html"
    p = cmsensord("report", str(logs), "--out", str(out), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    line = (f"r.bin was replayed 2 times into these logs: the report draws the newest replay ({second.name}) "
            f"and leaves out the older one ({first.name}).")
    assert f"cmsensord: report: {line}" in p.stderr.splitlines()
    page = out.read_text(encoding="utf-8")
    assert line in html.unescape(page) and "not all of one imported recording" not in page
    assert f"<td>{first}</td><td class=\"n\">{first.stat().st_size:,}</td><td class=\"n\">0</td>" \
           "<td>left out: an older replay of r.bin</td>" in page
    metas = {m["id"]: m for m in json.loads(re.search(
        r'<script type="application/json" id="figures">(.*?)</script>', page, re.S).group(1))}
    sev = metas["bearing-severity"]
    assert sev["axes"][-1]["xlabel"] == "recording time (from the import)"
    assert sev["points"] == alone["bearing-severity"]["points"]
    assert [ax["xlim"] for ax in sev["axes"]] == [ax["xlim"] for ax in alone["bearing-severity"]["axes"]]
    assert f"<title>cmsensord report {clock(0)[:16]} – {clock(39, 1)[:16]}</title>" in page


def _two_machines(tmp_path: Path) -> dict[str, Path]:
    """Two machines' recordings, each its own import with the channel named alike (a quiet one of
    12 snapshots, a loud one of 8, one every 10 minutes), replayed into one directory, the first
    twice: the log of each replay that the report draws, by capture."""
    rng = np.random.default_rng(1)
    logs = tmp_path / "mix"
    drawn = {}
    for name, n, g in (("quiet", 12, 0.05), ("loud", 8, 0.5), ("quiet", 12, 0.05)):
        if not (tmp_path / f"{name}.bin").exists():
            np.savez(tmp_path / f"{name}.npz", acc=g * rng.standard_normal((n, 2560, 1)), fs_hz=np.array(2560.0),
                     t_s=np.arange(n) * 600.0)
            p = cmsensord("import", f"{name}.npz", *R2F, "--out", f"{name}.bin", cwd=tmp_path)
            assert p.returncode == 0, p.stderr
        before = set(logs.glob("*.mcap"))
        p = cmsensord("replay", f"{name}.bin", "--out", "mix", cwd=tmp_path)
        assert p.returncode == 0, p.stderr
        (drawn[name],) = set(logs.glob("*.mcap")) - before
    return drawn


def test_replays_of_two_machines_in_one_directory_are_drawn_apart_each_over_its_own_time(tmp_path):
    """Two imports whose channel has one name, replayed into one directory: a part of the page
    each, its figures, events and files its own, over its own recording time (not one trace
    running back and forth between the machines over overlapping times)."""
    drawn = _two_machines(tmp_path)
    alone = {name: report(tmp_path, log)[1]["bearing-severity"] for name, log in drawn.items()}
    out = tmp_path / "mix.html"
    p = cmsensord("report", "mix", "--out", str(out), "--png", "png", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    lines = p.stderr.splitlines()
    assert lines[0] == ("cmsensord: report: these logs hold 2 different recordings, drawn apart, each over its "
                        "own time: quiet.bin (1 file(s)), loud.bin (1 file(s)).")
    assert lines[1].startswith("cmsensord: report: quiet.bin was replayed 2 times into these logs: the report "
                               f"draws the newest replay ({drawn['quiet'].name})")
    page = out.read_text(encoding="utf-8")
    metas = {m["id"]: m for m in json.loads(re.search(
        r'<script type="application/json" id="figures">(.*?)</script>', page, re.S).group(1))}
    assert {"quiet.bin-bearing-severity", "loud.bin-bearing-severity"} <= set(metas)
    assert not any(fid.startswith("bearing-") for fid in metas)
    assert {f.name for f in (tmp_path / "png").glob("*severity.png")} == {
        "quiet.bin-bearing-severity.png", "loud.bin-bearing-severity.png"}
    for name, fig in alone.items():
        mine = metas[f"{name}.bin-bearing-severity"]
        assert mine["title"] == f"{name}.bin bearing: severity index"
        assert mine["points"] == fig["points"] and mine["axes"][0]["xlim"] == fig["axes"][0]["xlim"]
        assert mine["axes"][-1]["xlabel"] == "hours into the recording"
    assert page.count("times are hours into the recording") == 2
    quiet, loud = page.split('<h2 class="recording" id="loud.bin-recording">Recording loud.bin</h2>')
    assert '<h2 class="recording" id="quiet.bin-recording">Recording quiet.bin</h2>' in quiet
    def cell(log: Path) -> str:
        return f"<td>mix/{log.name}</td>"
    assert cell(drawn["loud"]) not in quiet and cell(drawn["quiet"]) in quiet and cell(drawn["loud"]) in loud
    assert "<h2>Events of quiet.bin</h2>" in quiet and "<h2>Events of loud.bin</h2>" in loud
