"""The rotating sink's own events (a base of :class:`~cmsensord.sinks.rotating.RotatingSink`).

Events go to :attr:`RotatingSink.on_event` (``on_event(kind, message, **fields)``,
settable after construction: the Processor that turns them into ``/cm/events`` messages
and journal lines is created after the sink); until it is set they are queued. They are
delivered at the end of the public call that raised them, never from inside another
delivery, so an event written while the disk fails cannot loop: it is counted as dropped.
"""

from __future__ import annotations

import collections
from collections.abc import Callable
from typing import Any

__all__ = ["SinkEvents"]


class SinkEvents:
    """The sink's event queue: :meth:`emit` queues, :meth:`_deliver` hands the queue to
    ``on_event`` in order, never from inside another delivery."""

    _pending: collections.deque[tuple[str, str, dict]]
    _on_event: Callable[..., Any] | None
    #: called when an event is queued or the salvage thread hands its results over: the live loop
    #: wakes and ticks
    wake: Callable[[], Any] | None
    _delivering: bool

    @property
    def on_event(self) -> Callable[..., Any] | None:
        return self._on_event

    @on_event.setter
    def on_event(self, callback: Callable[..., Any] | None) -> None:
        self._on_event = callback
        self._deliver()

    @property
    def pending_events(self) -> list[tuple[str, str, dict]]:
        """Events not delivered yet (no on_event): (kind, message, fields)."""
        return list(self._pending)

    def emit(self, kind: str, message: str, **fields: Any) -> None:
        """Queue an event of the sink (delivered to ``on_event`` in order, or kept in
        :attr:`pending_events`), and wake whoever waits for it."""
        self._pending.append((kind, message, fields))
        if self.wake is not None:
            self.wake()

    def _deliver(self) -> None:
        if self._delivering or self._on_event is None:
            return
        self._delivering = True
        try:
            while self._pending:
                kind, message, fields = self._pending.popleft()
                self._on_event(kind, message, **fields)
        finally:
            self._delivering = False
