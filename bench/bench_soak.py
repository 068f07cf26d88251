#!/usr/bin/env python3
"""Memory over a long run: the daemon's resident set, sampled while `cmsensord --simulate` runs.

    python bench/bench_soak.py [--preset rms4|raw1] [--hours H] [--speed X] [--every S]

Runs the simulated board on a pty and the daemon on it (``cmsensord --simulate``, the same
process a user starts) for ``--hours`` board hours at ``--speed`` times real time, samples
the daemon process's VmRSS, its CPU seconds and open file descriptors every ``--every``
seconds, and prints a table (board hours, RSS MB, CPU s, fds) and the growth of the RSS over
the second half of the run in MB per board hour: a daemon that runs for months must not grow
with the time it has run.  Each MCAP file is rotated by wall time (``output.rotate_s``), so a
fast run keeps one file open for all of it: its indexes are in the figure too.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PRESETS = {
    "rms4": ["--scenario", "healthy", "--channels", "4"],
    "raw1": ["--scenario", "faulty", "--mode", "raw", "--tacho", "--channels", "1"],
}
TICK = os.sysconf("SC_CLK_TCK")


def sample(pid: int) -> tuple[float, float, int] | None:
    """(RSS MB, CPU s, open fds) of process ``pid``, or None once it has gone."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
        stat = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        fds = len(os.listdir(f"/proc/{pid}/fd"))
    except (FileNotFoundError, ProcessLookupError):
        return None
    rss_kb = next((int(line.split()[1]) for line in status.splitlines() if line.startswith("VmRSS")), None)
    if rss_kb is None:          # exited, not reaped yet
        return None
    return rss_kb / 1024, (int(stat[11]) + int(stat[12])) / TICK, fds


def run(preset: str, hours: float, speed: float, every: float) -> list[tuple[float, float, float, int]]:
    """The samples (board hours, RSS MB, CPU s, fds) of one run."""
    seconds = hours * 3600
    with tempfile.TemporaryDirectory(prefix="bench_soak") as out, open(Path(out) / "stderr", "w+") as log:
        p = subprocess.Popen([sys.executable, "-m", "cmsensord", "--simulate", *PRESETS[preset],
                              "--duration", str(seconds), "--speed", str(speed), "--out", out],
                             stdout=subprocess.DEVNULL, stderr=log, text=True)
        start, rows = time.monotonic(), []
        while p.poll() is None:
            time.sleep(every)
            got = sample(p.pid)
            if got is not None and p.poll() is None:
                board_h = min((time.monotonic() - start) * speed / 3600, hours)
                rows.append((board_h, *got))
                print(f"  {board_h:6.2f} board h: {got[0]:.1f} MB", file=sys.stderr, flush=True)
        log.seek(0)
        err = log.read()
    if p.returncode != 0:
        raise SystemExit(f"cmsensord --simulate exited {p.returncode}: {err[-2000:]}")
    return rows


def growth(rows: list[tuple[float, float, float, int]]) -> float:
    """Least-squares slope of RSS over the second half of the samples, MB per board hour."""
    half = rows[len(rows) // 2:]
    if len(half) < 2:
        return float("nan")
    xs, ys = [r[0] for r in half], [r[1] for r in half]
    mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
    den = sum((x - mx) ** 2 for x in xs)
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / den if den else float("nan")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--preset", choices=sorted(PRESETS), default="rms4")
    ap.add_argument("--hours", type=float, default=24.0, help="board hours (default 24)")
    ap.add_argument("--speed", type=float, default=400.0, help="x real time (default 400; raw1: try 40)")
    ap.add_argument("--every", type=float, default=10.0, help="seconds between samples (default 10)")
    a = ap.parse_args()
    rows = run(a.preset, a.hours, a.speed, a.every)
    if not rows:
        raise SystemExit("no sample: the run ended before the first (lower --every)")
    print(f"# {a.preset}: {a.hours:g} board hours at {a.speed:g}x, a sample every {a.every:g} s\n")
    print("| board hours | RSS MB | CPU s | open fds |\n| ---: | ---: | ---: | ---: |")
    step = max(1, len(rows) // 12)
    for r in rows[::step] + ([rows[-1]] if (len(rows) - 1) % step else []):
        print(f"| {r[0]:.2f} | {r[1]:.1f} | {r[2]:.1f} | {r[3]} |")
    print(f"\nRSS first / peak / last: {rows[0][1]:.1f} / {max(r[1] for r in rows):.1f} / {rows[-1][1]:.1f} MB; "
          f"growth over the second half: {growth(rows):+.3f} MB per board hour")
    return 0


if __name__ == "__main__":
    sys.exit(main())
