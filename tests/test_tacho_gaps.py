"""Frames lost for less than ``tacho.timeout_s``: the shaft speed across the gap, replayed.

A capture cut in a few places (bytes a UART dropped) loses RAW and TACHO frames alike.  The
edge interval across such a gap holds the pulses of the lost frames: counted when the speed
before and after says how many (a steady machine), else not taken (a run-up: the run starts
again after the gap).  The records and order blocks around a gap carry the speed the
edges they saw give (cmsensord/dsp/tacho/gaps.py).
"""

from __future__ import annotations

from pathlib import Path

from cmsensord.sinks.mcap_sink import read_messages
from processes import cmsensord, run_module


def capture(path: Path, scenario: str, *args: str) -> bytes:
    p = run_module("firmware_sim", "--scenario", scenario, "--mode", "raw", "--tacho", *args, "--out", str(path))
    assert p.returncode == 0, p.stderr
    return path.read_bytes()


def cut(data: bytes, fractions: tuple[float, ...], size: int = 15000) -> bytes:
    """``data`` without ``size`` bytes at each fraction of its length."""
    out, pos = bytearray(), 0
    for f in fractions:
        at = int(len(data) * f)
        out += data[pos:at]
        pos = at + size
    return bytes(out + data[pos:])


def replay(tmp_path: Path, name: str, *args: str) -> dict[str, list[tuple[int, dict]]]:
    """The replay's messages by topic: (log time, message)."""
    p = cmsensord("replay", f"{name}.bin", "--out", name, *args, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    got: dict[str, list[tuple[int, dict]]] = {}
    for topic, t, m in read_messages(next((tmp_path / name).glob("*.mcap"))):
        got.setdefault(topic, []).append((t, m))
    return got


def test_a_steady_machines_speed_across_short_gaps_is_its_speed(tmp_path):
    """The motor at 1720 rpm (1719.6: its 28.66 Hz), three gaps of ~0.28 s: the records over
    a gap carried 1550 to 1810 rpm (the gap's nine revolutions taken as one, then extrapolated),
    and order blocks after it up to 2244 rpm."""
    data = capture(tmp_path / "whole.bin", "faulty", "--duration", "12")
    (tmp_path / "gaps.bin").write_bytes(cut(data, (0.25, 0.5, 0.75)))
    got = replay(tmp_path, "gaps")
    records = [m for _, m in got["/cm/ch0/indicators"]]
    assert sum(m["missing_fraction"] > 0 for m in records) == 3
    off = [(m["speed_rpm"], m["missing_fraction"]) for m in records if abs(m["speed_rpm"] / 1719.6 - 1) > 0.005]
    assert off == [], off
    orders = [m for _, m in got["/cm/ch0/orders"] if m["valid"]]
    assert len(orders) > 100
    off = [(m["speed_rpm"], m["missing_fraction"]) for m in orders if abs(m["speed_rpm"] / 1719.6 - 1) > 0.005]
    assert off == [], off
    kinds = [m["kind"] for _, m in got["/cm/events"]]
    assert kinds.count("frames_lost") == 3 and "tacho_lost" not in kinds, kinds


def test_a_run_up_with_short_gaps_follows_its_ramp(tmp_path):
    """close_orders, 0 -> 3000 rpm in 5 s (600 rpm/s), four gaps of ~0.28 s, a record every
    0.25 s: the speed across a gap changes by more than the count of the lost pulses allows, so
    the run starts again after it.  Every record gives the speed of the same record of the
    whole capture (a record over a gap, the speed of the samples it holds, on a ramp): they
    were 10 to 83 % off."""
    data = capture(tmp_path / "whole.bin", "close_orders")
    (tmp_path / "gaps.bin").write_bytes(cut(data, (0.3, 0.5, 0.7, 0.85)))
    (tmp_path / "iv.yaml").write_text("indicators:\n  interval_s: 0.25\n")

    def speeds(name: str) -> dict[int, tuple[float | None, float]]:
        recs = replay(tmp_path, name, "--config", "iv.yaml")["/cm/ch0/indicators"]
        first = recs[0][0]
        return {round((t - first) / 250e6): (m.get("speed_rpm"), m["missing_fraction"]) for t, m in recs}

    whole, gaps = speeds("whole"), speeds("gaps")
    holed = [k for k, (_, mf) in gaps.items() if mf > 0]
    assert len(holed) == 4, gaps
    compared = 0
    for k, (rpm, mf) in gaps.items():
        ref = whole[k][0]
        if ref is None or ref < 500:
            continue
        compared += 1
        assert rpm is not None and abs(rpm / ref - 1) < (0.01 if mf else 1e-4), (k, rpm, ref, mf)
    assert compared >= 12, gaps
