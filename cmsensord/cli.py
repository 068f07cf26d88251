"""Command line: argparse, dispatch to :mod:`cmsensord.service`, errors -> exit status.

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
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

from cmsensord import __version__
from cmsensord.argtypes import count, positive
from cmsensord.commission import add_calibrate_parser, run_calibrate
from cmsensord.config import Config, default_config, load_config
from cmsensord.errors import EXIT_CONFIG, EXIT_USAGE, CmsensordError, ConfigError, LinkError, SinkError
from cmsensord.service.live import run_live
from cmsensord.service.record import record
from cmsensord.service.replay import replay
from cmsensord.service.simulate import RUNUP_ORDERS, SimulateOptions, simulate
from cmsensord.service.summary import summary

__all__ = ["main", "build_parser", "RUNUP_ORDERS"]

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


# --------------------------------------------------------------------------- argparse
def build_parser(with_scenarios: bool = True) -> argparse.ArgumentParser:
    p = _Parser(
        prog="cmsensord",
        description="Condition-monitoring daemon: serial frames from a TM4C ADC board -> banks of "
                    "adaptive Kalman filters -> severity indices and events in MCAP logs.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(_scenarios_help() if with_scenarios else "") + "\n\nsubcommands: replay, record, vkf, summary, "
                                   "ack, status (see `cmsensord SUBCOMMAND --help`)")
    p.add_argument("--version", action="version", version=f"cmsensord {__version__}")
    p.add_argument("--config", metavar="FILE", help="YAML configuration (see config/default.yaml)")
    p.add_argument("-v", "--verbose", action="store_true", help="log every event (debug level)")
    sim = p.add_argument_group("simulation (--simulate)")
    sim.add_argument("--simulate", action="store_true",
                     help="run a simulated ADC board on a pty and the daemon on it")
    sim.add_argument("--scenario", default="degrading", help="machine scenario (default degrading)")
    sim.add_argument("--duration", type=positive, default=600.0,
                     help="simulated seconds; a scenario's shape stretches over it (default 600)")
    sim.add_argument("--speed", type=positive, default=20.0,
                     help="x real time (default 20: 600 s simulated in 30 s)")
    sim.add_argument("--out", metavar="DIR", help="MCAP output directory (default output.dir)")
    sim.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    sim.add_argument("--channels", type=count(1, 8), default=1, help="number of channels 1..8 (default 1)")
    sim.add_argument("--mode", choices=("rms", "raw"),
                     help="board mode (default: rms; raw for whirl and close_orders)")
    sim.add_argument("--tacho", action="store_true",
                     help="the board sends TACHO frames (default for whirl and close_orders)")
    sim.add_argument("--capture", metavar="FILE", help="also write the received bytes to a capture "
                     "file (with --simulate or --config)")
    sim.add_argument("--akf-trace", action="store_true", help="write /cm/<ch>/akf per observation")
    sub = p.add_subparsers(dest="command", metavar="{replay,record,import,calibrate,vkf,summary,ack,status}",
                           parser_class=_Parser)
    r = sub.add_parser("replay", help="process a captured serial log as fast as possible")
    r.add_argument("capture", help="capture file (the bytes as read from the port)")
    r.add_argument("--config", dest="sub_config", metavar="FILE", help="YAML configuration")
    r.add_argument("--out", dest="sub_out", metavar="DIR", help="MCAP output directory")
    r.add_argument("--akf-trace", dest="sub_trace", action="store_true",
                   help="write /cm/<ch>/akf per observation")
    pace = r.add_mutually_exclusive_group()
    pace.add_argument("--realtime", action="store_const", const=1.0, dest="sub_speed",
                      help="pace the replay at the board's clock (default: as fast as possible)")
    pace.add_argument("--speed", type=positive, dest="sub_speed", metavar="X",
                      help="pace the replay at X times the board's clock")
    rec = sub.add_parser("record", help="capture the raw bytes of a serial port to a file")
    rec.add_argument("--port", required=True, help="serial device, e.g. /dev/ttyACM0")
    rec.add_argument("--out", dest="sub_out", required=True, metavar="FILE", help="capture file to write")
    rec.add_argument("--baud", type=int, default=921600)
    rec.add_argument("--duration", dest="sub_duration", type=positive, help="seconds (default: until Ctrl-C)")
    v = sub.add_parser("vkf", help="replay a RAW capture and add the batch (zero-phase) Vold-Kalman "
                                   "orders (Tůma) beside the recursive ones")
    v.add_argument("capture", help="capture file in RAW mode with a tacho")
    v.add_argument("--config", dest="sub_config", metavar="FILE", help="YAML configuration (orders)")
    v.add_argument("--out", dest="sub_out", metavar="DIR", help="MCAP output directory")
    v.add_argument("--bandwidth", type=positive, default=1.0,
                   help="-3 dB bandwidth [Hz] of the batch filter for every component (default 1)")
    v.add_argument("--poles", type=int, choices=(1, 2), default=2, help="1 or 2 poles (default 2)")
    from cmsensord.importing.command import add_import_parser
    add_import_parser(sub)
    add_calibrate_parser(sub)
    from cmsensord.service.operator import add_operator_parsers
    add_operator_parsers(sub)
    s = sub.add_parser("summary", help="summarise an MCAP log (also a truncated .mcap.part)")
    s.add_argument("mcap", help="MCAP file")
    s.add_argument("--json", action="store_true", help="print the summary as JSON")
    return p


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


def _run_vkf(args: argparse.Namespace) -> int:
    """``cmsensord vkf``: the batch orders of a capture."""
    from cmsensord.batch import batch_orders

    cfg, _ = _config_for(args.sub_config)
    if args.sub_out:
        cfg = dataclasses.replace(cfg, output=dataclasses.replace(cfg.output, dir=args.sub_out))
    paths, info = batch_orders(args.capture, cfg, bandwidth_hz=args.bandwidth, poles=args.poles)
    for p in paths:
        print(f"MCAP log: {p}", file=sys.stderr)
    print(f"  batch VKF: {info}", file=sys.stderr)
    return 0


def _run_replay(args: argparse.Namespace) -> int:
    """``cmsensord replay``: a capture through the daemon's Processor."""
    cfg, auto = _config_for(args.sub_config)
    if args.sub_out or args.sub_trace:
        cfg = dataclasses.replace(cfg, output=dataclasses.replace(
            cfg.output, dir=args.sub_out or cfg.output.dir,
            akf_trace=cfg.output.akf_trace or args.sub_trace))
    return replay(args.capture, cfg, auto_channels=auto, speed=args.sub_speed)[0]


