"""The AKF bank and severity index of Kim et al. 2023 on the simulated board, through bytes, decoder and Processor.

With the paper's parameters (the defaults: n = 10, R_min = 4e-3, R_max = 0.13,
z_c = 2.8, c = 0.4, f_r = 28.66 Hz):
- Fig. 5 on the board's `spikes` scenario;
- `healthy` never raises an anomaly in a simulated hour;
- `faulty` reaches S_idx >= 0.5;
- `degrading` rises through the levels, reaches a failure, and falls back (Figs. 15-16).
"""

from __future__ import annotations

import numpy as np
import pytest

from cmsensord.config import default_config
from cmsensord.dsp.akf import AkfBank
from cmsensord.monitor.processor import Processor
from cmsensord.protocol import Decoder
from cmsensord.sinks.memory import ListSink
from firmware_sim.board import Board, BoardConfig
from firmware_sim.scenarios import make_scenario


def run_scenario(name: str, seconds: float, seed: int = 0, channels: int = 1, **params):
    sc = make_scenario(name, n_channels=channels, duration_s=seconds, seed=seed, **params)
    board = Board(sc, BoardConfig(n_channels=channels))
    sink = ListSink()
    proc = Processor(default_config(channels), sink)
    dec = Decoder()
    for chunk in _chunks(board, int(seconds * 100)):
        proc.handle(dec.feed(chunk))
    proc.handle(dec.flush())
    assert dec.counters.crc_failures == 0 and dec.counters.frames_lost == 0
    return sink, proc


def _chunks(board, n_blocks, per=6000):
    buf = bytearray()
    for i, b in enumerate(board.iter_block_bytes(n_blocks)):
        buf += b
        if (i + 1) % per == 0:
            yield bytes(buf)
            buf.clear()
    if buf:
        yield bytes(buf)


@pytest.mark.parametrize("seed", [0, 1])
def test_fig5_on_the_board_spikes_scenario(seed):
    sc = make_scenario("spikes", duration_s=30, seed=seed)
    _, y = Board(sc, BoardConfig()).observations(3000)
    counts = {}
    for scaling in (True, False):
        bank = AkfBank(np.array([[1e-2]]), window=10, z_c=2.8, scaling=scaling)
        counts[scaling] = bank.process(y.astype(float)).outlier[:, 0, 0].reshape(30, 100).sum(1)[1:]
    assert (counts[True] == 25).all(), counts[True]          # every second after the first
    assert (counts[False] == 50).all(), counts[False]        # both edges of each spike without S(k)


def test_healthy_gives_no_anomaly_in_a_simulated_hour():
    sink, proc = run_scenario("healthy", 3600.0)
    sev = sink.topic("/cm/ch0/severity")
    assert len(sev) == 3600
    assert all(s["severity_index"] == 0 for s in sev)
    assert all(not any(s["anomaly"]) for s in sev)
    kinds = {e["kind"] for e in sink.topic("/cm/events")}
    assert not kinds & {"anomaly_onset", "severity_change", "failure"}


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_faulty_reaches_half_severity(seed):
    sink, _ = run_scenario("faulty", 120.0, seed=seed)
    sev = [s["severity_index"] for s in sink.topic("/cm/ch0/severity")]
    assert max(sev) >= 0.5


@pytest.mark.parametrize("seed", [0, 1])
def test_degrading_rises_through_levels_fails_and_eases(seed):
    dur = 3600.0
    sink, proc = run_scenario("degrading", dur, seed=seed)
    sev = np.array([s["severity_index"] for s in sink.topic("/cm/ch0/severity")])
    assert len(sev) == 3600
    assert np.all(sev[: int(0.25 * dur)] == 0)            # healthy stretch
    events = sink.topic("/cm/events")
    fails = [e for e in events if e["kind"] == "failure"]
    assert len(fails) >= 1
    # it rises through at least four distinct levels before the first failure
    first_fail = int(np.argmax(sev == 1.0))
    assert len(set(np.round(sev[:first_fail], 1)) - {0.0}) >= 4
    # and falls back as the vibration eases
    assert sev[-60:].mean() <= 0.5
    assert any(e["kind"] == "failure_clear" for e in events)
    changes = [e for e in events if e["kind"] == "severity_change"]
    assert any(e["severity_index"] < 1.0 for e in changes[changes.index(next(
        e for e in changes if e["severity_index"] == 1.0)):])
