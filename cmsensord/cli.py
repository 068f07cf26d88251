"""Command line: argparse, dispatch to :mod:`cmsensord.service`, errors -> exit status.

    cmsensord --simulate [--scenario NAME --duration S --speed X --out DIR ...]
    cmsensord --config FILE [--out DIR]  run the daemon on the configured port
    cmsensord replay CAPTURE [--config FILE] [--out DIR]
    cmsensord record --port DEV --out FILE [--duration S]
    cmsensord summary LOG.mcap ... | DIR
    cmsensord report LOG_OR_DIR... --out report.html [--png DIR]
    cmsensord ack | status | capture-now [--config FILE]   (to the running daemon)

Errors a user can cause (bad arguments, a bad configuration value, a missing
device or capture, an unwritable log directory) end in one line on stderr and
exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import difflib
import os
import sys
from collections.abc import Sequence

from cmsensord import __version__, hangup
from cmsensord.argtypes import count, positive
from cmsensord.commission import add_calibrate_parser, run_calibrate
from cmsensord.config import Config, as_written, default_config, load_config
from cmsensord.config.settings import MAX_BAUD
from cmsensord.errors import (
    EXIT_CONFIG,
    EXIT_INTERRUPTED,
    EXIT_USAGE,
    CaptureFileError,
    CmsensordError,
    ConfigError,
    InstanceError,
    Interrupted,
    LinkError,
    SinkError,
)
from cmsensord.journal import JournalStream, error_line, setup_logging, under_journal
from cmsensord.service.config_file import ConfigFile
from cmsensord.service.live import run_live
from cmsensord.service.record import record
from cmsensord.service.replay import replay
from cmsensord.service.simulate import RUNUP_ORDERS, SimulateOptions, simulate
from cmsensord.service.summary import summary_of

__all__ = ["main", "build_parser", "RUNUP_ORDERS"]


# --------------------------------------------------------------------------- helpers
def _scenarios_help() -> str:
    try:
        from firmware_sim.scenarios import SCENARIOS, make_scenario
    except ImportError:  # pragma: no cover
        return ""
    from cmsensord.service.simulate import scenario_run

    lines = []
    for name in SCENARIOS:
        try:
            desc = make_scenario(name, duration_s=60.0).description.split("\n")[0]
        except Exception:  # noqa: BLE001 - help text only
            desc = ""
        run = scenario_run(name)
        mics = f", microphone on ch{','.join(map(str, run.microphones))}" if run.microphones else ""
        lines.append(f"  {name:<19} {desc}\n  {'':<19} (defaults: {run.duration_s:g} s at {run.speed:g}x, "
                     f"{run.channels} channel(s), {run.mode.upper()}{mics})")
    return "scenarios (--scenario):\n" + "\n".join(lines)


#: options users reach for that are another's name here
_SYNONYMS = {"--seconds": "--duration", "--time": "--duration"}


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (and the pointer to the --help of the command or
    subcommand whose line it is on), exit 2; an option it does not know whose value it took for
    the subcommand is named as the error."""

    _argv: list[str] = []

    def parse_known_args(self, args=None, namespace=None):
        self._argv = list(sys.argv[1:] if args is None else args)
        return super().parse_known_args(args, namespace)

    def parse_args(self, args=None, namespace=None):
        """argparse's, but arguments left over after a subcommand are its usage error (they are
        on its command line: its --help is the one that helps)."""
        ns, extras = self.parse_known_args(args, namespace)
        if extras:
            subs = [a for a in self._actions if isinstance(a, argparse._SubParsersAction)]
            command = getattr(ns, subs[0].dest, None) if subs else None
            parser = subs[0].choices[command] if command in (subs[0].choices if subs else {}) else self
            parser.error(f"unrecognized arguments: {' '.join(extras)}")
        return ns

    def error(self, message: str):
        prefix = "<3>" if isinstance(sys.stderr, JournalStream) else ""
        unknown = self._unknown_option() if "invalid choice" in message else None
        if unknown:
            message = f"unrecognized argument {unknown}"
            like = _SYNONYMS.get(unknown) or next(iter(difflib.get_close_matches(
                unknown, [o for o in self._option_string_actions if o.startswith("--")], 1)), None)
            message += f" (did you mean {like}?)" if like else ""
        self.exit(EXIT_USAGE, f"{prefix}{self.prog}: error: {message} (see {self.prog} --help)\n")

    def _unknown_option(self) -> str | None:
        """The first ``--option`` of the command line this parser does not know (None: none)."""
        for arg in self._argv:
            if arg == "--":
                return None
            name = arg.split("=", 1)[0]
            if name.startswith("--") and name not in self._option_string_actions:
                return name
        return None