def _dispatch(args: argparse.Namespace) -> int:
    """Run the subcommand, the simulation or the daemon that ``args`` ask for."""
    if args.command == "summary":
        return summary(args.mcap, as_json=args.json)
    if args.command == "import":
        from cmsensord.importing.command import run_import
        return run_import(args)
    if args.command == "calibrate":
        return run_calibrate(args)
    if args.command in ("ack", "status"):
        from cmsensord.service.operator import run_ack, run_status
        return (run_ack if args.command == "ack" else run_status)(args)
    if args.command == "record":
        return record(args.port, args.sub_out, baud=args.baud, duration_s=args.sub_duration)
    if args.command == "vkf":
        return _run_vkf(args)
    if args.command == "replay":
        return _run_replay(args)
    if args.simulate:
        return simulate(SimulateOptions(
            scenario=args.scenario, duration=args.duration, speed=args.speed, seed=args.seed,
            channels=args.channels, mode=args.mode, tacho=args.tacho, config=args.config,
            out=args.out, capture=args.capture, akf_trace=args.akf_trace))
    if args.config:
        cfg, auto = _config_for(args.config)
        return run_live(cfg, auto_channels=auto, capture_path=args.capture)
    print("cmsensord: nothing to do: give --simulate, --config FILE or a subcommand "
          "(see cmsensord --help)", file=sys.stderr)
    return EXIT_USAGE


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(with_scenarios="-h" in argv or "--help" in argv)
    args = parser.parse_args(argv)
    _setup_logging(args.verbose, daemon=args.command is None)
    try:
        return _dispatch(args)
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


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
