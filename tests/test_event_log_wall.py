"""The journal's ten-minute limit is the journal's: /cm/events keeps every link, disk and broker
event (the wall-clock kinds, written as they come) past ten in ten minutes."""

from __future__ import annotations

import logging

from cmsensord.monitor.events import EventLog
from cmsensord.sinks.memory import ListSink
from cmsensord.sinks.schemas import TOPIC_EVENTS

S = 1_000_000_000


def test_fifteen_link_flaps_in_five_minutes_are_all_in_the_log_and_summarised_in_the_journal(caplog):
    sink = ListSink()
    log = EventLog(sink, default_stamp=lambda: 0)
    with caplog.at_level(logging.INFO, logger="cmsensord"):
        for k in range(15):
            log.emit("link_lost", None, f"/dev/ttyACM0: gone ({k})", 20 * k * S)
            log.emit("link_restored", None, f"/dev/ttyACM0 open again ({k})", (20 * k + 10) * S)
        log.summarise(final=True)
        log.flush()
    written = [m["kind"] for m in sink.topic(TOPIC_EVENTS)]
    assert written.count("link_lost") == 15 and written.count("link_restored") == 15
    journal = [r.getMessage() for r in caplog.records if r.getMessage().startswith("link_lost")]
    assert len(journal) == 11 and journal[-1] == (
        "link_lost: 5 more link_lost event(s) in 280 s: at most 10 per 600 s are written one by one")
