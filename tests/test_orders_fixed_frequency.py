"""A fixed-frequency order component (``freq_hz``) without a bandwidth of its own takes
``orders.bandwidth_pct`` of its frequency, as an order takes it of its own."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from cmsensord.dsp.order_tracker.bandwidth import bandwidth_to_r, component_r
from cmsensord.dsp.order_tracker.components import TrackedComponent
from cmsensord.sinks.mcap_sink import read_messages
from processes import cmsensord, run_module


@pytest.fixture(scope="module")
def whirl(tmp_path_factory) -> Path:
    cap = tmp_path_factory.mktemp("whirl") / "whirl.bin"
    p = run_module("firmware_sim", "--scenario", "whirl", "--mode", "raw", "--tacho", "--duration", "60",
                   "--out", str(cap))
    assert p.returncode == 0, p.stderr
    return cap


def _whip(cap: Path, tmp: Path, whip: str) -> tuple[str, list[float]]:
    """Replay with components 1x and the 47-Hz whip (``whip``: its YAML mapping): stderr, the
    whip's RMS per valid /orders message."""
    tmp.mkdir()
    cfg = tmp / "whip.yaml"
    cfg.write_text(f"output:\n  status_line: false\norders:\n  components:\n    - {{name: 1x, order: 1}}\n"
                   f"    - {whip}\n")
    p = cmsensord("replay", str(cap), "--config", str(cfg), "--out", str(tmp / "logs"))
    assert p.returncode == 0, p.stderr
    (log,) = (tmp / "logs").glob("*.mcap")
    rms = [next(o.get("rms", math.nan) for o in m["orders"] if o["name"] == "whip")
           for t, _, m in read_messages(log) if t == "/cm/ch0/orders" and m["valid"]]
    return p.stderr, rms


def test_a_fixed_frequency_component_takes_the_default_bandwidth_pct_of_its_frequency(whirl, tmp_path):
    """Its r is solved for that bandwidth, not for a bandwidth of None (NaN: two RuntimeWarnings on
    stderr and no order amplitude at all in the log, of the whip nor of any other component)."""
    err, rms = _whip(whirl, tmp_path / "pct", "{name: whip, freq_hz: 47.0}")
    assert "RuntimeWarning" not in err and "Warning:" not in err, err
    _, want = _whip(whirl, tmp_path / "hz", "{name: whip, freq_hz: 47.0, bandwidth_hz: 2.35}")   # 5 % of 47 Hz
    assert len(rms) > 400 and all(math.isfinite(x) for x in rms)
    assert rms == pytest.approx(want, rel=1e-9)


def test_the_r_of_a_fixed_frequency_component_given_a_bandwidth_pct():
    whip = TrackedComponent("whip", freq_hz=47.0, bandwidth_pct=5.0)
    r = component_r([whip], [600.0, 3000.0], 500.0)
    assert r[:, 0] == pytest.approx([float(bandwidth_to_r(2.35, 47.0, 500.0))] * 2, rel=1e-12)
    with pytest.raises(ValueError, match="got nan..nan"):         # no bandwidth: no r, not a NaN one
        bandwidth_to_r(None, 47.0, 500.0)
