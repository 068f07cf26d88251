"""Retention's routine deletions are ``retention`` events (INFO), not ``disk_error`` ones: a
daemon rotating every few kB deletes a log at each rotation, and the journal's budget of 10 lines
of a kind in 600 s is retention's own, so a real disk error after them (the file system filled by
another program: ENOSPC) is still an ERROR line of its own; a summary of the lines held back
is at the highest level among them (retention's: INFO, never ERROR).  The other program takes the
free space in one call (fallocate), then its last bytes, so it does not race the daemon's own
deletions for long; the daemon's outage begins where its next write fails (a chunk, a file's
close, or a new file's header at a rotation), one outage, not one a retry (each new file
fsynced with its header alone said logging resumed, then failed again).

A real daemon on a simulated board over a pty, its logs on a small tmpfs (``small_fs``).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time

from processes import spawn, start_board, stop

CONFIG = ("  compression: none\n  rotate_mb: 0.02\n  retain_mb: 0.1\n  min_free_mb: 0\n  flush_s: 0.1\n"
          "  retry_s: 1\n")


def _wait_for(predicate, timeout: float) -> None:
    end = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.2)


def test_a_disk_error_after_many_retention_passes_is_its_own_error_line(small_fs, tmp_path):
    logs = small_fs / "logs"
    link = tmp_path / "ttyBOARD"
    board = start_board("--scenario", "healthy", "--channels", "4", "--speed", "20", "--link", str(link),
                        "--flow-control")
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text(f"link:\n  port: {link}\n  max_drift_s: 0\noutput:\n  dir: {logs}\n  status_line: false\n{CONFIG}")
    daemon = spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg)], stderr=subprocess.PIPE, text=True)
    try:
        rotated: set[str] = set()

        def rotations() -> bool:                  # each rotation's retention deletes the oldest log
            rotated.update(p.name for p in logs.glob("*.mcap"))
            return len(rotated) >= 16

        _wait_for(rotations, 60)
        filler = small_fs / "other-program.bin"   # another program fills the file system
        with open(filler, "wb", buffering=0) as f:   # unbuffered: nothing left to write at its close
            try:                                  # all the free space in one call, then what is left
                st = os.statvfs(small_fs)
                os.posix_fallocate(f.fileno(), 0, st.f_bavail * st.f_frsize)
            except OSError:
                pass
            try:
                while True:
                    f.write(b"\0" * 4096)
            except OSError:
                pass
        time.sleep(2.0)
        os.unlink(filler)
        time.sleep(3.0)                           # retry_s 1: logging resumes
        err = stop(daemon, timeout=30)
    finally:
        board.terminate()
        board.wait(timeout=5)
    assert daemon.returncode == 0 and "Traceback" not in err, err[-3000:]
    lines = err.splitlines()
    errors = [line for line in lines if line.startswith("ERROR")]
    # a file an outage kept whose salvage, when logging resumed, the still-full disk refused: its
    # own ERROR line, once, and it is tried again after a rotation
    salvage = [line for line in errors if re.fullmatch(
        r"ERROR disk_error: \S+\.mcap\.part: cannot salvage: No space left on device; tried again after the "
        r"next rotation", line)]
    outages = [line for line in errors if line not in salvage]
    # one error line an outage, each but the newest ended by its "logging resumed" line: the file the
    # daemon gives up frees its bytes, so a retry can get in before the other program takes them and
    # the disk fills again (more outages, the newest maybe still open at the stop: a loaded machine)
    resumed = [line for line in lines if line.startswith("INFO disk_error: logging resumed in ")]
    assert outages and resumed and len(outages) - 1 <= len(resumed) <= len(outages) and all(
        re.match(r"ERROR disk_error: (not logging: )?\S+\.mcap\.part: (write failed|cannot finish MCAP file|cannot "
                 r"write): No space left on device; ", e) for e in outages), "\n".join(errors + resumed)
    kept = {m.group(1) for e in outages for m in [re.search(r"; file kept as (\S+) for salvage; ", e)] if m}
    for line in salvage:                          # the daemon's own file, salvaged later or left at the stop
        name = line.split()[2].rstrip(":").rsplit("/", 1)[-1]
        assert name in kept and any(x.startswith(f"INFO salvage: {name}: salvaged ") or (
            x.startswith("INFO ") and x.endswith("; left for the next start") and name in x) for x in lines), \
            "\n".join(errors + resumed + [x for x in lines if name in x])
    told = [line for line in lines if line.startswith("INFO retention: ") and "more retention event(s)" not in line]
    deletion = (r"INFO retention: deleted the \d+ oldest log file\(s\) \([0-9.]+ MB: cmsensord-\S+\.mcap"
                r"(, cmsensord-\S+\.mcap)*( \.\.\.)?\) to keep this prefix's")
    assert len(told) == 10 and all(re.match(deletion, line) for line in told), "\n".join(told)   # the budget
    summaries = [line for line in lines if "more retention event(s)" in line]
    assert summaries and all(line.startswith("INFO retention: ") for line in summaries), summaries
    assert not [line for line in lines if line.startswith("ERROR") and "retention" in line]
