"""Log file names keep the order the files were opened when the wall clock steps back (an NTP
sync on a board without an RTC battery): a new name never sorts before one already in the
directory, so retention deletes the files opened first and a report reads them in that order."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from cmsensord.report.reading import log_paths
from cmsensord.sinks.log_names import log_files, order_key
from cmsensord.sinks.mcap_file import McapSink
from cmsensord.sinks.mcap_read import read_messages
from processes import ENV, ROOT

T = 1_764_505_661.0                       # 2025-11-30T12:27:41Z


def test_a_file_opened_after_the_clock_stepped_back_is_named_after_the_newest_one(tmp_path):
    first = McapSink(tmp_path, wall_clock=lambda: T + 3600).close()
    second = McapSink(tmp_path, wall_clock=lambda: T + 3611).close()
    stepped = [McapSink(tmp_path, wall_clock=lambda k=k: T + k).close() for k in (0, 11)]   # an hour back
    assert [p.name for p in (first, second, *stepped)] == [
        "cmsensord-20251130T132741Z.mcap", "cmsensord-20251130T132752Z.mcap",
        "cmsensord-20251130T132752Z-1.mcap", "cmsensord-20251130T132752Z-2.mcap"]
    later = McapSink(tmp_path, wall_clock=lambda: T + 3700).close()      # the clock passed it again
    assert later.name == "cmsensord-20251130T132921Z.mcap"
    finished, _ = log_files(tmp_path, "cmsensord")
    assert finished == [first, second, *stepped, later]


def test_a_report_of_a_directory_reads_its_logs_in_the_order_they_were_opened(tmp_path):
    names = ["cmsensord-20251130T132752Z.mcap", "cmsensord-20251130T132752Z-2.mcap",
             "cmsensord-20251130T132752Z-10.mcap.part", "cmsensord-20251130T132753Z.salvaged.mcap"]
    for name in names:
        (tmp_path / name).write_bytes(b"")
    assert [p.name for p in log_paths([str(tmp_path)])] == names
    assert sorted(reversed(names), key=order_key) == names


def test_retention_after_the_clock_stepped_back_deletes_the_files_opened_first(tmp_path):
    """The daemon (simulated board, a file every few kB, 0.05 MB kept) whose wall clock steps
    back an hour once two files are finished: the files kept are the newest, one after the other in
    the data's time (guards against the files opened after the step named an hour earlier, and
    each deleted as "the oldest" once finished, the newest data)."""
    out = tmp_path / "out"
    (tmp_path / "c.yaml").write_text(f"output:\n  dir: {out}\n  rotate_mb: 0.005\n  retain_mb: 0.05\n"
                                     "  min_free_mb: 0\n  flush_s: 0.1\n")
    r = subprocess.run([sys.executable, str(ROOT / "tests" / "wall_step.py"), f"2@{out}/*.mcap", "-3600", "--simulate",
                        "--duration", "30", "--speed", "5", "--channels", "4", "--out", str(out),
                        "--config", str(tmp_path / "c.yaml")], capture_output=True, text=True, env=ENV,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    deleted = [name for names in re.findall(r"INFO retention: deleted the \d oldest log file\(s\) "
                                            r"\([0-9.]+ MB: (cmsensord-[^ )]+\.mcap(?:, cmsensord-[^ )]+\.mcap)*)\)",
                                            r.stderr) for name in names.split(", ")]
    kept, _ = log_files(out, "cmsensord")
    opened = deleted + [p.name for p in kept]
    assert len(deleted) >= 10 and len(kept) >= 2, (deleted, kept)
    assert opened == sorted(opened, key=order_key), opened          # each time the one opened first
    assert Path(re.findall(r"MCAP log: (\S+)", r.stderr)[-1]) == kept[-1]
    spans = [(min(stamps), max(stamps)) for stamps in ([s for _, s, _ in read_messages(p)] for p in kept)]
    for (_, end), (start, _) in zip(spans, spans[1:]):
        assert 0 <= start - end < 2e9, spans                        # the newest data, none missing
