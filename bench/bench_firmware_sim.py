"""Benchmark of the simulated board: ``python bench/bench_firmware_sim.py`` prints a table.

Sample generation speed per scenario (1 and 4 channels, 1-s requests, best of
3 runs of 20 s) and the wall time of a 1-hour RMS capture (written to a
temporary file), as the board's performance budget asks: > 20 M samples/s per
channel, a 1-hour capture well under a minute.
"""

from __future__ import annotations

import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

import os
import tempfile
import time

from firmware_sim.board import Board, BoardConfig
from firmware_sim.scenarios import SCENARIOS, make_scenario


def _samples_per_s(name: str, n_channels: int, seconds: int = 20, repeats: int = 3) -> float:
    sc = make_scenario(name, n_channels=n_channels, seed=1)
    best = float("inf")
    for r in range(repeats):
        t = time.perf_counter()
        for k in range(r * seconds, (r + 1) * seconds):
            sc.samples(k * sc.fs, sc.fs)
        best = min(best, time.perf_counter() - t)
    return seconds * sc.fs / best


def main() -> int:
    print(f"{'scenario':<10} {'1 ch [M samples/s]':>19} {'4 ch [M samples/s/ch]':>22} {'1 h capture [s]':>16}")
    for name in SCENARIOS:
        one = _samples_per_s(name, 1) / 1e6
        four = _samples_per_s(name, 4) / 1e6
        fd, path = tempfile.mkstemp(suffix=".bin")
        os.close(fd)
        try:
            t = time.perf_counter()
            Board(make_scenario(name, seed=0), BoardConfig()).write_capture(path, 3600.0)
            cap = time.perf_counter() - t
        finally:
            os.unlink(path)
        print(f"{name:<10} {one:>19.1f} {four:>22.1f} {cap:>16.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
