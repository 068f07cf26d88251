#!/usr/bin/env python3
"""Benchmark of the raw chain: decode + block RMS + AKF banks + tacho + 4-order tracker + MCAP.

Builds RAW-mode captures with a tacho (the `faulty` motor at 1720 rpm, and the
`close_orders` run-up of Yeh, Pan & Le) with firmware_sim, replays each in a fresh
process through `cmsensord replay` (default config: orders 1x-4x, recursive
and smoothed outputs) and prints real-time factor, throughput, CPU and peak
RSS.  Figures are ratios measured side by side in one run.

    python bench/bench_raw.py [--seconds 120]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from bench_rms import replay_in_subprocess  # noqa: E402  (one way to run and measure a replay)


def make_capture(path: Path, scenario: str, channels: int, seconds: float) -> None:
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    sc = make_scenario(scenario, n_channels=channels, duration_s=seconds, seed=1)
    Board(sc, BoardConfig(n_channels=channels, mode="raw", tacho=True)).write_capture(path, seconds)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=120.0, help="simulated seconds per capture")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for scenario, C in (("faulty", 1), ("faulty", 4), ("close_orders", 1)):
            cap = tmp / f"{scenario}{C}.bin"
            make_capture(cap, scenario, C, args.seconds)
            r = replay_in_subprocess(cap, tmp / f"out{scenario}{C}", trace=False)
            rows.append((scenario, C, args.seconds / r["wall_s"], cap.stat().st_size / r["wall_s"] / 1e6,
                         args.seconds / r["cpu_s"], r["peak_rss_mb"]))
    print(f"# RAW chain benchmark: {args.seconds:g} s simulated per capture, 25 kHz RAW + tacho, "
          "orders 1x-4x (recursive + smoothed)\n")
    print("| scenario | channels | real-time factor | MB/s | RT factor per CPU-s | peak RSS MB |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for sc, C, rtf, mbs, cpu, rss in rows:
        print(f"| {sc} | {C} | {rtf:,.0f}x | {mbs:.1f} | {cpu:,.0f}x | {rss:.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
