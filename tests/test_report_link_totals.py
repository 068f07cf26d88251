"""The report's link counters, summed over the runs its logs hold, whatever order the files come in.

Each replay is a run: its last ``/cm/diagnostics`` counts every byte of its capture. Two
replays into one directory total both captures (the first run is not dropped when the
second's first diagnostics already count more bytes than its last); one replay rotated into
many files, given newest first or shuffled, totals its capture once (a file boundary is no
restart). Logs written before files named their run are grouped by
``source`` and by ``uptime_s`` and ``bytes_received`` going on (:mod:`cmsensord.report.link_runs`).
"""

from __future__ import annotations

import json
import random
import re
from pathlib import Path

import pytest

from cmsensord.report.log_data import LogData
from cmsensord.sinks.mcap_read import read_messages
from processes import cmsensord, run_module


def _capture(tmp: Path, name: str, *args: str) -> Path:
    path = tmp / f"{name}.bin"
    r = run_module("firmware_sim", *args, "--out", str(path))
    assert r.returncode == 0, r.stderr
    return path


def _replay(capture: Path, out: Path, config: Path | None = None) -> list[Path]:
    """``cmsensord replay CAPTURE --out OUT``: the files it wrote, in the order written."""
    before = set(out.glob("*.mcap"))
    r = cmsensord("replay", str(capture), "--out", str(out), *(["--config", str(config)] if config else []))
    assert r.returncode == 0, r.stderr
    return sorted(set(out.glob("*.mcap")) - before, key=lambda p: read_messages(p)[0][1])


def _last_link(files: list[Path]) -> dict[str, int]:
    """The link counters of a run's newest diagnostics."""
    return [m for p in files for t, _, m in read_messages(p) if t == "/cm/diagnostics"][-1]["link"]


def _report(tmp: Path, *logs: Path) -> tuple[dict[str, int], str | None]:
    """(the report's link counter table, its line on the runs)."""
    out = tmp / "r.html"
    r = cmsensord("report", *map(str, logs), "--out", str(out))
    assert r.returncode == 0, r.stderr
    page = out.read_text(encoding="utf-8")
    table = re.search(r'<table id="link">(.*?)</table>', page).group(1)
    rows = re.findall(r'<tr><td>(\w+)</td><td class="n">([\d,]+)</td>', table)
    counters = {k: int(v.replace(",", "")) for k, v in rows}
    line = re.search(r'<p id="runs">(.*?)</p>', page)
    return counters, line.group(1) if line else None


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("links")
    short = _capture(tmp, "short", "--scenario", "healthy", "--duration", "20")
    long = _capture(tmp, "long", "--scenario", "healthy", "--duration", "60", "--seed", "1")
    big = _capture(tmp, "big", "--scenario", "degrading", "--duration", "300", "--channels", "2")
    two = tmp / "two"
    first = _replay(short, two)
    second = _replay(long, two)
    cfg = tmp / "rotate.yaml"
    cfg.write_text("output:\n  rotate_mb: 0.05\n  retain_mb: 0\n  min_free_mb: 0\n  akf_trace: true\n")
    rotated = _replay(big, tmp / "rotated", cfg)
    return {"short": short, "long": long, "big": big, "two": two, "first": first, "second": second,
            "rotated": rotated}


def _sum(*links: dict[str, int]) -> dict[str, int]:
    return {k: sum(link[k] for link in links) for k in links[0]}


def test_two_replays_into_one_directory_total_both_captures(runs, tmp_path):
    assert len(runs["first"]) == len(runs["second"]) == 1
    truth = _sum(_last_link(runs["first"]), _last_link(runs["second"]))
    assert truth["bytes_received"] == runs["short"].stat().st_size + runs["long"].stat().st_size == 179_680
    counters, line = _report(tmp_path, runs["two"])
    assert {k: counters[k] for k in truth} == truth
    assert line == "Link counters summed over 2 run(s) (a daemon start, a replay)."
    counters, _ = _report(tmp_path, *runs["second"], *runs["first"])      # given newest first
    assert {k: counters[k] for k in truth} == truth


def test_one_replay_rotated_into_files_totals_its_capture_once_in_any_order(runs, tmp_path):
    files = runs["rotated"]
    assert len(files) >= 5
    truth = _last_link(files)
    assert truth["bytes_received"] == runs["big"].stat().st_size == 796_200
    shuffled = files[::-1]
    random.Random(1).shuffle(shuffled)
    for order in (files[::-1], shuffled):
        counters, line = _report(tmp_path, *order)
        assert {k: counters[k] for k in truth} == truth
        assert line == "Link counters summed over 1 run(s) (a daemon start, a replay)."


def _diag(uptime_s: float, received: int) -> bytes:
    link = {"bytes_received": received, "bytes_discarded": 0, "frames_rms": received // 10}
    return json.dumps({"link": link, "queue_depth": 0, "queue_drops": 1, "lag_s": 0.0,
                       "observations": 0, "uptime_s": uptime_s}, separators=(",", ":")).encode()


def test_logs_without_a_run_are_grouped_by_source_uptime_and_bytes_in_any_order():
    """Files of before the ``run`` metadata: a daemon rotated into two files and restarted
    (uptime_s back to 1), and a replay (another source) whose counters start above the daemon's
    last: three runs, the same total whichever order the files come in."""
    files = [({"source": "/dev/ttyACM0"}, [(10**18, 1.0, 100), (10**18 + 10**9, 3600.0, 5000)]),
             ({"source": "/dev/ttyACM0"}, [(10**18 + 2 * 10**9, 3601.0, 5100), (10**18 + 3 * 10**9, 7200.0, 9000)]),
             ({"source": "/dev/ttyACM0"}, [(10**18 + 4 * 10**9, 1.0, 50), (10**18 + 5 * 10**9, 60.0, 700)]),
             ({"source": "cap.bin"}, [(10**18 + 6 * 10**9, 0.01, 20000), (10**18 + 7 * 10**9, 0.02, 30000)])]
    for order in ([0, 1, 2, 3], [3, 2, 1, 0], [2, 0, 3, 1]):
        data = LogData()
        for i in order:
            data.begin_file(files[i][0])
            for t, up, rx in files[i][1]:
                data.add("/cm/diagnostics", t, _diag(up, rx))
        assert data.link_counters() == {"bytes_received": 39700, "bytes_discarded": 0, "frames_rms": 3970}
        assert (data.total_queue_drops(), data.runs()) == (3, 3)
