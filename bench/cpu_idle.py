"""The CPUs' idle state held at polling while a benchmark measures: a diagnostic.

While :func:`polling_idle` holds ``/dev/cpu_dma_latency`` open with a request of 0 µs
(Linux PM QoS), the kernel's cpuidle picks no idle state with an exit latency: an idle
CPU spins in its poll loop instead of halting.  On a virtual machine a halted virtual CPU
leaves its physical core to the host (a VM exit), and the code that runs after the wake-up
finds the core's caches and branch predictors holding someone else's work.  Polling keeps
the virtual CPU on its core, so a measurement taken both ways shows how much of a paced
loop's cost is the halt.  Not a setting for the board: a polling CPU draws full power.
Needs root; the request ends when the file is closed.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

PM_QOS = "/dev/cpu_dma_latency"
CPUIDLE = Path("/sys/devices/system/cpu/cpuidle")


def idle_driver() -> str:
    """The cpuidle driver and governor, e.g. ``haltpoll / haltpoll`` ("?" where unreadable)."""
    def read(name: str) -> str:
        try:
            return (CPUIDLE / name).read_text().strip()
        except OSError:
            return "?"
    return f"{read('current_driver')} / {read('current_governor_ro')}"


@contextmanager
def polling_idle(on: bool = True) -> Iterator[None]:
    """While in the block (``on``), every CPU polls when idle instead of halting."""
    if not on:
        yield
        return
    try:
        fd = os.open(PM_QOS, os.O_WRONLY)
    except OSError as exc:
        raise SystemExit(f"--idle-poll: cannot open {PM_QOS}: {exc.strerror} (it needs root)") from None
    try:
        os.write(fd, struct.pack("i", 0))
        yield
    finally:
        os.close(fd)
