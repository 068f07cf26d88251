"""Hostile configuration input: the loader refuses it with one line and exit 78, never hangs.

Each case is a small file (or special file) given to ``cmsensord replay --config`` as a user
would, and the exact one-line message is asserted.
"""

from __future__ import annotations

import os

import pytest

from cmsensord.config import load_config
from cmsensord.config.yaml_file import MAX_CONFIG_BYTES
from cmsensord.errors import EXIT_CONFIG, ConfigError, _short_repr
from processes import cmsensord


def _alias_bomb() -> str:
    """A scalar value whose aliases stand for 9**9 (387 million) strings in 343 bytes."""
    lines = ["link:", "  port: [&a [x,x,x,x,x,x,x,x,x],"]
    prev = "a"
    for name in "bcdefghi":
        lines.append(f"    &{name} [{','.join(['*' + prev] * 9)}],")
        prev = name
    lines.append(f"    *{prev}]")
    return "\n".join(lines) + "\n"


def _refused(tmp_path, config, timeout=30) -> str:
    """``cmsensord replay --config CONFIG``: exit 78 and one line on stderr, returned."""
    run = cmsensord("replay", "--config", str(config), str(tmp_path / "none.bin"), timeout=timeout,
                    cwd=tmp_path)
    assert run.returncode == EXIT_CONFIG, run.stderr
    assert run.stderr.count("\n") == 1 and "Traceback" not in run.stderr, run.stderr
    assert not (tmp_path / "cmsensord-logs").exists()
    return run.stderr.strip()


@pytest.mark.parametrize("text, message", [
    (_alias_bomb(), "YAML aliases expand to more than 100000 values"),
    ("link:\n  port: &a [*a]\n", "a YAML alias refers to a node that contains it (a recursive structure)"),
    ('output:\n  dir: "logs\\0x"\n', "output.dir: must not contain a NUL byte (got 'logs\\x00x')"),
    ('link:\n  port: "/dev/tty\\0"\n', "link.port: must not contain a NUL byte (got '/dev/tty\\x00')"),
    ("link:\n  baud: 99999999999\n", "link.baud: must be > 0 and <= 12000000 (got 99999999999)"),
    ("#" * (MAX_CONFIG_BYTES + 1), f"larger than {MAX_CONFIG_BYTES} bytes: not a configuration file"),
    ("link:\n  baud: " + "9" * 5000 + "\n", "line 2, column 9: number too large (a whole number of 5,000 characters)"),
    ("link: {port: /dev/ttyACM0, baud: -" + "9" * 5000 + "}\n",
     "line 1, column 34: number too large (a whole number of 5,001 characters)"),
    ("commissioned:\n  date: 2024-13-45\n", "line 2, column 9: not a date (month must be in 1..12)"),
    ('link:\n  baud: !!int ""\n', "line 2, column 9: not a whole number ('')"),
    ('link:\n  baud: !!int "12abc"\n', "line 2, column 9: not a whole number ('12abc')"),
    ('link:\n  baud: !!float ""\n', "line 2, column 9: not a number ('')"),
    ('commissioned:\n  date: !!timestamp ""\n', "line 2, column 9: not a date ('')"),
    ('output:\n  status_line: !!bool "maybe"\n', "line 2, column 16: not true or false ('maybe')"),
], ids=["alias-bomb", "recursive-alias", "nul-in-output-dir", "nul-in-port", "baud-too-large", "too-large",
        "int-past-4300-digits", "negative-int-past-4300-digits", "impossible-date", "empty-tagged-int",
        "tagged-int-not-digits", "empty-tagged-float", "empty-tagged-date", "tagged-bool-not-a-bool"])
def test_hostile_file_is_one_line_config_error(tmp_path, text, message):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(text)
    assert _refused(tmp_path, cfg) == f"cmsensord: configuration error: {cfg}: {message}"


def test_the_daemon_refuses_a_number_past_4300_digits_in_one_line(tmp_path):
    """``cmsensord --config`` as ``replay --config``: exit 78, not Python's ValueError (exit 1)."""
    cfg = tmp_path / "big.yaml"
    cfg.write_text("link:\n  baud: " + "9" * 5000 + "\n")
    run = cmsensord("--config", str(cfg), timeout=30, cwd=tmp_path)
    assert (run.returncode, run.stderr) == (EXIT_CONFIG, f"cmsensord: configuration error: {cfg}: line 2, column 9: "
                                            "number too large (a whole number of 5,000 characters)\n")


def test_fifo_is_refused_without_waiting_for_a_writer(tmp_path):
    fifo = tmp_path / "cfg.fifo"
    os.mkfifo(fifo)
    assert _refused(tmp_path, fifo, timeout=20) == (
        f"cmsensord: configuration error: {fifo}: not a regular file (a FIFO); give the path of a YAML file")


def test_device_is_refused_not_read_to_the_end_of_memory(tmp_path):
    assert _refused(tmp_path, "/dev/zero", timeout=20) == (
        "cmsensord: configuration error: /dev/zero: not a regular file (a character device); "
        "give the path of a YAML file")


@pytest.mark.parametrize("written, value", [
    ("1.0e300", 1e300), ("1e300", 1e300), ("2.5E+3", 2.5e3), (".5e1", 5.0), ("1.e2", 100.0),
    ("1.0e+2", 100.0), ("1.5", 1.5)])
def test_every_exponent_form_is_a_number(tmp_path, written, value):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"monitor:\n  r_max: {written}\n")
    assert load_config(cfg).monitor.r_max == value


def test_exponent_beyond_float_is_not_finite(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("monitor:\n  r_max: 1e999\n")
    with pytest.raises(ConfigError) as info:
        load_config(cfg)
    assert str(info.value) == f"{cfg}: monitor.r_max: expected a finite number (got inf)"


def test_message_of_a_shared_structure_costs_what_it_shows():
    x: list = ["x"] * 9
    for _ in range(12):                 # 9**13 strings if written out in full
        x = [x] * 9
    assert _short_repr(x) == "[[[[[[[[[[[[[" + ", ".join(["'x'"] * 9) + "]..."
    loop: list = [1]
    loop.append(loop)
    assert _short_repr(loop) == repr(loop) == "[1, [...]]"
