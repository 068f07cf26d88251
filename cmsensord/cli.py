"""Command line: the daemon, ``--simulate``, ``replay``, ``record``, ``summary``.

    cmsensord --simulate [--scenario NAME --duration S --speed X --out DIR ...]
    cmsensord --config FILE              run the daemon on the configured port
    cmsensord replay CAPTURE [--config FILE] [--out DIR]
    cmsensord record --port DEV --out FILE [--duration S]
    cmsensord summary FILE.mcap

Errors a user can cause (bad arguments, a bad configuration value, a missing
device or capture, an unwritable log directory) end in one line on stderr and
exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Sequence

from cmsensord import __version__
from cmsensord.commission import add_calibrate_parser, run_calibrate
from cmsensord.config import Config, config_from_dict, config_to_dict, default_config, load_config
from cmsensord.errors import EXIT_CONFIG, EXIT_USAGE, CmsensordError, ConfigError, LinkError, SinkError
from cmsensord.link import FrameQueue, Progress, SerialReader, open_port_checked, read_capture
from cmsensord.pipeline import Processor
from cmsensord.protocol import Decoder
from cmsensord.sdnotify import Notifier
from cmsensord.sinks.mcap_sink import NOT_MCAP, summarize
from cmsensord.sinks.rotating import RotatingSink

log = logging.getLogger("cmsensord")


# --------------------------------------------------------------------------- helpers
def _scenarios_help() -> str:
    try:
        from firmware_sim.scenarios import SCENARIOS, make_scenario
    except ImportError:  # pragma: no cover
        return ""
    lines = []
    for name in SCENARIOS:
        try:
            desc = make_scenario(name, duration_s=60.0).description.split("\n")[0]
        except Exception:  # noqa: BLE001 - help text only
            desc = ""
        lines.append(f"  {name:<14} {desc}")
    return "scenarios (--scenario):\n" + "\n".join(lines)


def _setup_logging(verbose: bool, daemon: bool = True) -> None:
    """Events to stderr (the journal under systemd): INFO and up for the daemon, WARNING and
    up for the one-shot subcommands (they print their own summary), everything with -v."""
    level = logging.DEBUG if verbose else logging.INFO if daemon else logging.WARNING
    logging.basicConfig(level=level, format="%(levelname)s %(message)s", stream=sys.stderr)


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (and the pointer to --help), exit 2."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _open_sink(cfg: Config, metadata: dict[str, str]) -> RotatingSink:
    return RotatingSink(cfg.output, metadata=metadata)


def _route_sink_events(sink: RotatingSink, proc: Processor) -> None:
    """The sink's events (salvage, disk errors, retention) become the Processor's events:
    /cm/events, proc.events and the journal. Queued ones (salvage at start) go now."""
    sink.on_event = lambda kind, message, **fields: proc.event(kind, None, message, **fields)


def _status_line(proc: Processor, reader: SerialReader | None, queue: FrameQueue | None) -> str:
    parts = [f"[{proc.adc_seconds:8.1f} s]"]
    for v in proc.views:
        flags = "".join(str(a) for a in v.anomaly)
        parts.append(f"{v.name} S={v.severity:.1f} out/s={v.outliers_first:3d} F={flags}")
    if reader is not None:
        c = reader.decoder.counters
        parts.append(f"| rx {c.bytes_received} B, frames {sum(c.frames.values())}, "
                     f"lost {c.frames_lost}, crc {c.crc_failures}")
    if queue is not None:
        parts.append(f"q {len(queue)} drop {queue.drops}")
    return " ".join(parts)


def _summary(proc: Processor, paths: list[Path], wall_s: float) -> str:
    lines = [f"MCAP log: {p}" for p in paths] + [
             f"  {proc.adc_seconds:.1f} s of ADC time in {wall_s:.1f} s wall "
             f"({proc.observations} observations, {proc.missing_observations} missing, "
             f"{proc.frames_lost} frames lost)"]
    for v in proc.views:
        lines.append(f"  {v.name}: final severity {v.severity:.1f}, max {v.max_severity:.1f}, "
                     f"{v.failures} failure event(s), {v.decisions} decisions")
    if proc.event_counts:
        lines.append("  events: " + ", ".join(f"{k} {n}" for k, n in sorted(proc.event_counts.items())))
    return "\n".join(lines)


class _StopFlag:
    """SIGINT/SIGTERM set a flag the loop checks; a second signal is not needed."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signal: int | None = None
        self.reopen = False

    def install(self) -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._handler)

    def install_reopen(self) -> None:
        """SIGHUP sets ``reopen``; the loop then reopens the logs (for log rotation tools)."""
        signal.signal(signal.SIGHUP, self._hup)

    def _handler(self, signum, _frame) -> None:
        self.signal = signum
        self.event.set()

    def _hup(self, _signum, _frame) -> None:
        self.reopen = True              # only a flag: the loop does the work


