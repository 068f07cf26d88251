"""A RAW channel whose samples do not move (a dead sensor, a cut cable, an input pinned at an
ADC rail, with or without the board's clipped flag) has no signal, baseline or none: one
``signal_lost`` event naming the count, its severity messages ``signal_lost: true`` with the
severity held, then ``signal_back`` when the samples move again (guards against a dead channel
without a baseline reading as a healthy machine: RMS ~0, zone A, severity 0, no event; and a
pinned one with a baseline reading as a failure).  ``monitor.flat_signal: false`` turns it off;
a live channel, and the simulator's own runs, never read as flat.  Through ``python -m
firmware_sim`` and ``cmsensord replay`` / ``cmsensord --simulate``, as a user types them."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from cmsensord.protocol import COUNT_MAX
from cmsensord.sinks.mcap_sink import read_messages
from processes import cmsensord, run_module
from test_read_size import by_topic

FS = 25000          # the simulated board's sampling rate
SIGNAL = ("signal_lost", "signal_back")
#: an alarm each channel's healthy level (~0.6 m/s^2) holds at danger: a dead channel must not clear it
RULES = "alarms:\n  rules:\n    - {name: rms, indicator: accel_rms, alert: 0.3, danger: 0.5}\n"


def _board(tmp_path: Path, *extra: str, scenario: str = "healthy", seconds: float = 14) -> Path:
    """A RAW capture of the simulated board: two channels of the healthy motor."""
    cap = tmp_path / f"{scenario}.bin"
    p = run_module("firmware_sim", "--scenario", scenario, "--mode", "raw", "--channels", "2", "--duration",
                   str(seconds), *extra, "--out", str(cap))
    assert p.returncode == 0, p.stderr
    return cap


def _pinned(src: Path, dst: Path, chan: int, start_s: float, end_s: float, count: int) -> Path:
    """``src`` with every sample of channel ``chan``'s RAW blocks in [start_s, end_s) at ``count``,
    the clipped flag not set (a board that does not flag it), each frame's CRC made anew."""
    buf, pos = bytearray(src.read_bytes()), 0
    while pos < len(buf):
        assert buf[pos:pos + 2] == b"\xa5\x5a", pos
        kind, t0, ch, n = buf[pos + 3], *struct.unpack_from("<IBxH", buf, pos + 6)
        if kind == 3 and ch == chan and start_s * FS <= t0 < end_s * FS:
            buf[pos + 11] = 0
            buf[pos + 14:pos + 14 + n] = np.full(n // 2, count, dtype="<u2").tobytes()
            struct.pack_into("<I", buf, pos + 14 + n, zlib.crc32(bytes(buf[pos + 2:pos + 14 + n])))
        pos += 18 + n
    dst.write_bytes(bytes(buf))
    return dst


def _replay(tmp_path: Path, cap: Path, config: str = "") -> tuple[list[dict], dict[str, list[dict]], str]:
    """``cmsensord replay CAP [--config]``: its events, severity messages per channel, and output."""
    args = ["replay", str(cap), "--out", str(tmp_path / "logs")]
    if config:
        (tmp_path / "site.yaml").write_text(config)
        args += ["--config", str(tmp_path / "site.yaml")]
    p = cmsensord(*args)
    assert p.returncode == 0, p.stderr
    msgs = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    events = [m for t, _, m in msgs if t == "/cm/events"]
    sev = {ch: [m for t, _, m in msgs if t == f"/cm/{ch}/severity"] for ch in ("ch0", "ch1")}
    return events, sev, p.stdout + p.stderr


@pytest.mark.parametrize("count, start_s, end_s, board, config, held", [
    (COUNT_MAX, 5.0, 9.5, (), "", 5),                         # pinned at the top rail, no baseline
    (2048, 4.6, 9.3, ("--tacho",), "", 6),                    # mid-scale, dead; f_r from the tacho
    (COUNT_MAX, 5.0, 9.5, (), "monitor:\n  baseline: 0.6\n", 5),   # with a baseline: no failure
])
def test_a_channel_whose_samples_do_not_move_has_no_signal(tmp_path, count, start_s, end_s, board, config, held):
    """The decisions from the one the samples stop in to the one they move again in are held
    (4.6 s: the channel dies 0.6 s into a decision; 9.3 s: it comes back 0.3 s into one), and
    the channel's alarm with them (the record it dies in too: never cleared)."""
    cap = _pinned(_board(tmp_path, *board), tmp_path / "dead.bin", 1, start_s, end_s, count)
    events, sev, out = _replay(tmp_path, cap, RULES + config)
    said = [e for e in events if e["kind"] in SIGNAL]
    assert [(e["kind"], e["channel"]) for e in said] == [("signal_lost", "ch1"), ("signal_back", "ch1")], out
    lost, back = said
    rail = " (the ADC's rail)" if count == COUNT_MAX else " (no noise at all)"
    secs = 1 - start_s % 1
    assert lost["message"] == (
        f"ch1: no signal: every sample at {count} counts{rail} for {secs:.3g} s of the decision: a sensor, "
        "cable or ADC fault (monitor.flat_signal); severity 0.00 and the channel's alarms held until it is back")
    assert back["message"].startswith("ch1: signal back: "), back
    assert "WARNING signal_lost: ch1: no signal: every sample at" in out
    dead = [m for m in sev["ch1"] if m.get("signal_lost")]
    assert len(dead) == held and all(m["severity_index"] == 0.0 for m in dead), sev["ch1"]
    first = next(i for i, m in enumerate(sev["ch1"]) if m.get("signal_lost"))
    assert all(m.get("signal_lost") for m in sev["ch1"][first:first + held]), sev["ch1"]
    assert not [m for m in sev["ch0"] if m.get("signal_lost")]
    assert not [e for e in events if e["kind"] in ("failure", "severity_change")], out
    assert "final severity 0.0" in out and "(held: no signal" not in out, out
    alarms = [e["kind"] for e in events if e["kind"].startswith("alarm_") and "rms/ch1" in e["message"]]
    assert alarms == ["alarm_danger"], out


def test_flat_signal_false_turns_it_off_and_a_bad_value_is_one_line(tmp_path):
    cap = _pinned(_board(tmp_path), tmp_path / "dead.bin", 1, 5.0, 9.5, COUNT_MAX)
    events, sev, out = _replay(tmp_path, cap, "monitor:\n  flat_signal: false\n")
    assert not [e for e in events if e["kind"] in SIGNAL], out
    assert not [m for ms in sev.values() for m in ms if m.get("signal_lost")]
    (tmp_path / "bad.yaml").write_text("monitor:\n  flat_signal: 'yes'\n")
    p = cmsensord("replay", str(cap), "--config", str(tmp_path / "bad.yaml"), "--out", str(tmp_path / "bad"))
    assert p.returncode != 0 and p.stderr.count("\n") == 1, p.stderr
    assert "monitor.flat_signal: expected true or false (got 'yes')" in p.stderr, p.stderr


def test_a_channel_held_by_signal_floor_alone_is_said_so(tmp_path):
    """With a baseline and ``flat_signal: false`` on the dead channel, its hold is signal_floor's:
    the event names the level and signal_floor, not flat_signal (it named flat_signal)."""
    cap = _pinned(_board(tmp_path, "--tacho"), tmp_path / "dead.bin", 1, 4.6, 9.3, 2048)
    config = ("monitor:\n  baseline: 0.6\nchannels:\n  - {name: ch0, index: 0}\n"
              "  - {name: ch1, index: 1, flat_signal: false}\n")
    events, _, out = _replay(tmp_path, cap, config)
    said = [e for e in events if e["kind"] in SIGNAL]
    assert [e["kind"] for e in said] == list(SIGNAL), out
    assert said[0]["message"].startswith("ch1: no signal: level ") and "monitor.signal_floor" in said[0]["message"]
    assert "flat_signal" not in said[0]["message"], said[0]


@pytest.mark.parametrize("scenario, board, seconds", [
    ("healthy", ("--tacho",), 14), ("close_orders", ("--tacho",), 5), ("whirl", ("--tacho",), 30),
])
def test_live_channels_never_read_as_flat(tmp_path, scenario, board, seconds):
    """The simulated board's RAW runs (a run-up from standstill among them): no signal_lost."""
    events, sev, out = _replay(tmp_path, _board(tmp_path, *board, scenario=scenario, seconds=seconds))
    assert not [e for e in events if e["kind"] in SIGNAL], out
    assert not [m for ms in sev.values() for m in ms if m.get("signal_lost")]


def test_the_simulated_daemon_reads_no_flat_signal(tmp_path):
    """``cmsensord --simulate`` in RAW mode (the live path: a board on a pty, small reads)."""
    p = cmsensord("--simulate", "--scenario", "healthy", "--mode", "raw", "--tacho", "--channels", "2",
                  "--duration", "8", "--speed", "4", "--out", str(tmp_path))
    assert p.returncode == 0, p.stderr
    msgs = read_messages(next(tmp_path.glob("*.mcap")))
    assert not [m for t, _, m in msgs if t == "/cm/events" and m["kind"] in SIGNAL]
    assert len([m for t, _, m in msgs if t == "/cm/ch1/severity"]) >= 6


def test_the_flat_signal_is_alike_however_the_stream_is_read(tmp_path):
    """A channel dead at mid-scale, then alive again, read in 997-byte, 64-kB and 1-MiB reads:
    every topic's messages (not /cm/diagnostics, which tells how the stream was read) are alike,
    the one signal_lost and signal_back among them."""
    cap = _pinned(_board(tmp_path, "--tacho"), tmp_path / "dead.bin", 1, 4.6, 9.3, 2048)
    two = {"channels": [{"name": "ch0"}, {"name": "ch1"}]}
    runs = [by_topic(cap.read_bytes(), read, two) for read in (997, 65_536, 1 << 20)]
    assert runs[0] == runs[1] == runs[2]
    said = [m["kind"] for _, m in runs[0]["/cm/events"] if m["kind"] in SIGNAL]
    assert said == list(SIGNAL), said


def test_calibrate_refuses_a_channel_pinned_at_a_rail_in_the_healthy_period(tmp_path):
    """A channel pinned at 4095 all through the capture read as healthy to calibrate (a baseline
    of 196 m/s2: a 4x rise of the repaired channel then read 0.55 x baseline): refused in one
    line naming the count, exit 2; its working neighbour alone is learned with a --config."""
    cap = _pinned(_board(tmp_path), tmp_path / "pinned.bin", 1, 0.0, 15.0, COUNT_MAX)
    p = cmsensord("calibrate", str(cap), "--out", str(tmp_path / "site.yaml"))
    assert (p.returncode, p.stderr.strip()) == (2, (
        "cmsensord: calibrate: channel ch1: no signal in the healthy period: every sample at 4095 counts (the "
        "ADC's rail) for 1 s of the decision: nothing to learn; choose a period where it works, or leave it out "
        "(import --channels, or a --config BASE.yaml listing the channels to learn)")), p.stderr
    (tmp_path / "base.yaml").write_text("channels:\n  - {name: ch0, index: 0}\n")
    p = cmsensord("calibrate", str(cap), "--config", str(tmp_path / "base.yaml"), "--out", str(tmp_path / "site.yaml"))
    assert p.returncode == 0, p.stderr
