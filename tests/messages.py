"""Comparing the messages of two runs (live and replay, or two ways of feeding the same bytes)."""

from __future__ import annotations


def comparable(messages):
    """Severity and event messages with times relative to the first severity message.

    Only the wall-clock anchor may differ between a live run and a replay; the
    start/stop events name the source and are left out (on /cm/events and, as
    foxglove.Log records, on /cm/log).
    """
    sev = [s for t, s, _ in messages if t.endswith("/severity")]
    base = min(sev)
    out = []
    for topic, stamp, msg in messages:
        if topic == "/cm/diagnostics":
            continue
        if topic == "/cm/events" and msg["kind"] in ("start", "stop"):
            continue
        if topic == "/cm/log" and msg["message"].startswith(("start: ", "stop: ")):
            continue
        msg = {k: v for k, v in msg.items() if k != "timestamp"}
        out.append((topic, stamp - base, msg))
    return out
