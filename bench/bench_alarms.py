#!/usr/bin/env python3
"""Benchmark of the alarm manager: CPU per indicator interval, alone and in the daemon's chain.

1. :class:`cmsensord.monitor.alarms.Alarms` reading one channel's indicator record (and that
   interval's severity decision) against six rules (ISO zone velocity with delays, kurtosis
   latched, envelope RMS, BPFO line, acceleration RMS, severity index), operating state from
   the speed: microseconds per interval, and % of one core at one interval per second;
2. the RAW monitoring chain (Processor, no MCAP) over a simulated capture of the ``degrading``
   motor with a tacho, with and without those rules: CPU seconds, and the difference as % of
   one core (close to the run-to-run noise).

    python bench/bench_alarms.py [--seconds 30] [--intervals 20000]
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cmsensord.config import config_from_dict  # noqa: E402
from cmsensord.monitor import messages  # noqa: E402
from cmsensord.monitor.alarms import Alarms  # noqa: E402
from firmware_sim.board import Board, BoardConfig  # noqa: E402
from firmware_sim.scenarios import make_scenario  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_indicators import BEARING, processing_cpu  # noqa: E402

ALARMS = {
    "operating": {"source": "speed", "running_above": 600, "startup_suppress_s": 5},
    "rules": [
        {"name": "velocity", "indicator": "velocity_rms_mm_s", "alert_zone": "C", "danger_zone": "D",
         "on_delay_s": 10, "off_delay_s": 30},
        {"name": "kurtosis", "indicator": "kurtosis", "alert": 6, "danger": 10, "latch": True},
        {"name": "envelope", "indicator": "envelope_rms", "alert": 2.0, "danger": 5.0, "on_delay_s": 5},
        {"name": "bpfo", "indicator": "de.bpfo", "alert": 0.5, "danger": 1.0, "on_delay_s": 5},
        {"name": "accel", "indicator": "accel_rms", "alert": 3.0, "danger": 6.0},
        {"name": "severity", "indicator": "severity_index", "alert": 0.5, "danger": 0.9, "on_delay_s": 3},
    ]}


def record(k: int, v: float) -> messages.Message:
    return messages.indicators(k * 1_000_000_000, "ch0", {
        "mode": "raw", "interval_s": 1.0, "missing_fraction": 0.0, "speed_rpm": 1720.0, "speed_source": "tacho",
        "accel_rms": 0.7 * v, "accel_peak": 2.5 * v, "crest_factor": 3.6, "kurtosis": 3.0 + v,
        "velocity_rms_mm_s": 1.8 * v, "zone": "B", "envelope_rms": 0.3 * v, "velocity_band_hz": [10, 1000],
        "zone_boundaries_mm_s": [1.4, 2.8, 4.5], "envelope_band_hz": [2000, 10000],
        "bearings": [{"name": "de", "lines": {k: {"amplitude": 0.1 * v, "freq_hz": 100.0}
                                              for k in ("ftf", "bpfo", "bpfi", "bsf")}}], "bands": []})


def manager_us(n: int) -> float:
    cfg = config_from_dict({"alarms": ALARMS, "bearings": [BEARING]})
    alarms = Alarms(cfg, lambda: ("ch0",))
    recs = [record(k, 1.0 + 3.0 * ((k // 50) % 2)) for k in range(n)]      # alarms come and go
    sev = [messages.Message("/cm/ch0/severity", "severity", m.stamp_ns, {"channel": "ch0", "severity_index": 0.2})
           for m in recs]
    t = time.process_time()
    for m, s in zip(recs, sev):
        alarms.see(m)
        alarms.see(s)
    return (time.process_time() - t) / n * 1e6


def chain_cpu(data: bytes, rules: bool) -> float:
    return processing_cpu({"bearings": [BEARING], **({"alarms": ALARMS} if rules else {})}, data)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--intervals", type=int, default=20000)
    args = ap.parse_args()
    logging.disable(logging.CRITICAL)          # the chain's alarm events would go to stderr
    us = manager_us(args.intervals)
    print(f"alarm manager, 6 rules, 1 channel: {us:.1f} us per interval = {us / 1e4:.4f} % of a core "
          "at 1 interval/s\n")
    sc = make_scenario("degrading", n_channels=1, duration_s=args.seconds, seed=1)
    data = Board(sc, BoardConfig(n_channels=1, mode="raw", tacho=True)).generate(args.seconds)
    print(f"RAW chain over {args.seconds:g} s of the degrading motor with a tacho, 1 channel (CPU s, best of 3)\n")
    print("| without rules | with 6 rules | added CPU % of a core |")
    print("| ---: | ---: | ---: |")
    off = min(chain_cpu(data, False) for _ in range(3))
    on = min(chain_cpu(data, True) for _ in range(3))
    print(f"| {off:.2f} | {on:.2f} | {100 * (on - off) / args.seconds:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
