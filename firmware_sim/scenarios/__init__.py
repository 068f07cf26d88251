"""Machine signal models: physical acceleration in m/s^2 (or sound in Pa) at fs = 25 kHz.

Owns the simulated *machines* the firmware_sim board samples (the board, its
ADC and framing live in :mod:`firmware_sim.board`). The machine of Kim et al.
2023 (section IV): a 3-phase, 4-pole, 3.7 kW induction motor at about 1720 rpm,
so f_r = 28.66 Hz, with an accelerometer on top of it; a motor is "faulty"
above 7.1 mm/s velocity RMS (ISO 10816, "unacceptable"). The scenarios
(:data:`SCENARIOS`, built by :func:`make_scenario`):

======================  ========================================================
``healthy``             the motor in good condition (ISO 10816 velocity RMS ~1.8 mm/s)
``faulty``              the same motor with unbalance/looseness (>7.1 mm/s) and an
                        outer-race bearing defect (impacts at BPFO ringing at 3 kHz)
``degrading``           healthy -> faulty -> worse -> easing over ``duration_s``: the
                        shape of the test input of Kim et al. 2023, Figs. 14-16
``spikes``              the illustrative input of Kim et al. 2023, Fig. 4: a random
                        100 Hz RMS sequence with 25 single-block spikes per second
``whirl``               Yeh, Pan & Le synthetic signal 1: journal-bearing run-up
                        0 -> 7000 rpm in 180 s with oil whirl (order 0.47) and whip (47 Hz)
``close_orders``        Yeh, Pan & Le synthetic signal 2: run-up 0 -> 3000 rpm in 5 s
                        with the close orders 4 and 4.2
``healthy_mic``,        the motors with a microphone (Pa) beside the accelerometer
``faulty_mic``,         (Orimoto, Ikuta & Wang); ``degrading_mic_only``: the degrading
``degrading_mic``       motor heard by a microphone alone
======================  ========================================================

Modules: :mod:`.noise` (seeded random streams, the 16-bit Gaussian noise, all
scenarios and the board share it), :mod:`.base` (:class:`Scenario`: segments,
caches, shaft angle; determinism and chunk invariance), :mod:`.motor`,
:mod:`.spikes`, :mod:`.runups`, :mod:`.microphone` (the machines),
:mod:`.truth` (true waveforms beside a capture), :mod:`.registry` (names).
"""

from __future__ import annotations

from .base import DEFAULT_CHANNEL_GAINS, Scenario
from .microphone import DegradingMicMotor, DegradingMicOnlyMotor, FaultyMicMotor, HealthyMicMotor
from .motor import DegradingMotor, FaultyMotor, HealthyMotor, MotorScenario, velocity_rms
from .noise import MACHINE_STREAM
from .registry import SCENARIOS, make_scenario
from .runups import CloseOrdersRunUp, RunUpScenario, WhirlRunUp
from .spikes import SpikesScenario
from .truth import truth_key, write_truth

__all__ = [
    "MACHINE_STREAM",
    "DEFAULT_CHANNEL_GAINS",
    "Scenario",
    "MotorScenario",
    "HealthyMotor",
    "FaultyMotor",
    "DegradingMotor",
    "SpikesScenario",
    "RunUpScenario",
    "WhirlRunUp",
    "CloseOrdersRunUp",
    "HealthyMicMotor",
    "FaultyMicMotor",
    "DegradingMicMotor",
    "DegradingMicOnlyMotor",
    "SCENARIOS",
    "write_truth",
    "truth_key",
    "make_scenario",
    "velocity_rms",
]
