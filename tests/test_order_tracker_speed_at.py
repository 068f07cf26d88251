"""The order tracker given its speed as a function of the samples it reads (``process(y,
rpm=callable)``, what the daemon's order chain does) against the plain reference: the speed
at every input sample as an array.  The outputs are the same bit for bit, however the
stream is cut, and the tracker asks for one input sample in D, each once."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cmsensord.config import config_from_dict
from cmsensord.dsp.order_tracker import OrderTracker
from cmsensord.monitor.orders import OrderChain
from cmsensord.service.simulate import RUNUP_ORDERS
from firmware_sim.board import Board, BoardConfig
from firmware_sim.scenarios import make_scenario
from messages import comparable
from stream import run_processor
from tracker_cases import BACKENDS, CLOSE, SPLIT_SIG


class Asked:
    """rpm as a function of a call's samples, recording the absolute samples asked for."""

    def __init__(self, rpm: np.ndarray):
        self.rpm, self.asked = rpm, []

    def at(self, start: int):
        def speed(i):
            i = np.asarray(i)
            assert i.dtype.kind == "i" and (np.diff(i) > 0).all()
            self.asked.append(start + i)
            return self.rpm[start + i]
        return speed


def outputs_equal(a, b) -> None:
    for attr in ("index", "t_in", "rpm", "waveform", "missing", "smoothed_index", "smoothed_waveform"):
        np.testing.assert_array_equal(getattr(a, attr), getattr(b, attr), err_msg=attr)
    for blocks in ("blocks", "smoothed_blocks"):
        for f in ("start", "t_in", "rpm", "rms", "amplitude", "valid", "missing"):
            np.testing.assert_array_equal(getattr(getattr(a, blocks), f), getattr(getattr(b, blocks), f),
                                          err_msg=f"{blocks}.{f}")


def tracker(backend, gains="table", piece=None):
    tr = OrderTracker(CLOSE, fs_in=10000.0, max_rpm=3000.0, n_channels=2, gains=gains,
                      smoother_lag_s=0.03, backend=backend)
    if piece is not None:
        tr.piece = piece
    return tr


Y = np.stack([SPLIT_SIG.y, np.roll(SPLIT_SIG.y, 77)], axis=1)
RPM = SPLIT_SIG.rpm + 250.0 + np.sin(np.arange(len(SPLIT_SIG.rpm)) * 0.37)   # no two samples alike


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("gains", ["table", "exact"])
@settings(max_examples=10, deadline=None)
@given(cuts=st.lists(st.integers(min_value=0, max_value=len(RPM)), max_size=4),
       piece=st.sampled_from([None, 41]))
def test_speed_at_the_read_samples_equals_the_speed_at_every_sample(backend, gains, cuts, piece):
    """Cut anywhere (calls shorter than the filter delay, of one sample, empty; pieces of 41
    tracker samples within a call): every output and the carried state are those of the
    tracker given the speed of every sample, and the speed was asked at the first input
    and at the samples n with n + delay_in a multiple of D only, each once."""
    ref, got = tracker(backend, gains, piece), tracker(backend, gains, piece)
    assert ref.decimate == 8 and ref.delay_in > 8
    asked = Asked(RPM)
    bounds = [0, *sorted(cuts), len(RPM)]
    for a, b in zip(bounds, bounds[1:]):
        outputs_equal(got.process(Y[a:b], asked.at(a)), ref.process(Y[a:b], RPM[a:b]))
    np.testing.assert_array_equal(got.state.z, ref.state.z)
    n = np.concatenate(asked.asked)
    assert len(np.unique(n)) == len(n)
    D, d = ref.decimate, ref.delay_in
    want = np.union1d([0], np.arange(-d % D, len(RPM), D))
    np.testing.assert_array_equal(np.sort(n), want)


