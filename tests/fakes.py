"""Test doubles shared by the test modules."""

from __future__ import annotations

import struct


class FakeClock:
    """A clock the test sets by hand: calling it returns ``t`` (seconds, 100.0 at start).

    Stands in for ``time.monotonic`` wherever a sink or notifier takes a ``clock``;
    a test advances time with ``clock.t += dt``.
    """

    def __init__(self, t: float = 100.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def replay_ticking(cap, proc_of, sink, clock: FakeClock, step_s: float, **source_args) -> None:
    """A capture through a Processor (``proc_of(source)``, writing to ``sink``) as the live loop
    does: after each batch the clock moves on ``step_s`` and the sink ticks; then finished
    and closed."""
    from cmsensord.source import CaptureSource

    source = CaptureSource(cap, batches=True, **source_args)
    proc = proc_of(source)
    with source:
        for frames in source:
            proc.handle(frames)
            clock.t += step_s
            sink.tick()
    proc.finish()
    sink.close()


def tacho_payload(rnd, counts, p_cut: float, p_extra: float) -> bytes:
    """A random TACHO payload (docs/PROTOCOL.md: u16 N, N u32 offsets) of N from ``counts``;
    with probability ``p_cut`` cut short, else with ``p_extra`` 1-4 bytes too long."""
    n = rnd.choice(counts)
    p = struct.pack("<H", n) + b"".join(struct.pack("<I", rnd.randrange(2**32)) for _ in range(n))
    e = rnd.random()
    if e < p_cut:
        return p[:rnd.randrange(len(p))]
    if e < p_cut + p_extra:
        return p + rnd.randbytes(rnd.randrange(1, 5))
    return p