# --------------------------------------------------------------------------- argparse
def build_parser(with_scenarios: bool = True) -> argparse.ArgumentParser:
    p = _Parser(
        prog="cmsensord",
        description="Condition-monitoring daemon: serial frames from a TM4C ADC board -> banks of "
                    "adaptive Kalman filters -> severity indices and events in MCAP logs.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(_scenarios_help() if with_scenarios else "")
        + "\n\nsubcommands: replay, record, import, calibrate, vkf, config, summary, report, ack, status, "
          "capture-now (see `cmsensord SUBCOMMAND --help`)")
    p.add_argument("--version", action="version", version=f"cmsensord {__version__}")
    p.add_argument("--config", metavar="FILE", help="YAML configuration (`cmsensord config --default` "
                   "prints every key with its default and meaning)")
    p.add_argument("-v", "--verbose", action="count", default=0,
                   help="log more: -v the per-AKF anomaly flags too, -vv everything (debug)")
    _add_simulation_args(p.add_argument_group("simulation (--simulate)"))
    sub = p.add_subparsers(dest="command", parser_class=_Parser,
                           metavar="{replay,record,import,calibrate,vkf,config,summary,report,ack,status,capture-now}")
    _add_replay_parser(sub)
    _add_record_parser(sub)
    _add_vkf_parser(sub)
    from cmsensord.importing.command import add_import_parser
    add_import_parser(sub)
    add_calibrate_parser(sub)
    _add_config_parser(sub)
    from cmsensord.report.command import add_report_parser
    add_report_parser(sub)
    from cmsensord.service.operator import add_operator_parsers
    add_operator_parsers(sub)
    _add_summary_parser(sub)
    for subparser in sub.choices.values():
        _add_verbose_after(subparser)
    return p


def _add_verbose_after(subparser: argparse.ArgumentParser) -> None:
    """``-v``/``-vv`` after the subcommand too (``cmsensord replay f.bin -v``).  The subparser
    parses into a namespace of its own and copies what it holds over the main parser's: with
    no default there (SUPPRESS), a ``-v`` given before the subcommand is kept when none follows
    (and replaced by one that does)."""
    subparser.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS,
                           help="log more: -v info, -vv debug (default: warnings and up)")


def _add_simulation_args(sim) -> None:
    sim.add_argument("--simulate", action="store_true",
                     help="run a simulated ADC board on a pty and the daemon on it")
    sim.add_argument("--scenario", default="degrading", help="machine scenario (default degrading)")
    sim.add_argument("--duration", type=positive, default=None,
                     help="simulated seconds; a scenario's shape stretches over it (default: the "
                          "scenario's, 600 for the motors, listed below)")
    sim.add_argument("--speed", type=positive, default=None,
                     help="x real time (default: the scenario's, 20 for the motors: 600 s simulated "
                          "in 30 s; listed below); a reader that falls behind slows the board down")
    sim.add_argument("--out", metavar="DIR", help="MCAP output directory, of --simulate and of the "
                     "daemon of --config (default output.dir; the daemon's control socket is there too)")
    sim.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    sim.add_argument("--channels", type=count(1, 8), default=None,
                     help="number of channels 1..8 (default: the scenario's, 1; 2 with a microphone "
                          "beside the accelerometer)")
    sim.add_argument("--mode", choices=("rms", "raw"),
                     help="board mode (default: rms; raw for whirl and close_orders)")
    sim.add_argument("--tacho", action="store_true",
                     help="the board sends TACHO frames (default for whirl and close_orders)")
    sim.add_argument("--capture", metavar="FILE", help="also write the received bytes to a capture "
                     "file (with --simulate: written afresh; the daemon appends to it, and it is not "
                     "bounded by output.retain_mb)")
    sim.add_argument("--akf-trace", action="store_true", help="write /cm/<ch>/akf per observation "
                     "(--simulate and the daemon of --config; default output.akf_trace)")
    sim.add_argument("--publish", action="store_true", help="with --simulate and a config's mqtt section: "
                     "publish the simulated run to its broker, as its client_id (default: not published)")