# --------------------------------------------------------------------------- live loop
def run_live(cfg: Config, *, auto_channels: bool, duration_s: float | None = None,
             sim_done: threading.Event | None = None, capture_path: str | None = None,
             metadata: dict[str, str] | None = None) -> int:
    """The real-time loop: reader thread -> bounded queue -> Processor -> MCAP."""
    stop = _StopFlag()
    stop.install()
    stop.install_reopen()
    try:                                # before the sink: a bad path leaves nothing behind
        capture = open(capture_path, "wb") if capture_path else None
    except OSError as exc:
        raise SinkError(f"{capture_path}: cannot write the capture file: {exc.strerror or exc}") from None
    sink = _open_sink(cfg, metadata or {})
    queue = FrameQueue(cfg.link.queue_frames)
    reader = SerialReader(cfg.link.port, baud=cfg.link.baud, read_size=cfg.link.read_size,
                          queue=queue, capture=capture, reconnect_min_s=cfg.link.reconnect_min_s,
                          reconnect_max_s=cfg.link.reconnect_max_s)
    proc: Processor
    proc = Processor(cfg, sink, auto_channels=auto_channels,
                     link_counters=reader.decoder.counters.as_dict,
                     diagnostics=lambda: {"queue_depth": len(queue), "queue_drops": queue.drops,
                                          "lag_s": round(proc.lag_s(), 3)})
    t_start = time.monotonic()
    proc.event("start", None, f"cmsensord {__version__} on {cfg.link.port}")
    _route_sink_events(sink, proc)      # salvage at start, disk errors: events from now on
    log.info("effective settings: %s", json.dumps(config_to_dict(cfg), default=str))
    reader.start()
    notify = Notifier()                 # systemd Type=notify; does nothing without NOTIFY_SOCKET

    def service_state() -> str:         # STATUS=: the status line, and what the daemon waits for
        line = _status_line(proc, reader, queue)
        return line if reader.connected.is_set() else f"waiting for {cfg.link.port} | {line}"

    if notify.enabled:
        reader.connected.wait(0.2)      # a present port opens within ms: READY's STATUS says which
    notify.ready(service_state())
    next_status = time.monotonic() + 1.0
    stalled = False
    idle_since = None
    drops_seen = 0
    try:
        while not stop.event.is_set():
            notify.watchdog()           # only here: a loop stuck anywhere below stops the pings
            frames = queue.get(timeout=0.1)
            proc.handle(frames)
            while reader.events:
                wall_ns, kind, message = reader.events.popleft()
                proc.event(kind, None, message, wall_ns)
            if queue.drops != drops_seen:
                proc.event("queue_overflow", None, f"processing fell behind: {queue.drops - drops_seen} "
                           f"frame(s) dropped from the queue, oldest RAW blocks first ({queue.drops} "
                           f"in all, {queue.raw_drops} RAW)", count=queue.drops - drops_seen,
                           raw_total=queue.raw_drops)
                drops_seen = queue.drops
            now = time.monotonic()
            if stop.reopen:             # SIGHUP: finish the current file, start a new one
                stop.reopen = False
                sink.reopen()
            sink.tick()                 # flush by flush_s, fsync events and by fsync_s, retry a full disk
            if duration_s is not None and proc.board_seconds >= duration_s:
                break                   # the simulated board's clock reached the end of the run
            if frames:
                idle_since = None
                stalled = False
            else:
                idle_since = idle_since or now
                if sim_done is not None and sim_done.is_set() and now - idle_since > 1.0:
                    break               # the simulated board has sent everything and it is read
                if (not stalled and reader.connected.is_set()
                        and now - reader.last_data > cfg.link.stall_s and proc.anchor_ns is not None):
                    stalled = True
                    proc.event("link_stalled", None,
                               f"{cfg.link.port}: no bytes for {cfg.link.stall_s:g} s", time.time_ns())
            if now >= next_status:
                next_status = now + 1.0
                if cfg.output.status_line:
                    print(_status_line(proc, reader, queue), file=sys.stderr, flush=True)
                notify.status(service_state())
    finally:
        notify.stopping("stopping: closing the MCAP log")
        reader.stop()
        reader.join(timeout=2.0)
        proc.handle(queue.get(timeout=0))
        proc.finish()
        why = f"signal {signal.Signals(stop.signal).name}" if stop.signal else "end of run"
        proc.event("stop", None, f"cmsensord stopping ({why})")
        sink.close()
        if capture is not None:
            capture.close()
    print(_summary(proc, sink.paths, time.monotonic() - t_start), file=sys.stderr)
    if capture_path:
        print(f"  capture: {capture_path}", file=sys.stderr)
    return 0


