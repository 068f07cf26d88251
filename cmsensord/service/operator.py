"""``cmsensord ack``, ``status`` and ``capture-now``: an operator's commands to the running daemon.

They talk to the daemon's control socket (:mod:`.control`): the one in the
output directory of ``--config FILE``, the one given by ``--socket``, or by
default the systemd unit's ``/var/lib/cmsensord/cmsensord.sock`` (root only:
the state directory is mode 0700), or, when that is not there, the one of a daemon
started in the current directory with the default ``output.dir`` (a relative ``output.dir`` of
``--config`` is taken in the current directory, else, when only there, in the service's working
directory, ``/var/lib/cmsensord``, where the unit's daemon put it).  ``status`` prints
the daemon's status line and its alarm table; ``ack ALARM`` acknowledges one alarm, ``ack --all`` every
alarm showing a level.  ``capture-now [--channel CH]`` has the daemon keep a capture
(trigger ``manual``) of the channel, or of every channel, around the newest sample it
has: ``capture.pre_s`` from its ring, ``capture.post_s`` still to come; it prints per
channel what will be kept (or why not).  No daemon answering: a one-line error, exit 1; one
that took the request but whose answer did not come in time says so (the request may have been
applied), exit 1.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from datetime import datetime
from pathlib import Path

from cmsensord.config.alarm_indicators import unit_of
from cmsensord.config.settings import OutputConfig
from cmsensord.service.control import SOCKET_NAME, STATE_DIR, NoAnswer, request, socket_path

__all__ = ["add_operator_parsers", "run_ack", "run_status", "run_capture_now", "format_table"]

EXIT_NO_DAEMON = 1


def add_operator_parsers(sub) -> None:
    """The ``ack``, ``status`` and ``capture-now`` subcommands."""
    a = sub.add_parser("ack", help="acknowledge an alarm of the running daemon (latched alarms clear)")
    a.add_argument("alarm", nargs="?", help="alarm name as `cmsensord status` lists it, e.g. de_velocity/ch0")
    a.add_argument("--all", action="store_true", help="every alarm showing a level")
    s = sub.add_parser("status", help="the running daemon's status line and alarm table")
    s.add_argument("--json", action="store_true", help="print the answer as JSON")
    c = sub.add_parser("capture-now", help="the running daemon keeps a capture now (trigger manual): "
                       "capture.pre_s before, capture.post_s after")
    c.add_argument("--channel", metavar="CH", help="only this channel (default: every channel)")
    for p in (a, s, c):
        p.add_argument("--config", dest="sub_config", metavar="FILE",
                       help="the daemon's configuration (its socket is in output.dir)")
        p.add_argument("--socket", metavar="PATH", help=f"the control socket (default {STATE_DIR / SOCKET_NAME}, "
                       f"or, without it, {Path(OutputConfig().dir) / SOCKET_NAME} here)")


def _path(args: argparse.Namespace) -> tuple[Path, str]:
    """The socket to ask and what to try when no daemon answers there: ``--socket``; the socket of
    ``--config``'s output directory (a relative one here, else, when only there, under the
    service's working directory, the state directory, where the unit's daemon resolves it); the
    service's; else, when the service's is not there, that of a daemon started here with the
    default ``output.dir`` (``cmsensord --simulate``) if there is one."""
    if args.socket:
        return Path(args.socket), _NEXT
    if args.sub_config:
        from cmsensord.config import load_config
        out_dir = load_config(args.sub_config).output.dir
        here, service = socket_path(out_dir), STATE_DIR / out_dir / SOCKET_NAME
        if Path(out_dir).is_absolute():
            return here, f"is the daemon of {args.sub_config} running? see systemctl status cmsensord; {_OUT}"
        if not _is_socket(here) and _is_socket(service):
            return service, f"is the service running? see systemctl status cmsensord; {_OUT}"
        return here, (f"output.dir {out_dir} of {args.sub_config} is relative, taken here; the service "
                      f"runs in {STATE_DIR}, its daemon answers on --socket {service}; {_OUT}")
    here = socket_path(OutputConfig().dir)
    service = STATE_DIR / SOCKET_NAME
    return (here if not _exists(service) and here.is_socket() else service), _NEXT


#: what to try when no daemon answers on the socket asked
_OUT = "a daemon started with --out DIR answers on --socket DIR/cmsensord.sock"
_NEXT = f"is it running? give --config FILE or --socket PATH; {_OUT}"


def _is_socket(path: Path) -> bool:
    try:
        return path.is_socket()
    except OSError:                         # the state directory mode 0700 to another user
        return False


def _exists(path: Path) -> bool:
    try:
        return path.exists()
    except OSError:                         # the state directory mode 0700 to another user
        return True


#: the command a user typed, by the request it sends
_COMMAND = {"ack": "ack", "status": "status", "capture": "capture-now"}


def _ask(args: argparse.Namespace, body: dict) -> dict | None:
    path, then = _path(args)
    try:
        return request(path, body)
    except NoAnswer as exc:
        print(f"cmsensord: {_COMMAND[body['cmd']]}: {exc}", file=sys.stderr)
        return None
    except (OSError, ValueError) as exc:
        print(f"cmsensord: no daemon answers on {path}: {getattr(exc, 'strerror', None) or exc} ({then})",
              file=sys.stderr)
        return None


def run_ack(args: argparse.Namespace) -> int:
    if bool(args.alarm) == bool(args.all):
        both = ", not both" if args.all else ""
        print(f"cmsensord: ack: give an alarm name or --all{both} (see cmsensord ack --help)", file=sys.stderr)
        return 2
    answer = _ask(args, {"cmd": "ack", "alarm": None if args.all else args.alarm})
    if answer is None:
        return EXIT_NO_DAEMON
    if not answer.get("ok"):
        return _refused("ack", answer)
    return _shown("ack", lambda: _ack_text(args, answer))


def _ack_text(args: argparse.Namespace, answer: dict) -> tuple[str, int]:
    if answer["acknowledged"]:
        names = answer.get("alarms")
        return f"acknowledged {answer['acknowledged']} alarm(s)" + (f": {', '.join(names)}" if names else ""), 0
    if args.all:
        return "nothing to acknowledge: no alarm shows a level not acknowledged yet", 0
    if answer.get("level", "normal") == "normal":
        return f"nothing to acknowledge: {args.alarm} shows no level (normal)", 0
    return f"nothing to acknowledge: {args.alarm} is acknowledged already (it shows {answer['level']})", 0


def _refused(command: str, answer: dict) -> int:
    """The daemon's refusal (an answer not ``ok``) as one line on stderr, exit 1: its ``error``, or,
    when it gives none (or no text), that it gave no reason."""
    error = answer.get("error")
    if not isinstance(error, str) or not error.strip():
        error = ("the daemon refused the request without saying why (no 'error' text in its answer): a "
                 "daemon of another cmsensord version? `cmsensord status --json` prints the answer as it came")
    print(f"cmsensord: {command}: {error}", file=sys.stderr)
    return EXIT_NO_DAEMON


def _shown(command: str, text: Callable[[], tuple[str, int]]) -> int:
    """Print what ``text`` makes of the daemon's answer, and return its exit status; an answer
    without the fields this cmsensord reads (a daemon of another version, another program's
    socket) is one line on stderr instead, exit 1."""
    try:
        out, code = text()
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, OverflowError) as exc:
        what = f"no field {exc}" if isinstance(exc, KeyError) else f"a field of a wrong type ({exc})"
        print(f"cmsensord: {command}: the daemon's answer is not one this cmsensord reads ({what}): a daemon "
              "of another cmsensord version? `cmsensord status --json` prints the answer as it came", file=sys.stderr)
        return EXIT_NO_DAEMON
    print(out)
    return code


def run_status(args: argparse.Namespace) -> int:
    answer = _ask(args, {"cmd": "status"})
    if answer is None:
        return EXIT_NO_DAEMON
    if not answer.get("ok") and not args.json:
        return _refused("status", answer)
    code = 0 if answer.get("ok") else EXIT_NO_DAEMON
    if args.json:
        print(json.dumps(answer, indent=1))
        return code
    table = (lambda: "\n" + format_table(answer)) if "alarms" in answer else (lambda: "")
    return _shown("status", lambda: (f"{answer.get('status', '')}{table()}", code))


def run_capture_now(args: argparse.Namespace) -> int:
    answer = _ask(args, {"cmd": "capture", "channel": args.channel})
    if answer is None:
        return EXIT_NO_DAEMON
    if not answer.get("ok"):
        return _refused("capture-now", answer)
    return _shown("capture-now", lambda: _capture_text(answer))


def _capture_text(answer: dict) -> tuple[str, int]:
    lines = []
    for row in answer["captures"]:
        if "skipped" in row:
            lines.append(f"{row['channel']}: not captured: {row['skipped']}")
            continue
        at = datetime.fromtimestamp(row["stamp_ns"] / 1e9).isoformat(timespec="milliseconds")
        lines.append(f"{row['channel']}: capturing {row['pre_s']:g} s before and {row['post_s']:g} s after {at} "
                     f"({row['source'].upper()}, from board index {row['first_sample']}); written to the log "
                     f"in {row['post_s']:g} s")
    kept = sum(1 for row in answer["captures"] if "skipped" not in row)
    return "\n".join(lines), 0 if kept else EXIT_NO_DAEMON


def format_table(t: dict) -> str:
    """The alarm table as text, one alarm a line: the value and the levels in the indicator's unit
    (UNIT; "-": none, a ratio, a kurtosis, the severity index); LIVE "-": not known (a saved alarm
    before the first value); a saved alarm's level it cannot give as a number, what it depends on
    (``by speed``, ``2xbase``: :func:`cmsensord.alarms.saved.saved_rows`)."""
    head = f"operating state: {t['operating_state']}, worst: {t['worst']}"
    if "worst_alarm" in t:
        head += f" ({t['worst_alarm']})"
    if "speed_rpm" in t:
        head += f", speed {t['speed_rpm']:.0f} rpm"
    lines = [head, f"{'ALARM':24} {'LEVEL':7} {'LIVE':7} {'VALUE':>10} {'ALERT':>8} {'DANGER':>8} {'UNIT':5}  FLAGS"]
    for a in t["alarms"]:
        num = [f"{a[k]:.4g}" if k in a else str(a.get(on, "-"))
               for k, on in (("value", ""), ("alert_level", "alert_on"), ("danger_level", "danger_on"))]
        flags = " ".join(f for f, on in (("latched", a["latched"]), ("acknowledged", a["acknowledged"]),
                                         ("restored", a.get("restored", False)),
                                         ("saved", a.get("saved", False))) if on)
        unit, live = unit_of(str(a.get("indicator", ""))) or "-", a.get("live", "-")
        lines.append(f"{a['id']:24} {a['level']:7} {live:7} {num[0]:>10} {num[1]:>8} {num[2]:>8} {unit:5}  "
                     f"{flags}".rstrip())
    return "\n".join(lines)
