"""firmware_sim: the simulated TM4C1294 ADC board (see docs/PROTOCOL.md).

* :mod:`firmware_sim.scenarios` — machine signal models (``make_scenario``);
* :mod:`firmware_sim.board` — ADC, block RMS, tacho and framing (``Board``);
* :mod:`firmware_sim.pty_link` — the board's serial port as a pty;
* :mod:`firmware_sim.faults` — byte-stream fault injection;
* :mod:`firmware_sim.cli` — ``python -m firmware_sim``.
"""

from cmsensord import blas_threads  # noqa: F401, I001  (before numpy: one BLAS thread)

from .board import Board, BoardConfig
from .scenarios import SCENARIOS, Scenario, make_scenario

__all__ = ["Board", "BoardConfig", "SCENARIOS", "Scenario", "make_scenario"]