def _add_record_parser(sub) -> None:
    rec = sub.add_parser("record", help="capture the raw bytes of a serial port to a file",
                         description="Capture the bytes of the board's serial port, as read, to a file "
                                     "(for replay, calibrate and vkf), with a line a second and what it "
                                     "captured at the end.")
    rec.add_argument("--port", required=True, help="serial device, e.g. /dev/ttyACM0")
    rec.add_argument("--out", dest="sub_out", required=True, metavar="FILE", help="capture file to write")
    rec.add_argument("--baud", type=count(1, MAX_BAUD), default=921600,
                     help=f"UART baud (default 921600, at most {MAX_BAUD}; a USB CDC port or a pty ignores it)")
    rec.add_argument("--duration", dest="sub_duration", type=positive, metavar="S",
                     help="seconds (default: until Ctrl-C)")


#: --out of replay and vkf: where their logs go without it
_OUT_DIR_HELP = ("MCAP output directory (default: output.dir of --config, else cmsensord-logs here, where "
                 "--simulate writes too: give each run its own)")


def _add_vkf_parser(sub) -> None:
    v = sub.add_parser("vkf", help="replay a RAW capture and add the batch (zero-phase) Vold-Kalman "
                                   "orders (Tůma) beside the recursive ones",
                       description="Replay a RAW capture with a tacho as `cmsensord replay` does and add, "
                                   "on the same /cm/<channel>/orders topics (method batch), the zero-phase "
                                   "Vold-Kalman orders (Tůma) of the whole record, computed in memory.")
    v.add_argument("capture", help="capture file in RAW mode with a tacho")
    v.add_argument("--config", dest="sub_config", metavar="FILE", help="YAML configuration (orders)")
    v.add_argument("--out", dest="sub_out", metavar="DIR", help=_OUT_DIR_HELP)
    v.add_argument("--bandwidth", type=positive, default=1.0,
                   help="-3 dB bandwidth [Hz] of the batch filter for every component (default 1)")
    v.add_argument("--poles", type=int, choices=(1, 2), default=2, help="1 or 2 poles (default 2)")
    _add_publish_arg(v)


def _add_config_parser(sub) -> None:
    c = sub.add_parser("config", help="print the default configuration (every key, commented)")
    c.add_argument("--default", action="store_true", required=True,
                   help="print config/default.yaml: start a site file from it")


def _add_summary_parser(sub) -> None:
    s = sub.add_parser("summary", help="summarise MCAP logs (also a truncated .mcap.part, or a directory's logs)")
    s.add_argument("mcap", nargs="+", metavar="LOG", help="MCAP file(s), or directories of logs (in the order "
                   "their files were opened)")
    s.add_argument("--json", action="store_true", help="print the summary as JSON")


def _add_publish_arg(parser) -> None:
    parser.add_argument("--publish", dest="sub_publish", action="store_true",
                        help="publish to the broker of the config's mqtt section, as its client_id "
                        "and topics (those of the live daemon of that config) and through its "
                        "queue directory (default: the mqtt section is ignored)")


