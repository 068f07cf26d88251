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
from test_read_size import board, by_topic, frames

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


def _pinned(src: Path, dst: Path, chan: int, start_s: float, end_s: float, count: int, every: int = 1) -> Path:
    """``src`` with every sample of channel ``chan``'s RAW blocks in [start_s, end_s) at ``count``
    (with ``every``, those of every ``every``-th block only; start_s and end_s in 25-kHz samples /
    25000 whatever the board's rate), the clipped flag not set (a board that does not flag it), each
    frame's CRC made anew."""
    buf, pos = bytearray(src.read_bytes()), 0
    while pos < len(buf):
        assert buf[pos:pos + 2] == b"\xa5\x5a", pos
        kind, t0, ch, n = buf[pos + 3], *struct.unpack_from("<IBxH", buf, pos + 6)
        if kind == 3 and ch == chan and start_s * FS <= t0 < end_s * FS and (t0 // (n // 2)) % every == 0:
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


@pytest.mark.parametrize("config", ["", "monitor:\n  baseline: 0.6\n"])
def test_a_channel_flat_every_other_block_has_no_signal_not_a_failure(tmp_path, config):
    """Every other block of ch1 pinned at 4095 from 5 s to 9.5 s (an intermittent connector): no
    quarter is all flat, yet half its blocks say nothing about the machine.  The flat blocks are no
    observation for the banks, and each decision with a quarter of its blocks flat has no signal,
    the event naming how many (it read as a FAILURE of the AKF bank, with no signal_lost)."""
    cap = _pinned(_board(tmp_path), tmp_path / "loose.bin", 1, 5.0, 9.5, COUNT_MAX, every=2)
    events, sev, out = _replay(tmp_path, cap, RULES + config)
    said = [(e["kind"], e["message"]) for e in events if e["kind"] in SIGNAL]
    assert said == [
        ("signal_lost", "ch1: no signal: 50 of 100 blocks flat (intermittent), every sample at 4095 counts (the "
         "ADC's rail), for 0.5 s of the decision: a sensor, cable or ADC fault (monitor.flat_signal); severity "
         "0.00 and the channel's alarms held until it is back"),
        ("signal_back", said[1][1])], out
    assert said[1][1] == "ch1: signal back: its samples move again; severity and alarms judged again" if not config \
        else said[1][1].startswith("ch1: signal back: level "), said
    assert [i for i, m in enumerate(sev["ch1"]) if m.get("signal_lost")] == [5, 6, 7, 8, 9], sev["ch1"]
    assert not [e for e in events if e["kind"] in ("failure", "severity_change", "anomaly_onset")], out
    assert max(m["severity_index"] for m in sev["ch1"]) == 0.0
    alarms = [e["kind"] for e in events if e["kind"].startswith("alarm_") and "rms/ch1" in e["message"]]
    assert alarms == ["alarm_danger"], out


def test_a_few_flat_blocks_are_no_observation_and_raise_no_alarm(tmp_path):
    """One block in eight of ch1 at 4095 (fewer than a quarter: not a decision of no signal): its
    severity is judged on the blocks that move, and the indicator records holding the flat blocks
    are not judged by the alarms (marked signal_lost; the rail's samples made an accel_rms of 64
    m/s2: alarm_danger)."""
    cap = _pinned(_board(tmp_path), tmp_path / "loose.bin", 1, 5.0, 9.5, COUNT_MAX, every=8)
    rules = "alarms:\n  rules:\n    - {name: rms, indicator: accel_rms, alert: 2, danger: 5}\n"
    events, sev, out = _replay(tmp_path, cap, rules)
    assert not [e for e in events if e["kind"] in SIGNAL or e["kind"].startswith(("alarm_", "failure"))], out
    assert [e["message"] for e in events if e["kind"] == "flat_blocks"] == [
        "ch1: 12 of 100 blocks flat (intermittent: a loose connector or cable?), at 4095 counts: left out of the "
        "severity, and the channel's indicator records holding them are not judged by the alarms; a quarter of a "
        "decision's blocks flat is no signal"], out
    assert not [m for m in sev["ch1"] if m.get("signal_lost")] and max(m["severity_index"] for m in sev["ch1"]) == 0
    records = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    marked = [m for t, _, m in records if t == "/cm/ch1/indicators" and m.get("signal_lost")]
    assert len(marked) == 5 and min(m["accel_rms"] for m in marked) > 5, marked


def test_a_channel_with_the_check_off_says_nothing_of_its_flat_blocks(tmp_path):
    """ch1 with monitor.flat_signal false and one block in eight at 4095: its blocks are judged as
    any (the rail's accel_rms raises the alarm), and nothing says they are left out (a flat_blocks
    warning said so while the alarms fired)."""
    cap = _pinned(_board(tmp_path), tmp_path / "loose.bin", 1, 5.0, 9.5, COUNT_MAX, every=8)
    events, _, out = _replay(tmp_path, cap, "channels:\n  - {name: ch0, index: 0}\n"
                             "  - {name: ch1, index: 1, flat_signal: false}\nalarms:\n  rules:\n"
                             "    - {name: rms, indicator: accel_rms, alert: 2, danger: 5}\n")
    assert not [e for e in events if e["kind"] in SIGNAL or e["kind"] == "flat_blocks"], out
    assert [e["kind"] for e in events if e["kind"].startswith("alarm_")] == ["alarm_danger", "alarm_clear"], out


def test_a_channel_flat_from_the_start_is_said_lost_not_intermittent(tmp_path):
    """ch1 pinned at 4095 from the first block: one signal_lost, no flat_blocks warning (the first
    decision, the filters' transient, said '100 of 100 blocks flat (intermittent ...)')."""
    cap = _pinned(_board(tmp_path), tmp_path / "dead.bin", 1, 0.0, 1e6, COUNT_MAX)
    events, _, out = _replay(tmp_path, cap)
    assert [e["kind"] for e in events if e["kind"] in SIGNAL or e["kind"] == "flat_blocks"] == ["signal_lost"], out


def _stretches(tmp_path: Path, *parts: tuple[str, float, int]) -> Path:
    """A capture of the simulated healthy board, 2 channels, no tacho, in stretches of (mode, seconds,
    fs), each with its STATUS, the board's t0 and seq going on."""
    out, t0, seq = b"", 0, 0
    for mode, seconds, fs in parts:
        data = board(mode, seconds, fs=fs, t0=t0, seq=seq, channels=2, tacho=False)
        out, t0, seq = out + data, t0 + round(seconds * fs), seq + frames(data)
    cap = tmp_path / "stretches.bin"
    cap.write_bytes(out)
    return cap


def test_the_flat_time_counts_each_block_at_its_rate(tmp_path):
    """6.5 s at 25 kHz, then the board's STATUS halves the rate (50 blocks a second): ch1 pinned from
    6.2 s on.  The decision of 6-7 s holds 30 flat blocks of 10 ms and 25 of 20 ms: 0.8 s (it said
    55 blocks at the new rate, 1.1 s)."""
    cap = _pinned(_stretches(tmp_path, ("raw", 6.5, 25_000), ("raw", 6, 12_500)), tmp_path / "dead.bin", 1, 6.2,
                  1e6, COUNT_MAX)
    events, sev, out = _replay(tmp_path, cap)
    said = [(e["kind"], e["message"]) for e in events if e["kind"] in SIGNAL]
    assert said == [("signal_lost", "ch1: no signal: every sample at 4095 counts (the ADC's rail) for 0.8 s of the "
                     "decision: a sensor, cable or ADC fault (monitor.flat_signal); severity 0.00 and the channel's "
                     "alarms held until it is back")], out


def test_a_flat_channel_stays_held_while_the_board_sends_rms_frames(tmp_path):
    """ch1 pinned from 5 s until the board switches to RMS frames at 6.5 s, back to RAW (moving) at
    10.5 s: the RMS frames show nothing of its samples, so the hold lasts until the RAW blocks move
    (it said ``signal back: its samples move again`` at the first decision of RMS frames)."""
    cap = _pinned(_stretches(tmp_path, ("raw", 6.5, 25_000), ("rms", 4, 25_000), ("raw", 4, 25_000)),
                  tmp_path / "dead.bin", 1, 5.0, 6.5, COUNT_MAX)
    events, sev, out = _replay(tmp_path, cap)
    said = [e for e in events if e["kind"] in SIGNAL]
    assert [(e["kind"], e["message"]) for e in said] == [
        ("signal_lost", "ch1: no signal: every sample at 4095 counts (the ADC's rail) for 1 s of the decision: a "
         "sensor, cable or ADC fault (monitor.flat_signal); severity 0.00 and the channel's alarms held until it "
         "is back"),
        ("signal_back", "ch1: signal back: its samples move again; severity and alarms judged again")], out
    lost, back = (e["timestamp"]["sec"] + e["timestamp"]["nsec"] / 1e9 for e in said)
    assert round(back - lost, 3) == 5.0
    assert [i for i, m in enumerate(sev["ch1"]) if m.get("signal_lost")] == [5, 6, 7, 8, 9], sev["ch1"]
    assert not [e for e in events if e["kind"] in ("failure", "severity_change")], out


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


@pytest.mark.parametrize("every", [1, 2])
def test_the_flat_signal_is_alike_however_the_stream_is_read(tmp_path, every):
    """A channel dead at mid-scale (or flat every other block), then alive again, read in 997-byte,
    64-kB and 1-MiB reads: every topic's messages (not /cm/diagnostics, which tells how the stream
    was read) are alike, the one signal_lost and signal_back among them."""
    cap = _pinned(_board(tmp_path, "--tacho"), tmp_path / "dead.bin", 1, 4.6, 9.3, 2048, every)
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
