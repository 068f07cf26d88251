"""What a daemon running for months holds does not grow with the time it has run: the logs it
names in its exit summary (rotated files, some moved away by another program meanwhile)."""

from __future__ import annotations

import json
import re
import time

from cmsensord.sinks.log_names import log_files
from processes import start_board, start_daemon, stop

#: more of the daemon's output section: a file every ~2.5 board seconds of 4 channels, no retention
ROTATE = "  rotate_mb: 0.005\n  retain_mb: 0\n  min_free_mb: 0\n  flush_s: 0.1\n"


def finished(out):
    """The finished logs in ``out``, in the order they were opened."""
    return log_files(out, "cmsensord")[0] if out.is_dir() else []


def test_the_exit_summary_names_the_newest_logs_still_there_and_counts_the_older(tmp_path):
    """The daemon on a 40-s board of 4 channels rotating every few kB (over a dozen files); the
    first 3 finished files are moved away (an archiver) while it runs: the exit summary names
    none of them, names the newest 5 files in the directory and counts the others there, so a
    daemon rotating for months neither holds nor prints a line per file it ever wrote."""
    out, archive = tmp_path / "logs", tmp_path / "archive"
    archive.mkdir()
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", "--channels", "4", "--duration", "40", "--speed", "10",
                      "--link", str(link), "--flow-control")
    d = start_daemon(tmp_path, link, config=ROTATE)
    deadline = time.monotonic() + 60
    while len(done := finished(out)) < 3 and time.monotonic() < deadline:
        time.sleep(0.05)
    moved = [p.name for p in done[:3]]
    for name in moved:
        (out / name).rename(archive / name)
    json.loads(sim.stdout.readline())                # the board has sent everything
    time.sleep(1.0)
    err = stop(d)
    sim.terminate()
    sim.wait(timeout=5)
    assert d.returncode == 0 and "Traceback" not in err, err
    there = finished(out)
    assert len(moved) == 3 and len(there) > 5, (moved, there)
    named = re.findall(r"^MCAP log: (\S+)$", err, re.M)
    assert named == [str(p) for p in there[-5:]], err
    assert f"MCAP logs: {len(there) - 5} older one(s) of this run in {out}; the newest 5:" in err.splitlines(), err
