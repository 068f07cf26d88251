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
