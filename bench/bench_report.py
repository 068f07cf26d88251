#!/usr/bin/env python3
"""Benchmark of ``cmsensord report``: wall time and peak memory over logs of one day and one week.

Writes synthetic logs with the daemon's own MCAP writer (``McapSink``): per
second, for each channel one ``/cm/<ch>/severity`` and one ``/cm/<ch>/indicators``
(RAW-mode fields: velocity RMS and its ISO zone, kurtosis, crest factor), one
``/cm/diagnostics``, and an event every 10 minutes; the log rotates every 6 hours
as the daemon's does. Then runs ``python -m cmsensord report DIR --out ...`` as a
user would and prints, per length, the messages, the log size, the wall time and
the report process's peak resident memory (the same for a day and a week shows that
memory is bounded).

    python bench/bench_report.py [--days 1 7] [--channels 1] [--keep DIR]
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cmsensord.sinks.mcap_file import McapSink  # noqa: E402

NS = 1_000_000_000
T0 = 1_795_000_000 * NS


def _indicators(ch: str, k: int) -> dict:
    v = 2.0 + 1.5 * math.sin(k / 40000.0) + (3.0 if k % 86400 > 80000 else 0.0)
    return {"channel": ch, "mode": "raw", "interval_s": 1.0, "missing_fraction": 0.0,
            "accel_rms": v / 2.7, "accel_peak": v, "crest_factor": 3.1, "kurtosis": 3.0 + (k % 17) / 10,
            "velocity_rms_mm_s": v, "velocity_band_hz": [10.0, 1000.0],
            "zone": "A" if v < 1.4 else "B" if v < 2.8 else "C" if v < 4.5 else "D",
            "zone_boundaries_mm_s": [1.4, 2.8, 4.5], "envelope_rms": 0.3, "envelope_band_hz": [2000.0, 10000.0],
            "speed_rpm": 1720.0, "speed_source": "tacho", "bearings": [], "bands": []}


def write_logs(out: Path, seconds: int, channels: int) -> int:
    """Synthetic 1-Hz logs of ``seconds`` into ``out``, rotated every 6 h: the number of messages."""
    n = 0
    sink = None
    names = [f"ch{i}" for i in range(channels)]
    clock = [0.0]
    for k in range(seconds):
        if k % 21600 == 0:
            if sink is not None:
                sink.close()
            sink = McapSink(out, clock=lambda: clock[0], wall_clock=lambda k=k: T0 / NS + k)
        clock[0] = float(k)
        t = T0 + k * NS
        for ch in names:
            level = min(10, (k // 3600) % 11)
            sink.write(f"/cm/{ch}/severity", "severity", t, {
                "channel": ch, "severity_index": level / 10, "level": level, "anomaly": [int(level > i)
                                                                                         for i in range(10)],
                "outliers": [0] * 10, "f_r": 28.66, "r": [0.01 * i for i in range(10)], "failure": False,
                "missing": 0, "transient": False})
            sink.write(f"/cm/{ch}/indicators", "indicators", t, _indicators(ch, k))
            n += 2
        sink.write("/cm/diagnostics", "diagnostics", t, {
            "link": {"bytes_received": 2314 * k, "bytes_discarded": 0, "crc_failures": 0, "header_rejects": 0,
                     "frames_status": 2, "frames_rms": 100 * k, "frames_raw": 0, "frames_tacho": 0,
                     "frames_lost": 0, "overruns": 0},
            "queue_depth": k % 5, "queue_drops": 0, "lag_s": 0.01, "observations": 100 * k, "uptime_s": float(k)})
        n += 1
        if k % 600 == 0:
            sink.write("/cm/events", "event", t, {"kind": "severity_change", "channel": names[0],
                                                  "message": f"{names[0]}: severity index changed at {k} s"})
            n += 1
    if sink is not None:
        sink.close()
    return n


def run_report(log_dir: Path, out: Path) -> tuple[float, float]:
    """(wall seconds, peak RSS MiB) of ``python -m cmsensord report log_dir --out out`` in a child."""
    code = ("import resource, sys; from cmsensord.cli import main; rc = main(sys.argv[1:]); "
            "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr); sys.exit(rc)")
    t = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", code, "report", str(log_dir), "--out", str(out)],
                       capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    wall = time.perf_counter() - t
    if p.returncode != 0:
        raise SystemExit(p.stderr)
    return wall, int(p.stderr.strip().splitlines()[-1]) / 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--days", type=float, nargs="+", default=[1.0, 7.0])
    ap.add_argument("--channels", type=int, default=1)
    ap.add_argument("--keep", metavar="DIR", help="write the logs under DIR and keep them")
    args = ap.parse_args()
    base = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench_report_"))
    print(f"{'days':>5} {'messages':>10} {'log MB':>8} {'write s':>8} {'report s':>9} {'peak RSS MiB':>13}")
    for days in args.days:
        d = base / f"days{days:g}"
        d.mkdir(parents=True, exist_ok=True)
        t = time.perf_counter()
        n = write_logs(d, int(days * 86400), args.channels)
        write_s = time.perf_counter() - t
        size = sum(f.stat().st_size for f in d.iterdir()) / 1e6
        wall, rss = run_report(d, base / f"report{days:g}.html")
        print(f"{days:>5g} {n:>10,} {size:>8.1f} {write_s:>8.1f} {wall:>9.1f} {rss:>13.0f}")


if __name__ == "__main__":
    main()
