"""A board whose STATUS halves its rate mid-stream (fs 25000 -> 12500, block 250: 100 -> 50 blocks
a second), replayed by a real ``cmsensord replay`` process: decisions come every
``monitor.decision_period_s`` of the new rate as they do for a board at that rate from the start,
with its ``decision_rule`` event, and the exit summary's ADC time adds each stretch at its rate."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cmsensord.protocol import MODE_RMS, Status, encode_rms, encode_status
from cmsensord.sinks.mcap_read import read_messages
from processes import cmsensord

pytestmark = pytest.mark.process

L = 250
STATUS = Status(0x0100, MODE_RMS, 1, 25000, L, 0, 0, 0, 0, (0.01,), (2048.0,))


@pytest.fixture
def halved_at_4_5_s() -> bytes:
    """450 blocks at 25 kHz (4.5 s, half-way through a decision), then 275 at 12.5 kHz (5.5 s), t0
    going on 250 a block, a STATUS each 100 blocks."""
    slow = dataclasses.replace(STATUS, fs=12500)
    rng = np.random.default_rng(0)
    out, seq = bytearray(), 0
    for k in range(725):
        if k % 100 == 0 or k == 450:
            out += encode_status(seq, k * L, STATUS if k < 450 else slow)
            seq += 1
        out += encode_rms(seq, k * L, [0.5 + 0.01 * rng.standard_normal()])
        seq += 1
    return bytes(out)


def test_decisions_follow_a_rate_change_every_decision_period(tmp_path, halved_at_4_5_s):
    """Before: the decision kept 100 observations, 2 s at the new rate (decisions at 5.5, 7.5 and 9.5 s),
    with no decision_rule event, and the summary said 14.5 s of ADC time for 10 s."""
    cap = tmp_path / "cap.bin"
    cap.write_bytes(halved_at_4_5_s)
    r = cmsensord("replay", str(cap), "--out", str(tmp_path / "out"))
    assert r.returncode == 0, r.stderr
    msgs = [(t, s, m) for f in (tmp_path / "out").glob("*.mcap") for t, s, m in read_messages(f)]
    stamps = [s for t, s, _ in msgs if t == "/cm/ch0/severity"]
    assert [s - stamps[0] for s in stamps] == [k * 1_000_000_000 for k in range(10)]
    assert [m["message"] for t, _, m in msgs if t == "/cm/events" and m["kind"] == "decision_rule"] == [
        "board block rate 50 blocks/s (fs 12500 / block 250), not 100: a decision is 50 observations (1 s); "
        "f_r 28.66 is 57% of them; the window N = 10 observations is 0.2 s"]
    assert "  10.0 s of ADC time" in r.stderr and "(725 observations, 0 missing, 0 frames lost)" in r.stderr, r.stderr


def test_the_summary_of_a_chain_made_after_a_rate_change_is_in_the_runs_seconds(tmp_path):
    """4.5 s at 25 kHz, 5.5 s at 12.5 kHz, then a second channel (a new chain) for 20 s: 30 s
    of ADC time, and both channels' timelines end at 30 s (guards against the new chain's
    start read at the new rate: 34 s)."""
    one = Status(0x0100, MODE_RMS, 1, 25000, L, 0, 0, 0, 0, (0.01,), (2048.0,))
    slow = dataclasses.replace(one, fs=12500)
    two = dataclasses.replace(slow, n_channels=2, scale=(0.01, 0.01), offset=(2048.0, 2048.0))
    rng = np.random.default_rng(0)
    out, seq = bytearray(), 0
    for k in range(1725):
        st = one if k < 450 else slow if k < 725 else two
        if k % 100 == 0 or k in (450, 725):
            out += encode_status(seq, k * L, st)
            seq += 1
        out += encode_rms(seq, k * L, [0.5 + 0.01 * rng.standard_normal()] * st.n_channels)
        seq += 1
    cap = tmp_path / "rc.bin"
    cap.write_bytes(bytes(out))
    r = cmsensord("replay", str(cap), "--out", str(tmp_path / "o"))
    assert r.returncode == 0, r.stderr
    assert "  30.0 s of ADC time" in r.stderr, r.stderr
    spans = [line.split("| ")[1].split(";")[0] for line in r.stderr.splitlines()
             if line.startswith(("  ch0: |", "  ch1: |"))]
    assert len(spans) == 2 and all(s.endswith("-30 s") for s in spans), r.stderr
