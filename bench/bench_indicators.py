#!/usr/bin/env python3
"""Benchmark of the vibration indicators: CPU per channel-second, alone and in the daemon's chain.

1. ``compute`` of one 1-s interval at 25 kHz (statistics, velocity, ISO zone, envelope with
   one bearing's 8 lines, two bands), best of many, in ms and as % of one core per channel;
2. the RAW monitoring chain (Processor, no MCAP) over a simulated capture of the ``faulty``
   motor with a tacho, with ``indicators.enabled`` true and false, CPU seconds per
   board second, and the difference as % of one core.

    python bench/bench_indicators.py [--seconds 30] [--channels 1 4]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cmsensord.config import config_from_dict  # noqa: E402
from cmsensord.dsp.indicators import Band, Bearing, Setup, compute  # noqa: E402
from cmsensord.dsp.indicators.bearings import Geometry  # noqa: E402
from cmsensord.dsp.indicators.envelope import default_band  # noqa: E402
from cmsensord.monitor.processor import Processor  # noqa: E402
from cmsensord.protocol import Decoder  # noqa: E402
from firmware_sim.board import Board, BoardConfig  # noqa: E402
from firmware_sim.scenarios import make_scenario  # noqa: E402

FS = 25000
BEARING = {"name": "de", "channel": "ch0", "elements": 9, "ball_diameter": 9.525, "pitch_diameter": 46.0}


class NullSink:
    def write(self, topic, schema, stamp_ns, msg) -> None:
        pass


def compute_ms(repeat: int = 50) -> float:
    x = np.random.default_rng(0).normal(size=FS)
    s = Setup(FS, (10.0, 1000.0), default_band(FS), bearings=(Bearing("de", Geometry(9, 9.525, 46.0)),),
              bands=(Band("low", 10, 1000), Band("1x", 0.8, 1.2, orders=True)))
    best = np.inf
    for _ in range(repeat):
        t = time.process_time()
        compute(x, s, 28.66)
        best = min(best, time.process_time() - t)
    return best * 1e3


def chain_cpu(data: bytes, channels: int, enabled: bool) -> float:
    return processing_cpu({"indicators": {"enabled": enabled}, "bearings": [BEARING],
                           "channels": [{"name": f"ch{i}"} for i in range(channels)]}, data)


def processing_cpu(config: dict, data: bytes) -> float:
    """CPU seconds of the Processor (no MCAP) over the capture bytes ``data``, in 500-frame batches."""
    cfg = config_from_dict(config)
    frames = Decoder().feed(data)
    proc = Processor(cfg, NullSink(), clock_ns=lambda: 0)
    t = time.process_time()
    for i in range(0, len(frames), 500):
        proc.handle(frames[i:i + 500])
    proc.finish()
    return time.process_time() - t


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--channels", type=int, nargs="*", default=[1, 4])
    args = ap.parse_args()
    ms = compute_ms()
    print(f"compute() of one 1-s interval at 25 kHz: {ms:.2f} ms = {ms / 10:.2f} % of a core per channel\n")
    print(f"RAW chain over {args.seconds:g} s of the faulty motor with a tacho (CPU s, best of 3 runs)\n")
    print("| channels | without indicators | with | added CPU % of a core |")
    print("| ---: | ---: | ---: | ---: |")
    for C in args.channels:
        sc = make_scenario("faulty", n_channels=C, duration_s=args.seconds, seed=1)
        data = Board(sc, BoardConfig(n_channels=C, mode="raw", tacho=True)).generate(args.seconds)
        off = min(chain_cpu(data, C, False) for _ in range(3))
        on = min(chain_cpu(data, C, True) for _ in range(3))
        print(f"| {C} | {off:.2f} | {on:.2f} | {100 * (on - off) / args.seconds:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
