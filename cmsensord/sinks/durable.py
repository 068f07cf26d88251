"""Which events the rotating sink makes durable at once (an fsync at the loop's next tick) and
which ride the periodic fsync (``output.fsync_s``).

An fsync is a write to the SD card's flash: one per event on a noisy serial line (a
``frames_lost`` or ``decode_error`` every second or so) is ~73,000 a day instead of ~2,900.
So only the events that say what an operator must not lose to a power cut are fsynced at once
(:data:`FSYNC_AT_ONCE`: the machine's state, failures and alarms, a lost signal, the link or
the disk gone, the daemon's start and stop); the routine ones (lost, repeated or bad frames, a
stalled link, tacho pulses, severity steps, notes) are fsynced with everything else within
``fsync_s``.
"""

from __future__ import annotations

from collections.abc import Sequence

from cmsensord.sinks.schemas import TOPIC_EVENTS

__all__ = ["FSYNC_AT_ONCE", "urgent", "urgent_in"]

#: event kinds written to ``/cm/events`` that make the file fsynced at the next tick
FSYNC_AT_ONCE = frozenset({
    "failure", "failure_clear", "signal_lost", "signal_back",
    "alarm_alert", "alarm_danger", "alarm_clear", "alarm_ack", "alarm_restored", "alarm_not_restored",
    "alarm_state_error", "link_lost", "reader_died", "disk_error", "start", "stop",
})


def urgent(topic: str, msg: dict) -> bool:
    """Whether the message ``msg`` on ``topic`` is an event to fsync at once."""
    return topic == TOPIC_EVENTS and msg.get("kind") in FSYNC_AT_ONCE


def urgent_in(messages: Sequence[tuple[str, str, int, dict]], start: int, end: int) -> bool:
    """Whether ``messages[start:end]`` ``(topic, schema, stamp_ns, msg)`` hold an event to fsync at once."""
    return any(urgent(m[0], m[3]) for m in messages[start:end])
