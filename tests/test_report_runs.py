"""``cmsensord report`` of logs of several runs of imports in one directory: a ``vkf`` run drawn in
its recording (its batch orders beside the newest replay, on the recording's time), one capture
replayed under two spellings of its path is one recording, and recordings whose names make one
id are numbered (no figure, PNG or element id of one overwrites or repeats another's)."""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

import numpy as np
import pytest

from cmsensord.importing.timeline import Timeline
from cmsensord.report.fast_read import head_metadata
from cmsensord.report.runs import plan_logs
from cmsensord.sinks.mcap_sink import read_messages
from processes import cmsensord

pytest.importorskip("matplotlib", reason="the report extra")

#: 4 one-second snapshots at 2560 Hz, 10 minutes apart, one channel, a constant 1800 rpm (TACHO
#: frames, so that vkf runs on it)
IMPORT = ("--fs", "2560", "--block-len", "32", "--unit", "g", "--names", "bearing", "--rpm", "1800")


def imported(tmp_path: Path, *names: str) -> None:
    """One small recording imported as each of ``names``."""
    acc = 0.05 * np.random.default_rng(1).standard_normal((4, 2560, 1))
    np.savez(tmp_path / "m.npz", acc=acc, fs_hz=np.array(2560.0), t_s=np.arange(4) * 600.0)
    for name in names:
        p = cmsensord("import", "m.npz", *IMPORT, "--out", name, cwd=tmp_path)
        assert p.returncode == 0, p.stderr


def run(tmp_path: Path, *args: str) -> Path:
    """``cmsensord ARGS --out logs`` in ``tmp_path``: the log it wrote."""
    before = set((tmp_path / "logs").glob("*.mcap"))
    p = cmsensord(*args, "--out", "logs", cwd=tmp_path, timeout=300)
    assert p.returncode == 0, p.stderr
    (log,) = set((tmp_path / "logs").glob("*.mcap")) - before
    return log


