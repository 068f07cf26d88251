"""With a tacho, its speed is the f_r of the anomaly decision (Kim et al. 2023 Fig. 3)."""

from __future__ import annotations

import pytest

from cmsensord.config import config_from_dict
from firmware_sim.board import Board, BoardConfig
from firmware_sim.scenarios import make_scenario
from stream import run_processor


def severity(mode, *, chunk=40_000, from_tacho=True, seconds=8.0, tacho=True):
    sc = make_scenario("faulty", n_channels=2, duration_s=seconds, seed=4)
    data = Board(sc, BoardConfig(n_channels=2, mode=mode, tacho=tacho)).generate(seconds)
    cfg = config_from_dict({"monitor": {"f_r": 10.0}, "tacho": {"f_r_from_tacho": from_tacho},
                            "channels": [{"name": "a"}, {"name": "b"}]})
    sink, _, _ = run_processor(data, cfg, chunk=chunk)
    return [(s, m) for t, s, m in sink.messages if t == "/cm/b/severity"]


@pytest.mark.parametrize("mode", ["rms", "raw"])
def test_the_tacho_speed_is_f_r(mode):
    sev = severity(mode)
    assert len(sev) == 8
    assert all(abs(m["f_r"] - 28.66) < 0.05 for _, m in sev[1:]), [m["f_r"] for _, m in sev]


def test_without_the_option_or_the_tacho_the_configured_f_r_is_used():
    assert all(m["f_r"] == 10.0 for _, m in severity("rms", from_tacho=False))
    assert all(m["f_r"] == 10.0 for _, m in severity("rms", tacho=False))


@pytest.mark.parametrize("mode", ["rms", "raw"])
def test_decisions_with_the_tacho_do_not_depend_on_the_reads(mode):
    assert severity(mode, chunk=40_000) == severity(mode, chunk=3_333)