def _add_replay_parser(sub) -> None:
    r = sub.add_parser("replay", help="process a captured serial log as fast as possible",
                       description="Process a capture (the bytes of the port, from `cmsensord record` or "
                                   "--capture) through the daemon's chain into MCAP logs, as fast as "
                                   "possible or paced (--realtime, --speed X), and print its summary.")
    r.add_argument("capture", help="capture file (the bytes as read from the port)")
    r.add_argument("--config", dest="sub_config", metavar="FILE", help="YAML configuration")
    r.add_argument("--out", dest="sub_out", metavar="DIR", help=_OUT_DIR_HELP)
    r.add_argument("--akf-trace", dest="sub_trace", action="store_true",
                   help="write /cm/<ch>/akf per observation")
    _add_publish_arg(r)
    pace = r.add_mutually_exclusive_group()
    pace.add_argument("--realtime", action="store_const", const=1.0, dest="sub_speed",
                      help="pace the replay at the board's clock (default: as fast as possible)")
    pace.add_argument("--speed", type=positive, dest="sub_speed", metavar="X",
                      help="pace the replay at X times the board's clock")


def replay_parser() -> argparse.ArgumentParser:
    """The parser :func:`main` uses for ``cmsensord replay ...`` (no help asked): the replay
    subcommand alone, the same options, errors and namespace as :func:`build_parser` gives
    it, without building (and importing the modules of) every other subcommand, a fixed
    cost of every replay."""
    p = _Parser(prog="cmsensord")
    p.add_argument("-v", "--verbose", action="count", default=0)
    sub = p.add_subparsers(dest="command", parser_class=_Parser)
    _add_replay_parser(sub)
    _add_verbose_after(sub.choices["replay"])
    return p


def _config_for(path: str | None) -> tuple[Config, bool]:
    """Load a config (an empty one said in a warning line, by load_config); auto_channels when the
    file does not list channels."""
    if path is None:
        return default_config(1), True
    return load_config(path), not as_written(path).get("channels")


def _zones_note(cfg: Config, path: str | None, proc) -> None:
    """After a replay whose board was in RAW mode (its records carry a zone), the note that the
    ISO 10816-3 zones were graded for a machine class the configuration does not set
    (:func:`~cmsensord.config.indicators.zones_assumed`)."""
    from cmsensord.config.indicators import zones_assumed
    from cmsensord.protocol import MODE_RAW

    st = proc.setup.status
    note = zones_assumed(cfg.indicators, as_written(path).get("indicators")) if st is not None else None
    if note and st.mode == MODE_RAW:
        print(note, file=sys.stderr)


def _with_output(cfg: Config, out: str | None, akf_trace: bool) -> Config:
    """``cfg`` with ``--out DIR`` as its output.dir and ``--akf-trace`` turning output.akf_trace on."""
    if not out and not akf_trace:
        return cfg
    return dataclasses.replace(cfg, output=dataclasses.replace(
        cfg.output, dir=out or cfg.output.dir, akf_trace=cfg.output.akf_trace or akf_trace))


def _run_vkf(args: argparse.Namespace) -> int:
    """``cmsensord vkf``: the batch orders of a capture."""
    from cmsensord.batch import batch_orders, describe

    cfg, auto = _config_for(args.sub_config)
    if args.sub_out:
        cfg = dataclasses.replace(cfg, output=dataclasses.replace(cfg.output, dir=args.sub_out))
    paths, info = batch_orders(args.capture, cfg, bandwidth_hz=args.bandwidth, poles=args.poles, auto_channels=auto,
                               publish=args.sub_publish)
    for p in paths:
        print(f"MCAP log: {p}", file=sys.stderr)
    print(f"  {describe(info, bandwidth_hz=args.bandwidth, poles=args.poles)}", file=sys.stderr)
    for line in info["mqtt"]:
        print(line, file=sys.stderr)
    return 0


def _run_replay(args: argparse.Namespace) -> int:
    """``cmsensord replay``: a capture through the daemon's Processor."""
    cfg, auto = _config_for(args.sub_config)
    cfg = _with_output(cfg, args.sub_out, args.sub_trace)
    code, _, proc = replay(args.capture, cfg, auto_channels=auto, speed=args.sub_speed, publish=args.sub_publish)
    _zones_note(cfg, args.sub_config, proc)
    return code


def _print_default_config() -> int:
    """``cmsensord config --default``: the commented default configuration on stdout."""
    from cmsensord.config.default_file import default_yaml

    text = default_yaml()
    if text is None:
        error_line("cmsensord: the default configuration file is not installed (config/default.yaml)")
        return 1
    sys.stdout.write(text)
    sys.stdout.flush()
    return 0