# --------------------------------------------------------------------------- replay
def replay(path: str, cfg: Config, *, auto_channels: bool, metadata: dict[str, str] | None = None,
           quiet: bool = False, speed: float | None = None) -> tuple[int, Path, Processor]:
    """Process a capture file through the same decoder and Processor: as fast as possible,
    or paced at ``speed`` x the board's clock (1: real time)."""
    size = Path(path).stat().st_size if Path(path).is_file() else 0
    chunks = read_capture(path, chunk=1 << 16 if speed is None else 1 << 12)
    first = next(chunks, None)          # raises LinkError before any output file exists
    sink = _open_sink(cfg, {"source": str(path), **(metadata or {})})
    decoder = Decoder()
    proc = Processor(cfg, sink, auto_channels=auto_channels, link_counters=decoder.counters.as_dict)
    _route_sink_events(sink, proc)
    progress = Progress(size, f"replay {Path(path).name}")
    t0 = time.monotonic()
    try:
        if first is not None:
            proc.handle(decoder.feed(first))
            done = len(first)
            progress.update(done)
            for data in chunks:
                proc.handle(decoder.feed(data))
                done += len(data)
                progress.update(done, f"{proc.adc_seconds:.0f} s")
                if speed is not None:       # the board's clock at speed x the wall clock
                    wait = t0 + proc.adc_seconds / speed - time.monotonic()
                    if wait > 0:
                        time.sleep(wait)
        proc.handle(decoder.flush())
        proc.finish()
    finally:
        progress.close()
        out = sink.close()
    if not quiet:
        print(_summary(proc, sink.paths, time.monotonic() - t0), file=sys.stderr)
    return 0, out, proc


# --------------------------------------------------------------------------- record
def record(port: str, out: str, *, baud: int, duration_s: float | None) -> int:
    """Capture the raw bytes of a port to a file (PROTOCOL.md captured serial log)."""
    ser = open_port_checked(port, baud)
    stop = _StopFlag()
    stop.install()
    decoder = Decoder()             # only to show what is being captured
    t0 = time.monotonic()
    n = 0
    next_status = t0 + 1.0
    try:
        f = open(out, "wb")
    except OSError as exc:
        raise LinkError(f"{out}: cannot write capture: {exc.strerror or exc}") from None
    with f, ser:
        while not stop.event.is_set():
            if duration_s is not None and time.monotonic() - t0 >= duration_s:
                break
            try:
                data = ser.read(max(1, ser.in_waiting or 1))
            except (OSError, Exception) as exc:  # pyserial raises SerialException on unplug
                print(f"cmsensord record: {port}: {exc}; stopping", file=sys.stderr)
                break
            if data:
                f.write(data)
                n += len(data)
                decoder.feed(data)
            if time.monotonic() >= next_status:
                next_status += 1.0
                c = decoder.counters
                print(f"recorded {n} B, {sum(c.frames.values())} frames, crc errors {c.crc_failures}",
                      file=sys.stderr, flush=True)
    print(f"capture: {out} ({n} bytes)", file=sys.stderr)
    return 0


