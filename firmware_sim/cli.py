"""Command line of the simulated board: write a capture file or serve a pty.

    python -m firmware_sim --list
    python -m firmware_sim --scenario degrading --duration 3600 --out capture.bin
    python -m firmware_sim --scenario faulty --channels 2 --tacho --pty --speed 10

``--out`` writes the bytes as fast as possible and prints a one-line summary.
``--pty`` prints the slave device path as the first line of stdout (flushed),
then streams paced at ``--speed`` x real time until ``--duration`` or
SIGINT/SIGTERM, and prints the link statistics. Bad arguments give a one-line
error and exit code 2.
"""

from __future__ import annotations

import argparse
import ast
import json
import math
import signal
import sys
import threading
import time

from .board import Board, BoardConfig
from .scenarios import SCENARIOS, make_scenario

__all__ = ["main"]

EXIT_USAGE = 2


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, no usage dump
        raise _UsageError(message)


def _param(text: str) -> tuple[str, object]:
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    try:
        parsed = ast.literal_eval(value.strip())
    except (ValueError, SyntaxError):
        raise argparse.ArgumentTypeError(f"value of {key!r} is not a number or tuple: {value!r}") from None
    return key.strip(), parsed


def _build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="firmware_sim", description="The simulated TM4C1294 ADC board of cmsensord "
                "(PROTOCOL.md): writes a capture file or serves a pseudo-terminal.")
    p.add_argument("--list", action="store_true", help="list the scenarios and exit")
    p.add_argument("--scenario", help=f"machine model: {', '.join(SCENARIOS)}")
    p.add_argument("--channels", type=int, default=1, help="accelerometer channels, 1..8 (default 1)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--duration", type=float, default=None,
                   help="seconds to generate; also the scenario's time axis (degrading). "
                        "Default: 3600 for --out, endless for --pty")
    p.add_argument("--mode", choices=("rms", "raw"), default="rms", help="RMS frames or RAW blocks")
    p.add_argument("--tacho", action="store_true", help="send a TACHO frame per block")
    p.add_argument("--ppr", type=int, default=1, help="tacho pulses per revolution, 1..255 (default 1)")
    p.add_argument("--t0-start", type=int, default=0, help="initial sample counter (e.g. 4294967000 to wrap soon)")
    p.add_argument("--param", action="append", type=_param, default=[], metavar="KEY=VALUE",
                   help="scenario parameter, repeatable (e.g. --param impact_peak=8)")
    out = p.add_mutually_exclusive_group()
    out.add_argument("--out", metavar="FILE", help="write a capture file as fast as possible")
    out.add_argument("--pty", action="store_true", help="serve a pty; its path is the first stdout line")
    p.add_argument("--hold", action="store_true",
                   help="with --pty: after --duration keep the pty open (idle) until SIGINT/SIGTERM, "
                        "so the reader sees the end of the data, not a disconnect")
    p.add_argument("--speed", type=float, default=1.0,
                   help="pty pacing, x real time (0 or inf: as fast as possible; default 1)")
    return p


def _list() -> int:
    width = max(map(len, SCENARIOS))
    for name, factory in SCENARIOS.items():
        print(f"{name:<{width}}  {factory.description}")
    return 0


def main(argv: list[str] | None = None) -> int:
    try:
        args = _build_parser().parse_args(argv)
        if args.list:
            return _list()
        if not args.scenario:
            raise _UsageError("--scenario is required (see --list)")
        if not args.out and not args.pty:
            raise _UsageError("give --out FILE or --pty")
        if args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
            raise _UsageError(f"--duration must be a positive number of seconds, got {args.duration}")
        if not args.speed >= 0:
            raise _UsageError(f"--speed must be >= 0, got {args.speed}")
        duration = args.duration if args.duration is not None else (3600.0 if args.out else None)
        scenario = make_scenario(args.scenario, n_channels=args.channels, seed=args.seed,
                                 duration_s=duration if duration is not None else 3600.0,
                                 **dict(args.param))
        config = BoardConfig(mode=args.mode, n_channels=args.channels, fs=scenario.fs,
                             tacho=args.tacho, ppr=args.ppr, t0_start=args.t0_start)
        board = Board(scenario, config)
    except (_UsageError, ValueError, TypeError) as exc:
        print(f"firmware_sim: error: {exc}", file=sys.stderr)
        return EXIT_USAGE

    if args.out:
        t = time.perf_counter()
        try:
            counts = board.write_capture(args.out, duration)
        except OSError as exc:
            print(f"firmware_sim: error: cannot write {args.out}: {exc.strerror or exc}", file=sys.stderr)
            return 1
        dt = time.perf_counter() - t
        print(f"wrote {args.out}: {args.scenario}, {args.channels} ch, {args.mode}, {duration:g} s, "
              f"{counts['blocks']} blocks, {counts['frames']} frames, {counts['bytes']} bytes in {dt:.1f} s")
        return 0
    return _serve_pty(board, speed=args.speed, duration=duration, hold=args.hold)


def _serve_pty(board: Board, *, speed: float, duration: float | None, hold: bool = False) -> int:
    from .pty_link import PtyEndpoint

    stop = threading.Event()

    def _on_signal(signum, frame):
        stop.set()

    old = {s: signal.signal(s, _on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with PtyEndpoint() as ep:
            print(ep.path, flush=True)
            stats = ep.run(board, speed=speed, duration_s=duration, stop=stop)
            print(json.dumps({"stats": stats.as_dict()}), flush=True)
            if hold:
                stop.wait()
    except OSError as exc:
        print(f"firmware_sim: error: pty: {exc}", file=sys.stderr)
        return 1
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    return 0