@pytest.mark.parametrize("backend", BACKENDS)
def test_array_and_function_calls_mix(backend):
    """A tracker fed the speed as arrays and as functions in turn gives the outputs of one fed
    arrays only (both keep the delay line's entries that are read)."""
    ref, got = tracker(backend), tracker(backend)
    asked = Asked(RPM)
    bounds = [0, 5, 3000, 3013, 7000, 7001, 11000, len(RPM)]
    for k, (a, b) in enumerate(zip(bounds, bounds[1:])):
        rpm = asked.at(a) if k % 2 else RPM[a:b]
        outputs_equal(got.process(Y[a:b], rpm), ref.process(Y[a:b], RPM[a:b]))


def test_a_tracker_without_decimation_asks_for_every_sample():
    """D = 1 (no anti-alias filter): the function is asked for every sample of the call."""
    kw = {"fs_in": 2000.0, "max_rpm": 3000.0, "smoother_lag_s": 0.05}
    ref, got = OrderTracker(CLOSE, **kw), OrderTracker(CLOSE, **kw)
    assert ref.decimate == 1
    y, rpm = SPLIT_SIG.y[:3000], RPM[:3000]
    asked = Asked(rpm)
    for a, b in ((0, 1000), (1000, 1000), (1000, 3000)):
        outputs_equal(got.process(y[a:b], asked.at(a)), ref.process(y[a:b], rpm[a:b]))
    np.testing.assert_array_equal(np.concatenate(asked.asked), np.arange(3000))


@pytest.mark.parametrize("speed", ["causal", "final"])
def test_the_order_chain_writes_what_the_speed_of_every_sample_gives(monkeypatch, speed):
    """Through the daemon (decoded frames, tacho, order chain) on a run-up with lost RAW and
    TACHO frames: the /orders messages are those of the chain asking the tacho for the
    speed at every sample (the reference: what it did before), message for message."""
    from cmsensord.protocol import Decoder, FrameType

    sc = make_scenario("close_orders", n_channels=1, duration_s=4.0, seed=1)
    data = Board(sc, BoardConfig(n_channels=1, mode="raw", tacho=True)).generate(4.0)
    frames = Decoder().feed(data)
    ends = [f.offset for f in frames[1:]] + [len(data)]
    rng = np.random.default_rng(5)
    drop = rng.random(len(frames)) < 0.01
    cut = b"".join(data[f.offset:e] for f, e, x in zip(frames, ends, drop)
                   if not (x and f.type in (FrameType.RAW, FrameType.TACHO)))
    cfg = config_from_dict({"orders": {**RUNUP_ORDERS["close_orders"], "speed": speed}})
    stream = data[:frames[0].offset] + cut
    got, proc, _ = run_processor(stream, cfg, chunk=9_001)
    assert proc.frames_lost > 5
    orig, orig_blocks = OrderTracker.process, OrderTracker.process_blocks

    def every_sample(self, y, rpm):
        return orig(self, y, rpm(np.arange(len(y))) if callable(rpm) else rpm)

    def every_sample_blocks(self, y, rpm):     # what the chain calls
        return orig_blocks(self, y, rpm(np.arange(len(y))) if callable(rpm) else rpm)

    monkeypatch.setattr(OrderTracker, "process", every_sample)
    monkeypatch.setattr(OrderTracker, "process_blocks", every_sample_blocks)
    asked = []
    rpm_of = OrderChain._rpm
    monkeypatch.setattr(OrderChain, "_rpm", lambda self, s: asked.append(len(s)) or rpm_of(self, s))
    ref, _, _ = run_processor(stream, cfg, chunk=9_001)
    assert sum(asked) >= 4 * 25000 - 25000                  # the reference asked at every sample
    orders = [m for m in got.messages if m[0] == "/cm/ch0/orders"]
    assert len(orders) >= 60
    assert orders == [m for m in ref.messages if m[0] == "/cm/ch0/orders"]
    assert comparable(got.messages) == comparable(ref.messages)     # all but the wall clock's uptime
