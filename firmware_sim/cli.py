"""Command line of the simulated board: write a capture file or serve a pty.

    python -m firmware_sim --list
    python -m firmware_sim --scenario degrading --duration 3600 --out capture.bin
    python -m firmware_sim --scenario faulty --channels 2 --tacho --pty --speed 10
    python -m firmware_sim --scenario close_orders --mode raw --tacho --out cap.bin --truth truth.npz
    python -m firmware_sim --scenario whirl --mode raw --tacho --tacho-missed 0.01 --tacho-jitter 2 --out w.bin

``--out`` writes the bytes as fast as possible and prints a one-line summary.
``--pty`` prints the slave device path as the first line of stdout (flushed),
then streams paced at ``--speed`` x real time until ``--duration`` or
SIGINT/SIGTERM, and prints the link statistics; a reader that falls behind loses the
bytes that do not fit in the pty, unless ``--flow-control`` makes the board wait for it
(what ``cmsensord --simulate`` uses). Bad arguments give a one-line
error and exit code 2. ``--truth`` writes the true waveforms (t, rpm, turns,
each component of the run-up scenarios) of channel 0 to an .npz file
(:func:`firmware_sim.scenarios.write_truth`). When the stream needs more
bytes per second than a UART at ``--baud`` carries (docs/PROTOCOL.md's byte
budget), one warning line goes to stderr (a pty has no baud limit, so for
``--pty`` it says that a real UART would not carry the stream).
"""

from __future__ import annotations

import argparse
import ast
import json
import math
import os
import select
import signal
import sys
import threading
import time

from cmsensord import __version__

from .board import DEFAULT_BAUD, Board, BoardConfig, link_budget
from .scenarios import SCENARIOS, make_scenario, write_truth

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


def _fault(text: str) -> float | tuple[int, ...]:
    """A probability ("0.01", with a decimal point) or pulse indices ("5" or "5,17,300": integers)."""
    t = text.strip().strip("()[]")
    try:
        if "," in t or t.isdigit():
            return tuple(int(v) for v in t.split(",") if v.strip())
        return float(t)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a probability or pulse indices like 5,17, got {text!r}") from None


def _blocks(text: str) -> tuple[int, ...]:
    """Block indices ("5" or "5,17,300": integers from 0)."""
    try:
        blocks = tuple(int(v) for v in text.strip().strip("()[]").split(",") if v.strip())
    except ValueError:
        blocks = (-1,)
    if not blocks or min(blocks) < 0:
        raise argparse.ArgumentTypeError(f"expected block indices like 5,17 (integers from 0), got {text!r}")
    return blocks


def _build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="firmware_sim", description="The simulated TM4C1294 ADC board of cmsensord "
                "(docs/PROTOCOL.md): writes a capture file or serves a pseudo-terminal.")
    p.add_argument("--version", action="version", version=f"firmware_sim (cmsensord {__version__})")
    p.add_argument("--list", action="store_true", help="list the scenarios and exit")
    p.add_argument("--scenario", help=f"machine model: {', '.join(SCENARIOS)}")
    p.add_argument("--channels", type=int, default=1,
                   help="channels, 1..8 (default 1; the *_mic scenarios' microphone is channel 1: give 2)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--duration", type=float, default=None,
                   help="seconds to generate; also the scenario's time axis (degrading). "
                        "Default: 3600 for --out (a run-up: its own length, whirl 180 s, "
                        "close_orders 5 s), endless for --pty")
    p.add_argument("--mode", choices=("rms", "raw"), default="rms",
                   help="RMS frames or RAW blocks (default rms, for every scenario: the run-ups' orders "
                   "need --mode raw --tacho, which cmsensord --simulate gives them)")
    p.add_argument("--tacho", action="store_true", help="send a TACHO frame per block (default: none)")
    p.add_argument("--ppr", type=int, default=1, help="tacho pulses per revolution, 1..255 (default 1)")
    p.add_argument("--tacho-missed", type=_fault, default=0.0, metavar="P|M,M,..",
                   help="encoder fault: probability a pulse is missed (0.01), or the pulse indices "
                        "to drop (integers: 5,17; pulse 0 is at t = 0)")
    p.add_argument("--tacho-extra", type=_fault, default=0.0, metavar="P|M,M,..",
                   help="encoder fault: probability of a spurious pulse after a pulse, or the pulse indices")
    p.add_argument("--tacho-jitter", type=float, default=0.0, metavar="SAMPLES",
                   help="encoder fault: std of the edge-time jitter in samples (default 0)")
    p.add_argument("--resend-blocks", type=_blocks, default=(), metavar="B,B,..",
                   help="board fault: the blocks (indices from 0) whose frames it sends twice, as a "
                        "firmware that sends a DMA buffer again")
    p.add_argument("--resend-new-seq", action="store_true",
                   help="with --resend-blocks: the frames sent again carry the next seqs (the buffer sent "
                        "again with a fresh header)")
    p.add_argument("--baud", type=float, default=DEFAULT_BAUD,
                   help=f"UART rate the stream must fit (default {DEFAULT_BAUD}); warns when it does not")
    p.add_argument("--truth", metavar="FILE.npz",
                   help="also write the true waveforms (t, rpm, turns, components) of channel 0")
    p.add_argument("--truth-rate", type=float, default=None, metavar="HZ",
                   help="sample rate of the truth file (default: the board's 25 kHz)")
    p.add_argument("--byte-error-rate", type=float, default=0.0, metavar="P",
                   help="line noise: each byte is flipped, dropped or doubled by a glitch with "
                        "probability P (e.g. 1e-3); with --pty or --out")
    p.add_argument("--faults-out", metavar="FILE.jsonl",
                   help="write the injected line faults (offset in the clean stream, kind) here")
    p.add_argument("--link", metavar="PATH",
                   help="with --pty: also publish the port as this symlink (a stable name, as a "
                        "udev rule gives); removed when the board goes away")
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
    p.add_argument("--flow-control", action="store_true",
                   help="with --pty: wait for a slow reader (hardware handshake); without it (the "
                        "default) the bytes that do not fit are dropped, as by a UART without flow control")
    p.add_argument("--start-on-stdin", action="store_true",
                   help="with --pty: start the stream when a line (or EOF) comes on stdin, e.g. once "
                        "the reader has opened the port (pyserial discards what waits at its open)")
    return p