def report(tmp_path: Path, *logs: str, png: bool = False) -> tuple[list[str], str, dict[str, dict]]:
    """(stderr lines, page, figures by id) of ``cmsensord report LOGS --out r.html``."""
    p = cmsensord("report", *logs, "--out", "r.html", *("--png", "png") * png, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    page = (tmp_path / "r.html").read_text(encoding="utf-8")
    metas = json.loads(re.search(r'<script type="application/json" id="figures">(.*?)</script>', page, re.S)[1])
    return p.stderr.splitlines(), page, {m["id"]: m for m in metas}


def file_row(page: str, log: Path) -> tuple[str, str]:
    """A file's (messages, state) in the page's table of files."""
    m = re.search(rf'<td>logs/{log.name}</td><td class="n">[\d,]+</td><td class="n">([\d,]+)</td><td>([^<]*)</td>',
                  page)
    assert m is not None, log
    return m[1], html.unescape(m[2])


def test_a_vkf_run_of_an_import_is_drawn_in_its_recording_on_its_time_beside_the_newest_replay(tmp_path):
    """An import replayed and run through vkf twice into one directory: one recording (not the vkf
    logs apart as "board logs" on the wall clock), drawn from the replay and the batch orders of
    the newest vkf run (its recursive orders, severity and events repeat the replay's); the older
    vkf run left out and said, as older replays are."""
    imported(tmp_path, "r.bin")
    replay = run(tmp_path, "replay", "r.bin")
    old = run(tmp_path, "vkf", "r.bin")
    vkf = run(tmp_path, "vkf", "r.bin")
    head = head_metadata(vkf)["cmsensord"]
    assert head["source"] == str((tmp_path / "r.bin").resolve())
    timeline, zero = Timeline.from_json(head["recording_timeline"])
    assert timeline.source_s.tolist() == [0.0, 600.0, 1200.0, 1800.0]
    batch = [t for topic, t, m in read_messages(vkf) if topic == "/cm/bearing/orders" and m["method"] == "batch"]
    assert len(batch) == 40 and 0 < (batch[0] - zero) / 1e9 < (batch[-1] - zero) / 1e9 <= 4.0   # board seconds
    _, _, alone = report(tmp_path, str(replay))
    lines, page, metas = report(tmp_path, "logs", png=True)
    messages = len(read_messages(replay)) + len(batch)
    assert lines == [
        f"cmsensord: report: r.bin was run through vkf 2 times into these logs: the report draws the newest vkf run "
        f"({vkf.name}) and leaves out the older one ({old.name}).",
        f"report: r.html (3 figures, {messages:,} messages from 2 file(s))"]
    assert {f.name for f in (tmp_path / "png").iterdir()} == {
        "bearing-severity.png", "bearing-indicators.png", "bearing-orders.png"}
    assert file_row(page, vkf) == ("40", "read for its batch VKF orders only (the rest repeats the replay's); complete")
    assert file_row(page, old) == ("0", "left out: an older vkf run of r.bin")
    assert file_row(page, replay)[1] == "complete"
    sev = metas["bearing-severity"]
    assert sev["axes"][-1]["xlabel"] == "hours into the recording"
    assert sev["points"] == alone["bearing-severity"]["points"]
    assert [ax["xlim"] for ax in sev["axes"]] == [ax["xlim"] for ax in alone["bearing-severity"]["axes"]]
    # the replay's recursive orders and the vkf run's batch orders of one order, apart
    names = alone["bearing-orders"]["orders"]
    assert metas["bearing-orders"]["orders"] == names + [f"{n} (batch)" for n in names] and names
    # the vkf log alone: all of it, on the recording's time (its board second 0 anchored as a replay's)
    lines, page, metas = report(tmp_path, str(vkf))
    assert lines == [f"report: r.html (3 figures, {len(read_messages(vkf)):,} messages from 1 file(s))"]
    assert metas["bearing-severity"]["axes"][-1]["xlabel"] == "hours into the recording"
    assert metas["bearing-severity"]["points"] == alone["bearing-severity"]["points"]
    assert "<title>cmsensord report 0.000 h – 0.500 h</title>" in page


def test_one_capture_replayed_under_two_spellings_of_its_path_is_one_recording(tmp_path):
    imported(tmp_path, "a.bin")
    first = run(tmp_path, "replay", "a.bin")
    second = run(tmp_path, "replay", str(tmp_path / "logs" / ".." / "a.bin"))
    assert {head_metadata(log)["cmsensord"]["source"] for log in (first, second)} == {
        str((tmp_path / "a.bin").resolve())}
    lines, page, _ = report(tmp_path, "logs")
    assert lines[0] == (f"cmsensord: report: a.bin was replayed 2 times into these logs: the report draws the newest "
                        f"replay ({second.name}) and leaves out the older one ({first.name}).")
    assert len(lines) == 2 and "different recordings" not in page
    assert file_row(page, first) == ("0", "left out: an older replay of a.bin")


def test_logs_that_name_their_capture_by_other_paths_are_of_one_recording(tmp_path, monkeypatch):
    """Logs whose ``source`` is the capture as it was given (relative, absolute), not its real
    path, are grouped by the real path, read from where the report runs."""
    monkeypatch.chdir(tmp_path)
    timeline = Timeline(np.array([0.0, 1.0]), np.array([0.0, 600.0]), end_s=2.0)
    metas = [{"cmsensord": {"source": source, "recording_timeline": timeline.to_json(zero)}}
             for source, zero in (("a.bin", 10), (f"{tmp_path}/./a.bin", 20), ("b.bin", 30))]
    (a, b) = plan_logs([Path("1.mcap"), Path("2.mcap"), Path("3.mcap")], metas)
    assert (a.name, a.paths, b.name) == ("a.bin", [Path("2.mcap")], "b.bin")
    assert a.left_out == [(Path("1.mcap"), "left out: an older replay of a.bin")]


def test_recordings_whose_names_make_one_id_are_numbered_in_ids_and_png_names(tmp_path):
    """Captures "x y.bin" and "x-y.bin" (ids of both "x-y.bin"): every figure its own PNG, every
    element id once in the page."""
    imported(tmp_path, "x y.bin", "x-y.bin")
    run(tmp_path, "replay", "x y.bin")
    run(tmp_path, "replay", "x-y.bin")
    lines, page, metas = report(tmp_path, "logs", png=True)
    assert lines[0] == ("cmsensord: report: these logs hold 2 different recordings, drawn apart, each over its own "
                        "time: x y.bin (1 file(s)), x-y.bin (1 file(s)).")
    figures = {f"{rec}-bearing-{kind}" for rec in ("x-y.bin", "x-y.bin-2")
               for kind in ("severity", "indicators", "orders")}
    assert set(metas) == figures
    assert {f.name for f in (tmp_path / "png").iterdir()} == {f"{fid}.png" for fid in figures}
    assert metas["x-y.bin-bearing-severity"]["title"] == "x y.bin bearing: severity index"
    assert metas["x-y.bin-2-bearing-severity"]["title"] == "x-y.bin bearing: severity index"
    ids = re.findall(r' id="([^"]+)"', page)
    assert len(ids) == len(set(ids)) and {"x-y.bin-recording", "x-y.bin-2-recording"} <= set(ids)
