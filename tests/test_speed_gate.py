"""The speed gate: rows wait for a final shaft speed, but never without limit."""

from __future__ import annotations

import numpy as np

from cmsensord.config import default_config
from cmsensord.monitor.orders import MAX_WAIT_S
from cmsensord.monitor.processor import Processor
from cmsensord.monitor.severity import PENDING_DECISION_SLOTS
from cmsensord.monitor.speed_gate import SpeedGate
from cmsensord.protocol import Decoder, FrameType, Status, encode_raw, encode_status
from cmsensord.sinks.memory import ListSink


def test_rows_wait_until_their_position_is_final():
    g = SpeedGate(max_rows=100)
    g.restart(1000)
    g.push(np.arange(10.0), np.ones(10, dtype=bool))
    g.push(np.arange(10.0, 15.0), np.zeros(5, dtype=bool))
    assert g.release(1000) is None and g.waiting == 15
    first, (a, b) = g.release(1012)
    assert first == 1000 and a.tolist() == list(range(12)) and b.tolist() == [True] * 10 + [False] * 2
    assert g.first == 1012 and g.waiting == 3
    assert g.release(2000, final=False)[1][0].tolist() == [12.0, 13.0, 14.0]   # never beyond the newest
    assert g.release(2000) is None


def test_final_releases_everything():
    g = SpeedGate(max_rows=100)
    g.restart(0)
    g.push(np.zeros(7))
    first, (a,) = g.release(-50, final=True)
    assert first == 0 and a.shape == (7,) and g.waiting == 0


def test_bounded_keeps_at_most_max_rows_waiting():
    """Pushed faster than the speed becomes final: with ``bounded`` the oldest go anyway."""
    g = SpeedGate(max_rows=50)
    g.restart(0)
    released = 0
    for _ in range(100):
        g.push(np.zeros((30, 2)))
        assert g.release(0) is None                     # the speed is final nowhere
        got = g.release(0, bounded=True)
        if got is not None:
            assert got[0] == released
            released += got[1][0].shape[0]
        assert g.waiting <= 50
    assert released + g.waiting == 3000


def test_a_tacho_that_never_sends_keeps_the_order_chain_bounded():
    """STATUS announces a tacho, TACHO frames never come: the RAW samples waiting for a speed
    in the order chain stay below MAX_WAIT_S of samples however long the stream runs."""
    st = Status(fw_version=0x0100, mode=2, n_channels=1, fs=25000, block_len=250, tacho_inputs=1,
                tacho_ppr=1, overruns=0, uptime_s=0, scale=(0.0244,), offset=(2048.0,))
    proc = Processor(default_config(1), ListSink(), clock_ns=lambda: 0)
    rng = np.random.default_rng(0)
    dec = Decoder()
    seq = 0
    most = 0
    for second in range(25):
        data = [encode_status(seq, second * 25000, st)]
        seq += 1
        for b in range(100):
            counts = (2048 + 40 * rng.standard_normal(250)).astype(np.uint16)
            data.append(encode_raw(seq, second * 25000 + b * 250, 0, counts))
            seq += 1
        frames = dec.feed(b"".join(data))
        assert not any(f.type == FrameType.TACHO for f in frames)
        proc.handle(frames)
        most = max(most, proc.orders.gate.waiting)
        assert proc.severity.gate.waiting <= PENDING_DECISION_SLOTS     # the decisions' gate too
    assert proc.orders is not None and proc.next_slot == 2500
    assert 0 < most <= MAX_WAIT_S * 25000 + 100 * 250
    assert proc.orders.gate.waiting <= MAX_WAIT_S * 25000
