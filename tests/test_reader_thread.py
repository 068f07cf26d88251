"""The serial reader thread against exceptions that are not port errors, on real processes.

The daemon runs as ``python inject.py --config X``: inject.py replaces ``serial.Serial.read``
so that one read (or every read from one on, or one read with an exception that ends a
thread) fails as a bug would, then runs ``cmsensord.cli.main``; the board is firmware_sim
on a pty. The reader reports the failure once as a ``reader_error`` event logged at ERROR,
closes the port and reopens it with back-off, and says ``reader_recovered`` when bytes flow
again; if the thread ends all the same, the loop stops and exits 70 for systemd to restart.
"""

from __future__ import annotations

import subprocess
import sys

from cmsensord.errors import EXIT_CONFIG
from cmsensord.sinks.event_schema import EVENT_KINDS
from cmsensord.sinks.mcap_sink import read_messages
from processes import ENV, board_on_pty, spawn, stop

INJECT = '''\
import sys
import serial
from cmsensord.cli import main

FAIL_AT, MODE = int(sys.argv.pop(1)), sys.argv.pop(1)
reads = 0
real_read = serial.Serial.read


def read(self, size=1):
    global reads
    reads += 1
    if reads == FAIL_AT or (MODE == "always" and reads > FAIL_AT):
        print(f"injected {reads - FAIL_AT + 1}", file=sys.stderr, flush=True)
        raise (SystemExit(3) if MODE == "exit" else ZeroDivisionError("injected"))
    return real_read(self, size)


serial.Serial.read = read
sys.exit(main(sys.argv[1:]))
'''
#: the line of inject.py that raises
RAISE_LINE = INJECT.splitlines().index(
    '        raise (SystemExit(3) if MODE == "exit" else ZeroDivisionError("injected"))') + 1


def _daemon(tmp_path, port, fail_at: int, mode: str) -> subprocess.Popen:
    (tmp_path / "inject.py").write_text(INJECT)
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text(f"link:\n  port: {port}\n  reconnect_min_s: 0.05\n  reconnect_max_s: 0.1\n"
                   f"output:\n  dir: {tmp_path / 'logs'}\n  status_line: false\n")
    return spawn([sys.executable, str(tmp_path / "inject.py"), str(fail_at), mode,
                             "--config", str(cfg)], stderr=subprocess.PIPE, text=True, env=ENV,
                            cwd=tmp_path)


def _until(proc: subprocess.Popen, text: str) -> list[str]:
    """stderr lines up to and including the first that contains ``text``."""
    lines = []
    for line in proc.stderr:
        lines.append(line.rstrip("\n"))
        if text in line:
            return lines
    raise AssertionError(f"{text!r} never came: {lines}")


def _error_line(port: str) -> str:
    return (f"ERROR reader_error: {port}: reader failed: ZeroDivisionError: injected "
            f"(at inject.py:{RAISE_LINE}); closing the port, retrying every 0.05..0.1 s")


def test_one_failed_read_is_reported_and_reading_goes_on(tmp_path):
    with board_on_pty("--scenario", "healthy", "--duration", "60", "--channels", "1") as port:
        d = _daemon(tmp_path, port, 20, "once")
        lines = _until(d, "reader_recovered")
        lines += stop(d).splitlines()
    assert d.returncode == 0, lines
    assert lines.count(_error_line(port)) == 1, lines
    assert f"INFO reader_recovered: {port}: reading again after 1 reader error(s)" in lines
    assert not [x for x in lines if "Traceback" in x or "link_restored" in x], lines
    events = [m for t, _, m in read_messages(next((tmp_path / "logs").glob("*.mcap"))) if t == "/cm/events"]
    kinds = [m["kind"] for m in events]
    # the board's first STATUS (a `config` event) may come before or after the failed read
    assert [k for k in kinds if k not in ("frames_lost", "config")] == \
        ["start", "reader_error", "reader_recovered", "stop"]
    assert set(kinds) <= set(EVENT_KINDS)       # the kinds the event schema allows


def test_a_read_that_always_fails_is_one_event_and_the_daemon_keeps_trying(tmp_path):
    with board_on_pty("--scenario", "healthy", "--duration", "60", "--channels", "1") as port:
        d = _daemon(tmp_path, port, 20, "always")
        lines = _until(d, "injected 4")         # the port reopened and failed three more times
        assert d.poll() is None                 # still running
        lines += stop(d).splitlines()
    assert d.returncode == 0, lines
    assert [x for x in lines if "reader_" in x.split(":")[0]] == [_error_line(port)], lines
    # the board's first STATUS (a `config` event) may come before the first failed read
    assert [x for x in lines if x.startswith("  events: ")] in (
        ["  events: reader_error 1, start 1, stop 1"], ["  events: config 1, reader_error 1, start 1, stop 1"])


def test_a_reader_thread_that_ends_ends_the_daemon_with_status_70(tmp_path):
    with board_on_pty("--scenario", "healthy", "--duration", "60", "--channels", "1") as port:
        d = _daemon(tmp_path, port, 20, "exit")
        _, err = d.communicate(timeout=30)
    assert d.returncode == 70, err
    assert ("ERROR reader_died: the serial reader thread has ended; exiting with status 70 for "
            "the service manager to restart the daemon") in err.splitlines(), err


def test_a_baud_rate_beyond_any_uart_is_a_config_error_of_the_daemon(tmp_path):
    cfg = tmp_path / "baud.yaml"
    cfg.write_text("link:\n  port: /dev/ttyACM0\n  baud: 99999999999\n")
    run = subprocess.run([sys.executable, "-m", "cmsensord", "--config", str(cfg)], capture_output=True,
                         text=True, env=ENV, timeout=30, cwd=tmp_path)
    assert run.returncode == EXIT_CONFIG
    assert run.stderr == (f"cmsensord: configuration error: {cfg}: link.baud: must be > 0 and "
                          "<= 12000000 (got 99999999999)\n")