def _list() -> int:
    width = max(map(len, SCENARIOS))
    for name, factory in SCENARIOS.items():
        print(f"{name:<{width}}  {factory.description}")
    return 0


def _check_args(args: argparse.Namespace) -> None:
    """The rules between options that argparse does not express: _UsageError naming the option."""
    if not args.scenario:
        raise _UsageError("--scenario is required (see --list)")
    if not args.out and not args.pty:
        raise _UsageError("give --out FILE or --pty")
    if args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
        raise _UsageError(f"--duration must be a positive number of seconds, got {args.duration}")
    if not args.speed >= 0:
        raise _UsageError(f"--speed must be >= 0, got {args.speed}")
    if not 0.0 <= args.byte_error_rate <= 1.0:
        raise _UsageError(f"--byte-error-rate must be a probability 0..1, got {args.byte_error_rate}")
    if args.faults_out and not args.byte_error_rate:
        raise _UsageError("--faults-out needs --byte-error-rate")
    if args.resend_new_seq and not args.resend_blocks:
        raise _UsageError("--resend-new-seq needs --resend-blocks")
    if args.link and not args.pty:
        raise _UsageError("--link needs --pty")
    if args.flow_control and not args.pty:
        raise _UsageError("--flow-control needs --pty")


def main(argv: list[str] | None = None) -> int:
    truth = None                                   # (path, seconds) of --truth
    try:
        args = _build_parser().parse_args(argv)
        if args.list:
            return _list()
        _check_args(args)
        natural = getattr(SCENARIOS.get(args.scenario), "natural_duration_s", None)
        # the scenario's length; what is sent: all of it for --out, until stopped for --pty
        span = args.duration if args.duration is not None else (natural or 3600.0)
        duration = span if args.out or args.duration is not None else None
        scenario = make_scenario(args.scenario, n_channels=args.channels, seed=args.seed,
                                 duration_s=span, **dict(args.param))
        config = BoardConfig(mode=args.mode, n_channels=args.channels, fs=scenario.fs,
                             tacho=args.tacho, ppr=args.ppr, t0_start=args.t0_start,
                             tacho_missed=args.tacho_missed, tacho_extra=args.tacho_extra,
                             tacho_jitter=args.tacho_jitter, resent_blocks=args.resend_blocks,
                             resend_new_seq=args.resend_new_seq,
                             scale=getattr(scenario, "board_scale", None))   # Pa/count for a microphone
        board = Board(scenario, config)
        if args.truth_rate is not None and not args.truth:
            raise _UsageError("--truth-rate needs --truth FILE")
        if args.truth:
            truth_duration = duration if duration is not None else natural
            if truth_duration is None:
                raise _UsageError("--truth with --pty needs --duration")
            truth = (args.truth, truth_duration)
        _, fits, budget = link_budget(args.mode, args.channels, config.block_len, config.fs,
                                      args.tacho, args.baud,
                                      tacho_edges=_tacho_edges_per_block(scenario, config, duration))
    except (_UsageError, ValueError, TypeError) as exc:
        print(f"firmware_sim: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if not fits:
        where = ("the pty has no baud limit, but a real UART would not carry this stream" if args.pty
                 else "the capture holds it all, but a real UART would not carry this stream")
        print(f"firmware_sim: warning: {budget}; {where}", file=sys.stderr, flush=True)
    if truth is not None:
        status = _write_truth(scenario, *truth, rate=args.truth_rate)
        if status:
            return status

    injector = None
    if args.byte_error_rate:
        from .faults import StreamInjector

        injector = StreamInjector(args.byte_error_rate, seed=args.seed)
    if args.out:
        return _write_out(board, args, span, injector)
    return _serve_pty(board, speed=args.speed, duration=duration, hold=args.hold,
                      link=args.link, injector=injector, faults_out=args.faults_out,
                      flow_control=args.flow_control, start_on_stdin=args.start_on_stdin)


def _write_truth(scenario, path: str, duration: float, *, rate) -> int:
    """--truth: the true waveforms to ``path``; 0, or the exit status after a one-line error."""
    try:
        write_truth(scenario, path, duration, rate=rate)
    except ValueError as exc:
        print(f"firmware_sim: error: --truth: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:
        print(f"firmware_sim: error: cannot write {path}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    return 0


def _write_out(board: Board, args: argparse.Namespace, duration: float, injector) -> int:
    """--out: ``duration`` seconds as fast as possible, then a one-line summary; the exit status."""
    t = time.perf_counter()
    try:
        if injector is None:
            counts = board.write_capture(args.out, duration)
        else:
            counts = _write_noisy_capture(board, args.out, duration, injector)
            if args.faults_out:
                injector.write_records(args.faults_out)
    except OSError as exc:
        print(f"firmware_sim: error: cannot write {args.out}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    dt = time.perf_counter() - t
    print(f"wrote {args.out}: {args.scenario}, {args.channels} ch, {args.mode}, {duration:g} s, "
          f"{counts['blocks']} blocks, {counts['frames']} frames, {counts['bytes']} bytes in {dt:.1f} s")
    return 0


def _write_noisy_capture(board: Board, path: str, duration: float, injector) -> dict:
    """A capture with line noise: each block's bytes through the injector."""
    counts = {"blocks": 0, "frames": 0, "bytes": 0}
    with open(path, "wb") as fh:
        for data, n_frames in board.iter_blocks(board.n_blocks_for(duration)):
            out = injector(data)
            fh.write(out)
            counts["blocks"] += 1
            counts["frames"] += n_frames
            counts["bytes"] += len(out)
    return counts


def _tacho_edges_per_block(scenario, config: BoardConfig, duration: float | None) -> int:
    """Edges per TACHO frame for the byte budget: the table's 4, or more for a fast shaft."""
    if not config.tacho:
        return 0
    import numpy as np

    span = duration if duration is not None else max(scenario.duration_s, 1.0)
    top_hz = float(np.max(scenario.shaft_hz(np.linspace(0.0, span, 2001))))
    return max(4, math.ceil(config.ppr * top_hz * config.block_len / config.fs))


def _serve_pty(board: Board, *, speed: float, duration: float | None, hold: bool = False,
               link: str | None = None, injector=None, faults_out: str | None = None,
               flow_control: bool = False, start_on_stdin: bool = False) -> int:
    from .pty_link import PtyEndpoint

    stop = _stop_on_signals()
    _stop_when_orphaned(stop)
    try:
        with PtyEndpoint(link=link, injector=injector, flow_control=flow_control) as ep:
            print(ep.path, flush=True)
            if start_on_stdin and not _wait_for_stdin(stop):
                return 0
            stats = ep.run(board, speed=speed, duration_s=duration, stop=stop)
            if injector is not None and faults_out:
                injector.write_records(faults_out)
            print(json.dumps({"stats": stats.as_dict()}), flush=True)
            if hold:
                stop.wait()
    except OSError as exc:
        print(f"firmware_sim: error: pty: {exc}", file=sys.stderr)
        return 1
    return 0


def _stop_when_orphaned(stop: threading.Event) -> None:
    """Set ``stop`` when the process that started the simulator has gone (it is then another's
    child): a ``cmsensord --simulate`` killed with SIGKILL leaves no board streaming or holding
    its pty behind it."""
    parent = os.getppid()

    def _watch() -> None:
        while not stop.wait(0.5):
            if os.getppid() != parent:
                stop.set()

    threading.Thread(target=_watch, name="parent", daemon=True).start()


def _wait_for_stdin(stop: threading.Event) -> bool:
    """Wait for a line (or EOF) on stdin; False when ``stop`` is set first."""
    while not stop.is_set():
        if select.select([sys.stdin], [], [], 0.1)[0]:
            sys.stdin.readline()
            return True
    return False


def _stop_on_signals() -> threading.Event:
    """An event set by SIGINT or SIGTERM, from a thread that reads the signal wakeup fd.

    The Python handler does nothing: a handler calling ``Event.set`` in the main thread
    could deadlock when the signal lands while that thread holds the event's own lock
    (inside ``wait``, which the paced stream calls a thousand times a second at 10x).
    """
    stop = threading.Event()
    rfd, wfd = os.pipe()
    os.set_blocking(wfd, False)
    signal.set_wakeup_fd(wfd, warn_on_full_buffer=False)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda _signum, _frame: None)

    def _wait() -> None:
        while not set(os.read(rfd, 64)) & {signal.SIGINT, signal.SIGTERM}:
            pass
        stop.set()

    threading.Thread(target=_wait, name="signals", daemon=True).start()
    return stop