def _dispatch(args: argparse.Namespace) -> int:
    """Run the subcommand, the simulation or the daemon that ``args`` ask for."""
    if args.command == "config":
        return _print_default_config()
    if args.command == "summary":
        return summary_of(args.mcap, as_json=args.json)
    if args.command == "import":
        from cmsensord.importing.command import run_import
        return run_import(args)
    if args.command == "report":
        from cmsensord.report.command import run_report
        return run_report(args)
    if args.command == "calibrate":
        return run_calibrate(args)
    if args.command in ("ack", "status", "capture-now"):
        from cmsensord.service.operator import run_ack, run_capture_now, run_status
        return {"ack": run_ack, "status": run_status, "capture-now": run_capture_now}[args.command](args)
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
            out=args.out, capture=args.capture, akf_trace=args.akf_trace, publish=args.publish))
    if args.config:
        cfg, auto = _config_for(args.config)
        return run_live(_with_output(cfg, args.out, args.akf_trace), auto_channels=auto, capture_path=args.capture,
                        inputs=[args.config], config_file=ConfigFile.at_start(args.config, cfg))
    error_line("cmsensord: nothing to do: give --simulate, --config FILE or a subcommand "
               "(see cmsensord --help)")
    return EXIT_USAGE


def _in_config_file(exc: ConfigError, args: argparse.Namespace) -> ConfigError:
    """``exc`` in the --config file given, when it was found in code (``<code>``: the settings
    against the channels, once the capture or the board said which there are)."""
    path = getattr(args, "sub_config", None) or getattr(args, "config", None)
    return exc.relocated(str(path)) if exc.source == "<code>" and path else exc


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if under_journal() and not isinstance(sys.stderr, JournalStream):
        sys.stderr = JournalStream(sys.stderr)
    helping = "-h" in argv or "--help" in argv
    parser = replay_parser() if argv[:1] == ["replay"] and not helping else build_parser(with_scenarios=helping)
    args = parser.parse_args(argv)
    if args.command is not None:        # not the daemon: SIGHUP as the entry point found it
        hangup.release()
    setup_logging(args.verbose, daemon=args.command is None)
    try:
        return _dispatch(args)
    except ConfigError as exc:
        exc = _in_config_file(exc, args)
        if exc.source.startswith("--"):         # a command-line option: a usage error
            error_line(f"cmsensord: {exc}")
            return EXIT_USAGE
        error_line(f"cmsensord: configuration error: {exc}")
        return EXIT_CONFIG
    except InstanceError as exc:        # another daemon on this output directory
        error_line(f"cmsensord: {exc}")
        return EXIT_CONFIG
    except CaptureFileError as exc:     # the daemon's --capture
        error_line(f"cmsensord: {exc}")
        return EXIT_CONFIG
    except SinkError as exc:            # the output directory is a setting (output.dir / --out)
        error_line(f"cmsensord: output error: {exc} (set output.dir or --out to a writable directory)")
        return EXIT_CONFIG
    except LinkError as exc:
        error_line(f"cmsensord: {exc}")
        return EXIT_USAGE
    except Interrupted as exc:          # Ctrl-C in a one-shot command: what it left on disk
        error_line(f"cmsensord: {exc}")
        return EXIT_INTERRUPTED
    except CmsensordError as exc:
        error_line(f"cmsensord: {exc}")
        return EXIT_USAGE
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except BrokenPipeError:             # `cmsensord ... | head -1`: the reader is gone
        return _quiet_broken_pipe()


#: exit status after a closed pipe, as a shell reports a process ended by SIGPIPE
EXIT_PIPE = 141


def _quiet_broken_pipe() -> int:
    """stdout or stderr is a pipe whose reader has gone (the run is already finished: the MCAP
    file is closed on the way out): no traceback, nothing more written, exit 141."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):
            os.dup2(devnull, stream.fileno())
    os.close(devnull)
    return EXIT_PIPE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
