#!/usr/bin/env python3
"""Benchmark of the raw chain: decode + block RMS + AKF banks + tacho + 4-order tracker + MCAP.

Builds RAW-mode captures with a tacho (the `faulty` motor at 1720 rpm, and the
`close_orders` run-up of Yeh, Pan & Le) with firmware_sim, replays each in a fresh
process through `cmsensord replay` (default config: orders 1x-4x from the
recursive tracker; the fixed-lag smoother is off by default) and prints real-time factor, throughput, CPU and peak
RSS.  Figures are ratios measured side by side in one run.

    python bench/bench_raw.py [--seconds 120] [--only faulty1] [--kernels both] [--tree before=DIR]
                              [--repeat 3]

``--kernels off`` (or ``both``) also replays with the compiled kernels unimportable (the
numpy fallbacks, as without a C compiler); ``--tree LABEL=DIR`` (repeatable) replays with
another checkout's code too, interleaved with this one: before/after figures of one run;
``--repeat N`` replays each capture N times per code and shows the best.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from bench_rms import best_of, replay_in_subprocess, trees  # noqa: E402  (one way to run and measure a replay)


def make_capture(path: Path, scenario: str, channels: int, seconds: float) -> None:
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    sc = make_scenario(scenario, n_channels=channels, duration_s=seconds, seed=1)
    Board(sc, BoardConfig(n_channels=channels, mode="raw", tacho=True)).write_capture(path, seconds)


CASES = {"faulty1": ("faulty", 1), "faulty4": ("faulty", 4), "runup1": ("close_orders", 1)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=120.0, help="simulated seconds per capture")
    ap.add_argument("--only", action="append", choices=sorted(CASES), help="only these captures")
    ap.add_argument("--kernels", choices=("on", "off", "both"), default="on")
    ap.add_argument("--tree", action="append", default=[], metavar="LABEL=DIR",
                    help="also replay with the code of another checkout, interleaved (e.g. before=/tmp/before)")
    ap.add_argument("--repeat", type=int, default=1, help="replays of each capture per code (the best is shown)")
    args = ap.parse_args()
    kernel_runs = {"both": (True, False), "on": (True,), "off": (False,)}[args.kernels]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for name in args.only or list(CASES):
            scenario, C = CASES[name]
            cap = tmp / f"{scenario}{C}.bin"
            make_capture(cap, scenario, C, args.seconds)
            for kernels in kernel_runs:
                runs: dict[str, list[dict]] = {}
                for _ in range(args.repeat):          # interleaved: each code sees the same machine
                    for label, tree in trees(args.tree):
                        out = tmp / f"out{scenario}{C}{label}{kernels}"
                        shutil.rmtree(out, ignore_errors=True)
                        runs.setdefault(label, []).append(
                            replay_in_subprocess(cap, out, trace=False, tree=tree, kernels=kernels))
                for label, _ in trees(args.tree):
                    r = best_of(runs[label])
                    rows.append((scenario, C, "yes" if kernels else "no", label, args.seconds / r["wall_s"],
                                 cap.stat().st_size / r["wall_s"] / 1e6, args.seconds / r["cpu_s"],
                                 r["peak_rss_mb"]))
    print(f"# RAW chain benchmark: {args.seconds:g} s simulated per capture, 25 kHz RAW + tacho, "
          "orders 1x-4x (recursive, the default config)\n")
    print("| scenario | channels | kernels | code | real-time factor | MB/s | RT factor per CPU-s | peak RSS MB |")
    print("| --- | ---: | --- | --- | ---: | ---: | ---: | ---: |")
    for sc, C, kern, label, rtf, mbs, cpu, rss in rows:
        print(f"| {sc} | {C} | {kern} | {label} | {rtf:,.0f}x | {mbs:.1f} | {cpu:,.0f}x | {rss:.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