# --------------------------------------------------------------------------- simulate
#: order-tracker settings for the run-up scenarios of seed 001 (section 4.1): their components,
#: a -3 dB bandwidth of 20 Hz (r about 50 at the tracker rate) and the 0.1 s smoother, which
#: keeps the close orders within the paper's error bounds (tests/test_order_tracker.py)
RUNUP_ORDERS = {
    "close_orders": {"max_rpm": 3000.0, "smoother_lag_s": 0.1, "components": [
        {"name": "o1", "order": 1.0, "bandwidth_hz": 20.0},
        {"name": "o4", "order": 4.0, "bandwidth_hz": 20.0},
        {"name": "o4_2", "order": 4.2, "bandwidth_hz": 20.0}]},
    "whirl": {"max_rpm": 7000.0, "smoother_lag_s": 0.1, "components": [
        {"name": "o1", "order": 1.0, "bandwidth_hz": 5.0},
        {"name": "whirl", "order": 0.47, "bandwidth_hz": 5.0, "alarm_rms": 0.7},
        {"name": "whip", "freq_hz": 47.0, "bandwidth_hz": 5.0}]},
}


def simulate(args: argparse.Namespace) -> int:
    """Start firmware_sim on a pty and the daemon on that pty."""
    from firmware_sim.scenarios import SCENARIOS

    if args.scenario not in SCENARIOS:
        raise ConfigError("--scenario", None, f"unknown scenario; choose from {', '.join(SCENARIOS)}",
                          args.scenario)
    cfg = load_config(args.config, n_channels=args.channels) if args.config else default_config(args.channels)
    runup = args.scenario in RUNUP_ORDERS
    mode = args.mode or ("raw" if runup else "rms")
    tacho = args.tacho or runup
    if runup and not args.config:
        # the paper's validation signals: track their components (seed 001 section 4.1)
        cfg = dataclasses.replace(cfg, orders=config_from_dict(
            {"orders": RUNUP_ORDERS[args.scenario]}, source="--scenario").orders)
    out_dir = args.out or cfg.output.dir
    try:                                # before the simulator starts: a clear error first
        Path(out_dir).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SinkError(f"{out_dir}: cannot create the output directory: {exc.strerror or exc}") from None
    cfg = dataclasses.replace(cfg, output=dataclasses.replace(cfg.output, dir=out_dir,
                                                              akf_trace=cfg.output.akf_trace or args.akf_trace))
    cmd = [sys.executable, "-m", "firmware_sim", "--pty", "--scenario", args.scenario,
           "--duration", str(args.duration), "--speed", str(args.speed), "--seed", str(args.seed),
           "--channels", str(args.channels), "--mode", mode, "--hold"] + (["--tacho"] if tacho else [])
    sim = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                           start_new_session=True)
    try:
        line = sim.stdout.readline().strip()
        if not line.startswith("/dev/"):
            err = sim.stderr.read() if sim.poll() is not None else ""
            print(f"cmsensord: the simulator did not start: {line or err.strip()}", file=sys.stderr)
            return 1
        print(f"simulated board ({args.scenario}, {mode.upper()} mode{' + tacho' if tacho else ''}, "
              f"{args.channels} channel(s), seed {args.seed}) on "
              f"{line}; {args.duration:g} s at {args.speed:g}x real time", file=sys.stderr)
        cfg = dataclasses.replace(cfg, link=dataclasses.replace(cfg.link, port=line))
        capture = args.capture
        sim_done = threading.Event()

        def watch_sim() -> None:        # the simulator prints its stats when it has sent everything
            for out_line in sim.stdout:
                if out_line.startswith("{"):
                    sim_done.set()
            sim_done.set()

        threading.Thread(target=watch_sim, name="sim-watch", daemon=True).start()
        return run_live(cfg, auto_channels=False, duration_s=args.duration, sim_done=sim_done,
                        capture_path=capture,
                        metadata={"scenario": args.scenario, "seed": str(args.seed),
                                  "duration_s": str(args.duration)})
    finally:
        if sim.poll() is None:
            sim.terminate()
        try:
            sim.wait(timeout=3)
        except subprocess.TimeoutExpired:
            sim.kill()


