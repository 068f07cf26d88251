"""A sink that also hands every message to a publisher (the MQTT publisher of ``mqtt``).

:class:`TeeSink` wraps the run's MCAP sink: ``write`` writes to it, then offers the message
to the publisher, which only appends to its bounded hand-over queue. Everything else (``tick``,
``close``, ``paths``, ``on_event`` ...) is the wrapped sink's, so live, replay and simulate
publish without knowing. The publisher's events (link state, queue drops) are handed back to
``on_publisher_event`` from the caller's thread, at the next ``write`` or ``tick``.
"""

from __future__ import annotations

import logging
from typing import Any

_OWN = frozenset({"inner", "publisher", "_draining", "on_publisher_event"})


class TeeSink:
    """``inner`` (the MCAP sink) and ``publisher`` (``offer(topic, stamp_ns, msg)``, ``events``)."""

    def __init__(self, inner: Any, publisher: Any) -> None:
        object.__setattr__(self, "inner", inner)
        object.__setattr__(self, "publisher", publisher)
        object.__setattr__(self, "_draining", False)
        #: ``on_publisher_event(kind, message, log_level, fields)``: where the publisher's events go
        self.on_publisher_event: Any = None

    def write(self, topic: str, schema: str, stamp_ns: int, msg: dict) -> None:
        """Write to the MCAP sink, then offer the message to the publisher."""
        self.inner.write(topic, schema, stamp_ns, msg)
        self.publisher.offer(topic, stamp_ns, msg)
        if self.publisher.events:
            self.drain_events()

    def write_many(self, messages: list[tuple[str, str, int, dict]]) -> None:
        """:meth:`write` of each message: to the MCAP sink in one call (its ``write_many``, if
        it has one), then each offered to the publisher; its events after the last."""
        inner = self.inner
        if hasattr(type(inner), "write_many"):
            inner.write_many(messages)
        else:
            for m in messages:
                inner.write(*m)
        for topic, _, stamp_ns, msg in messages:
            self.publisher.offer(topic, stamp_ns, msg)
        if self.publisher.events:
            self.drain_events()

    def write_group(self, messages: list[tuple[str, str, int, dict]]) -> bool:
        """Write the group to the MCAP sink (whole or absent after a crash), then offer each
        message to the publisher; whether the MCAP sink took it (its answer)."""
        taken = self.inner.write_group(messages) is not False
        for topic, _, stamp_ns, msg in messages:
            self.publisher.offer(topic, stamp_ns, msg)
        if self.publisher.events:
            self.drain_events()
        return taken

    def channels_known(self, names: tuple[str, ...]) -> None:
        """The monitored channels are known (or changed): the publisher's discovery and worst
        alarms cover them."""
        self.publisher.set_channels(names)

    def tick(self) -> None:
        """The MCAP sink's tick, and the publisher's events."""
        self.inner.tick()
        self.drain_events()

    def close(self) -> Any:
        """Close the MCAP sink (its result), then stop the publisher (it sends what it can)."""
        try:
            return self.inner.close()
        finally:
            self.publisher.close()
            while self.publisher.events:        # after the log's end: to the journal only
                kind, message, level, _ = self.publisher.events.popleft()
                logging.getLogger("cmsensord").log(level, "%s: %s", kind, message)

    def drain_events(self) -> None:
        """The publisher's events -> ``on_publisher_event`` (the event log), in order, never
        re-entered (writing an event writes a message)."""
        events, on_event = self.publisher.events, self.on_publisher_event
        if self._draining or on_event is None:
            return
        object.__setattr__(self, "_draining", True)
        try:
            while events:
                kind, message, level, fields = events.popleft()
                on_event(kind, message, level, fields)
        finally:
            object.__setattr__(self, "_draining", False)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def __setattr__(self, name: str, value: Any) -> None:
        if name in _OWN:
            object.__setattr__(self, name, value)
        else:
            setattr(self.inner, name, value)
