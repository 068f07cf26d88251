"""The scenarios by name, and :func:`make_scenario` that builds one with checked parameters."""

from __future__ import annotations

from typing import Any

from .base import Scenario, keyword_params
from .microphone import DegradingMicMotor, DegradingMicOnlyMotor, FaultyMicMotor, HealthyMicMotor
from .motor import DegradingMotor, FaultyMotor, HealthyMotor
from .runups import CloseOrdersRunUp, WhirlRunUp
from .spikes import SpikesScenario

__all__ = ["SCENARIOS", "make_scenario"]

#: every scenario by its name (the ``--scenario`` of the command lines), in listing order
SCENARIOS: dict[str, type[Scenario]] = {
    "healthy": HealthyMotor,
    "faulty": FaultyMotor,
    "degrading": DegradingMotor,
    "spikes": SpikesScenario,
    "whirl": WhirlRunUp,
    "close_orders": CloseOrdersRunUp,
    "healthy_mic": HealthyMicMotor,
    "faulty_mic": FaultyMicMotor,
    "degrading_mic": DegradingMicMotor,
    "degrading_mic_only": DegradingMicOnlyMotor,
}


def make_scenario(name: str, *, n_channels: int = 1, duration_s: float = 3600.0, seed: int = 0,
                  **params: Any) -> Scenario:
    """Build scenario ``name``; unknown names and parameters raise ValueError listing the valid ones."""
    factory = SCENARIOS.get(name)
    if factory is None:
        raise ValueError(f"unknown scenario {name!r}; known: {', '.join(SCENARIOS)}")
    accepted = keyword_params(factory)
    bad = [p for p in params if p not in accepted]
    if bad:
        raise ValueError(f"scenario {name!r} has no parameter {', '.join(map(repr, bad))}; "
                         f"accepted: {', '.join(a for a in accepted if a not in ('n_channels', 'duration_s', 'seed'))}")
    return factory(n_channels=n_channels, duration_s=duration_s, seed=seed, **params)
