"""Test doubles shared by the test modules."""

from __future__ import annotations


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
