"""The simulator's IIR filters (firmware_sim/scenarios/iir.py) are scipy.signal.lfilter's to the
bit (the one-coefficient numerators the scenarios use; a full biquad to rounding),
and a simulated board starts without importing scipy.signal (its ~0.65 s of CPU was most of
a board's start-up)."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from scipy.signal import lfilter as scipy_lfilter

from firmware_sim.scenarios import iir
from processes import ENV


@pytest.mark.parametrize("seed", range(6))
def test_the_resonance_and_one_pole_filters_are_lfilter_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(4000) * 10.0 ** rng.uniform(-3, 3)
    zeta, wn = rng.uniform(0.01, 0.2), rng.uniform(0.05, 2.5)
    r, wd = math.exp(-zeta * wn), wn * math.sqrt(1.0 - zeta * zeta)
    rho = rng.uniform(0.5, 0.999)
    for b, a in (([math.sin(wd)], [1.0, -2.0 * r * math.cos(wd), r * r]), ([1.0 - rho], [1.0, -rho])):
        assert np.array_equal(iir.lfilter(b, a, x), scipy_lfilter(b, a, x))
    b, a = [0.3, -0.2, 0.1], [2.0, -0.4, 0.1]           # a full biquad: its sums in another order
    np.testing.assert_allclose(iir.lfilter(b, a, x), scipy_lfilter(b, a, x), rtol=1e-12, atol=1e-12 * np.max(abs(x)))


def test_a_simulated_board_does_not_import_scipy_signal(tmp_path):
    p = subprocess.run([sys.executable, "-X", "importtime", "-m", "firmware_sim", "--scenario", "degrading_mic",
                        "--duration", "1", "--out", str(tmp_path / "board.bin")],
                       capture_output=True, text=True, timeout=60, env=ENV)
    assert p.returncode == 0, p.stderr[-2000:]
    imported = {line.rsplit("|", 1)[-1].strip() for line in p.stderr.splitlines() if line.startswith("import time:")}
    assert "firmware_sim.scenarios.iir" in imported and "scipy.signal" not in imported