# --------------------------------------------------------------------------- argparse
def build_parser(with_scenarios: bool = True) -> argparse.ArgumentParser:
    p = _Parser(
        prog="cmsensord",
        description="Condition-monitoring daemon: serial frames from a TM4C ADC board -> banks of "
                    "adaptive Kalman filters -> severity indices and events in MCAP logs.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(_scenarios_help() if with_scenarios else "") + "\n\nsubcommands: replay, record, vkf, summary (see "
                                   "`cmsensord SUBCOMMAND --help`)")
    p.add_argument("--version", action="version", version=f"cmsensord {__version__}")
    p.add_argument("--config", metavar="FILE", help="YAML configuration (see config/default.yaml)")
    p.add_argument("-v", "--verbose", action="store_true", help="log every event (debug level)")
    sim = p.add_argument_group("simulation (--simulate)")
    sim.add_argument("--simulate", action="store_true",
                     help="run a simulated ADC board on a pty and the daemon on it")
    sim.add_argument("--scenario", default="degrading", help="machine scenario (default degrading)")
    sim.add_argument("--duration", type=_positive, default=600.0,
                     help="simulated seconds; a scenario's shape stretches over it (default 600)")
    sim.add_argument("--speed", type=_positive, default=20.0,
                     help="x real time (default 20: 600 s simulated in 30 s)")
    sim.add_argument("--out", metavar="DIR", help="MCAP output directory (default output.dir)")
    sim.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    sim.add_argument("--channels", type=_channels, default=1, help="number of channels 1..8 (default 1)")
    sim.add_argument("--mode", choices=("rms", "raw"),
                     help="board mode (default: rms; raw for whirl and close_orders)")
    sim.add_argument("--tacho", action="store_true",
                     help="the board sends TACHO frames (default for whirl and close_orders)")
    sim.add_argument("--capture", metavar="FILE", help="also write the received bytes to a capture "
                     "file (with --simulate or --config)")
    sim.add_argument("--akf-trace", action="store_true", help="write /cm/<ch>/akf per observation")
    sub = p.add_subparsers(dest="command", metavar="{replay,record,vkf,calibrate,summary}", parser_class=_Parser)
    r = sub.add_parser("replay", help="process a captured serial log as fast as possible")
    r.add_argument("capture", help="capture file (the bytes as read from the port)")
    r.add_argument("--config", dest="sub_config", metavar="FILE", help="YAML configuration")
    r.add_argument("--out", dest="sub_out", metavar="DIR", help="MCAP output directory")
    r.add_argument("--akf-trace", dest="sub_trace", action="store_true",
                   help="write /cm/<ch>/akf per observation")
    pace = r.add_mutually_exclusive_group()
    pace.add_argument("--realtime", action="store_const", const=1.0, dest="sub_speed",
                      help="pace the replay at the board's clock (default: as fast as possible)")
    pace.add_argument("--speed", type=_positive, dest="sub_speed", metavar="X",
                      help="pace the replay at X times the board's clock")
    rec = sub.add_parser("record", help="capture the raw bytes of a serial port to a file")
    rec.add_argument("--port", required=True, help="serial device, e.g. /dev/ttyACM0")
    rec.add_argument("--out", dest="sub_out", required=True, metavar="FILE", help="capture file to write")
    rec.add_argument("--baud", type=int, default=921600)
    rec.add_argument("--duration", dest="sub_duration", type=_positive, help="seconds (default: until Ctrl-C)")
    v = sub.add_parser("vkf", help="replay a RAW capture and add the batch (zero-phase) Vold-Kalman "
                                   "orders of seed 003 beside the recursive ones")
    v.add_argument("capture", help="capture file in RAW mode with a tacho")
    v.add_argument("--config", dest="sub_config", metavar="FILE", help="YAML configuration (orders)")
    v.add_argument("--out", dest="sub_out", metavar="DIR", help="MCAP output directory")
    v.add_argument("--bandwidth", type=_positive, default=1.0,
                   help="-3 dB bandwidth [Hz] of the batch filter for every component (default 1)")
    v.add_argument("--poles", type=int, choices=(1, 2), default=2, help="1 or 2 poles (default 2)")
    add_calibrate_parser(sub)
    s = sub.add_parser("summary", help="summarise an MCAP log (also a truncated .mcap.part)")
    s.add_argument("mcap", help="MCAP file")
    s.add_argument("--json", action="store_true", help="print the summary as JSON")
    return p


def _positive(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not v > 0 or v != v or v == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return v


def _channels(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer 1..8, got {text!r}") from None
    if not 1 <= v <= 8:
        raise argparse.ArgumentTypeError(f"expected an integer 1..8, got {v}")
    return v


def _config_for(path: str | None) -> tuple[Config, bool]:
    """Load a config; auto_channels when the file does not list channels."""
    if path is None:
        return default_config(1), True
    cfg = load_config(path)
    import yaml  # only to see whether the file lists channels
    try:
        raw = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
    except (OSError, yaml.YAMLError):
        raw = {}
    return cfg, not (isinstance(raw, dict) and raw.get("channels"))


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(with_scenarios="-h" in argv or "--help" in argv)
    args = parser.parse_args(argv)
    _setup_logging(args.verbose, daemon=args.command is None)
    try:
        if args.command == "summary":
            if not Path(args.mcap).is_file():
                what = "is a directory, not an MCAP file" if Path(args.mcap).is_dir() else "file not found"
                print(f"cmsensord: {args.mcap}: {what}", file=sys.stderr)
                return EXIT_USAGE
            info = summarize(args.mcap)
            if info["error"] == NOT_MCAP:
                print(f"cmsensord: {args.mcap}: {NOT_MCAP}", file=sys.stderr)
                return EXIT_USAGE
            try:
                print(json.dumps(info, indent=2, default=str) if args.json else _format_summary(info),
                      flush=True)
            except BrokenPipeError:     # `cmsensord summary FILE | head`: the reader has enough
                os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 0
        if args.command == "calibrate":
            return run_calibrate(args)
        if args.command == "record":
            return record(args.port, args.sub_out, baud=args.baud, duration_s=args.sub_duration)
        if args.command == "vkf":
            from cmsensord.batch import batch_orders

            cfg, _ = _config_for(args.sub_config)
            if args.sub_out:
                cfg = dataclasses.replace(cfg, output=dataclasses.replace(cfg.output, dir=args.sub_out))
            paths, info = batch_orders(args.capture, cfg, bandwidth_hz=args.bandwidth, poles=args.poles)
            for p in paths:
                print(f"MCAP log: {p}", file=sys.stderr)
            print(f"  batch VKF: {info}", file=sys.stderr)
            return 0
        if args.command == "replay":
            cfg, auto = _config_for(args.sub_config)
            if args.sub_out or args.sub_trace:
                cfg = dataclasses.replace(cfg, output=dataclasses.replace(
                    cfg.output, dir=args.sub_out or cfg.output.dir,
                    akf_trace=cfg.output.akf_trace or args.sub_trace))
            return replay(args.capture, cfg, auto_channels=auto, speed=args.sub_speed)[0]
        if args.simulate:
            return simulate(args)
        if args.config:
            cfg, auto = _config_for(args.config)
            return run_live(cfg, auto_channels=auto, capture_path=args.capture)
        print("cmsensord: nothing to do: give --simulate, --config FILE or a subcommand "
              "(see cmsensord --help)", file=sys.stderr)
        return EXIT_USAGE
    except ConfigError as exc:
        if exc.source.startswith("--"):         # a command-line option: a usage error
            print(f"cmsensord: {exc}", file=sys.stderr)
            return EXIT_USAGE
        print(f"cmsensord: configuration error: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    except SinkError as exc:            # the output directory is a setting (output.dir / --out)
        print(f"cmsensord: output error: {exc} (set output.dir or --out to a writable directory)",
              file=sys.stderr)
        return EXIT_CONFIG
    except LinkError as exc:
        print(f"cmsensord: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except CmsensordError as exc:
        print(f"cmsensord: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        return 130


def _format_summary(info: dict) -> str:
    lines = []
    for k, v in info.items():
        if isinstance(v, dict):
            lines.append(f"{k}:")
            for kk, vv in v.items():
                lines.append(f"  {kk}: {vv}")
        elif isinstance(v, list):
            lines.append(f"{k}: {len(v)} item(s)")
            for item in v[:50]:
                lines.append(f"  {item}")
        else:
            lines.append(f"{k}: {v}")
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
