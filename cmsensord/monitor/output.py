"""What the Processor makes, in its order: messages to the sink, events to the event log,
and what the alarm manager says of a message right after it."""

from __future__ import annotations

from cmsensord.monitor import messages
from cmsensord.monitor.alarms import WATCHED, Alarms
from cmsensord.monitor.events import Event, EventLog


class Output:
    """Messages and events of the monitoring chain to where they go (:meth:`out`)."""

    def __init__(self, sink, log: EventLog, alarms: Alarms):
        self.sink, self.log, self.alarms = sink, log, alarms
        # a sink's own write_many (not one a wrapper's __getattr__ hands on from what it wraps)
        self.write_many = sink.write_many if hasattr(type(sink), "write_many") else None

    def out(self, items) -> list:
        """Messages to the sink and events to the log, in their order: each run of messages
        in one call of the sink's ``write_many`` (the same as one ``write`` each), if it has one.
        Returns a new empty list."""
        if not items:
            return []
        run: list = []
        watching = self.alarms.watching
        for it in items:
            kind = type(it)
            if kind is Event:
                run = self._write_run(run)
                self.log.add((it,))
            elif kind is messages.MessageGroup:         # a capture: one chunk of the log
                run = self._write_run(run)
                taken = self.sink.write_group(list(it.messages)) is not False
                said = it.written if taken else it.dropped
                if said is not None:
                    self.log.add((said,))
            else:
                run.append(it)
                if watching and it.schema in WATCHED:   # the alarm manager reads it
                    more = self.alarms.see(it)
                    if more:
                        run = self._write_run(run)
                        self.out(more)
        return self._write_run(run)

    def _write_run(self, run: list) -> list:
        """Messages to the sink, in one call if it takes many; returns a new empty run."""
        if len(run) > 1 and self.write_many is not None:
            self.write_many(run)
        else:
            for m in run:
                self.sink.write(*m)
        return []
