"""Opening the MCAP sink of a run, and where its events go (with the journal level they deserve)."""

from __future__ import annotations

import logging
import math
import secrets
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

from cmsensord.config import Config
from cmsensord.errors import CmsensordError, ConfigError, SinkError
from cmsensord.monitor.events import EventLog
from cmsensord.service.instance import hold_output_dir
from cmsensord.sinks.mcap_file import log_files
from cmsensord.sinks.rotating import RotatingSink
from cmsensord.sinks.tee import TeeSink
from cmsensord.terminal_bar import Bar

#: disk_error events that report a recovery (details.action): INFO in the journal
_DISK_NEWS = frozenset({"resumed", "salvaged"})

log = logging.getLogger("cmsensord")


def run_id() -> str:
    """A new identity of a run (a daemon start, a replay): its UTC start and 8 random hex digits."""
    return f"{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}-{secrets.token_hex(4)}"


def open_sink(cfg: Config, metadata: dict[str, str], *, background_salvage: bool = False,
              publish: bool = False, command: str = "this run", max_lag_s: float | None = None,
              own_files: bool | None = None) -> RotatingSink:
    """The rotating MCAP sink of ``cfg.output``; SinkError if the directory is unusable (for the
    daemon a read-only one is not: it logs nothing until it is writable, :class:`RotatingSink`),
    InstanceError if a running daemon holds it and ``command`` is not the daemon. A
    ``command`` that is not the daemon holds the directory's lock while it writes (a daemon
    started meanwhile is refused; ``release`` after ``close`` lets it go), and its retention
    counts and deletes its own files only, said in one WARNING line when the directory holds
    other logs of the prefix (:func:`_say_own_retention`); so does the daemon on a simulated
    board (``own_files``: True).
    ``background_salvage``: leftover ``.part`` files are salvaged by a thread (the daemon).
    With an ``mqtt`` section and ``publish`` (the daemon, ``--simulate``, a ``--publish``
    option), a :class:`TeeSink` that also publishes (its thread started; its ``close`` stops
    it). With an ``mqtt`` section and not ``publish``, nothing is published and one INFO line
    says so: ``command`` (e.g. ``replay``) would publish as the live daemon of that
    configuration (its client id, its retained topics, its queue). Every file of the run gets
    ``metadata`` and the run's identity (``run``: :func:`run_id`) as its ``cmsensord`` metadata,
    by which a report tells the runs of its files apart. ``max_lag_s``: the longest lag the
    reorder window is opened to when one is expected (default 10 s;
    :mod:`~cmsensord.sinks.reorder_lag`)."""
    daemon = command == "the daemon"
    held = None if daemon else hold_output_dir(cfg.output.dir, command)   # the daemon's is run_live's
    own = not daemon if own_files is None else own_files
    if own:
        _say_own_retention(cfg, "simulated run" if daemon else command)
    _say_tight_cap(cfg)
    try:
        sink = RotatingSink(cfg.output, metadata={**metadata, "run": run_id()}, background_salvage=background_salvage,
                            max_lag_s=max_lag_s, own_files=own, wait_for_disk=daemon)
    except BaseException:
        if held is not None:
            held.close()
        raise
    sink.lock = held
    if cfg.mqtt is None:
        return sink
    if not publish:
        log.info("mqtt: the mqtt section is ignored: %s does not publish (it would publish as client_id "
                 "%s under %s/, the live daemon's); give --publish to publish it", command, cfg.mqtt.client,
                 cfg.mqtt.prefix)
        return sink
    from cmsensord.monitor.alarms import has_alarm_rules
    from cmsensord.publish.publisher import Publisher  # paho only when mqtt is configured

    queue_dir = cfg.mqtt.queue_path(cfg.output.dir)
    try:                                               # its channels: the Processor's, when known
        publisher = Publisher(cfg.mqtt, queue_dir, alarm_rules=has_alarm_rules(cfg),
                              wait_when_full=command != "the daemon", wait_for_disk=command == "the daemon")
    except OSError as exc:
        sink.close()
        raise _queue_dir_error(cfg, queue_dir, exc) from None
    publisher.start()
    if command != "the daemon":
        log.info("mqtt: %s publishes to %s:%d as client_id %s under %s/", command, cfg.mqtt.host,
                 cfg.mqtt.port, cfg.mqtt.client, cfg.mqtt.prefix)
    return TeeSink(sink, publisher)  # type: ignore[return-value]  # a RotatingSink to its callers


def _queue_dir_error(cfg: Config, queue_dir: str, exc: OSError) -> CmsensordError:
    """The error of a queue directory that cannot be used, naming the entry at fault: a
    ConfigError of ``mqtt.queue_dir`` when that is set, else a SinkError (the directory is in
    the output directory: output.dir or --out)."""
    why = "not a directory" if isinstance(exc, FileExistsError) else exc.strerror or str(exc)
    if exc.filename is not None and Path(exc.filename) != Path(queue_dir):
        why = f"{exc.filename}: {why}"
    reason = f"{queue_dir}: cannot use the MQTT queue directory: {why}"
    if cfg.mqtt is not None and cfg.mqtt.queue_dir is not None:
        return ConfigError("<code>", "mqtt.queue_dir", f"{reason} (set mqtt.queue_dir to a directory it can write)")
    return SinkError(reason)


def _say_tight_cap(cfg: Config) -> None:
    """One WARNING line when ``retain_mb`` cannot hold the file being written (up to ``rotate_mb``)
    and a finished one beside it: then, as that file grows, at times no finished log is kept."""
    o = cfg.output
    if o.retain_mb and o.retain_mb < 2 * o.rotate_mb:
        log.warning("retention: retain_mb = %g MB counts the file being written (up to rotate_mb = %g MB) too: "
                    "below 2 x rotate_mb, at times no finished log is kept; set retain_mb >= %g or rotate_mb "
                    "<= %g", o.retain_mb, o.rotate_mb, 2 * o.rotate_mb, o.retain_mb / 2)


def _say_own_retention(cfg: Config, command: str) -> None:
    """One WARNING line when ``command``'s retention could have deleted logs it did not write:
    limits set and logs of the prefix in the directory (the service's, say), left alone."""
    o = cfg.output
    if not (o.retain_mb or o.min_free_mb):
        return
    try:
        finished, parts = log_files(o.dir, o.prefix)
    except OSError:
        return
    if finished or parts:
        log.warning("retention: the %d log(s) of prefix %r already in %s are not this %s's: left alone; it "
                    "counts and deletes only its own under retain_mb and min_free_mb", len(finished) + len(parts),
                    o.prefix, o.dir, command)


def publish_lines(sink: RotatingSink) -> list[str]:
    """The exit summary's line of the sink's MQTT publisher (after ``close``), if it has one."""
    publisher = publisher_of(sink)
    return [publisher.summary()] if publisher is not None else []


def send_queued(sink: RotatingSink, stream: TextIO | None = None,
                interrupted: Callable[[], bool] = lambda: False) -> bool:
    """Before a run that publishes and is not the daemon (``replay --publish``) ends: wait until
    the broker has acknowledged what the run offered, saying so in one line (a bar on a
    terminal) and passing the publisher's events on as they come, as long as the broker
    acknowledges something every :data:`~cmsensord.publish.publisher.CONNACK_S` seconds and
    has not refused the connection. Ctrl-C stops waiting; what is left stays in the queue for
    the next run publishing from it (the summary says how many): a KeyboardInterrupt, or
    ``interrupted()`` once the wait has ended (a run that takes SIGINT itself stops the
    publisher's waiting then). Whether Ctrl-C stopped it."""
    publisher = publisher_of(sink)
    if publisher is None or not publisher.left() or publisher.give_up.is_set():
        return interrupted()
    from cmsensord.publish.publisher import CONNACK_S

    assert isinstance(sink, TeeSink), "a publisher is a TeeSink's"
    out, cfg, n, start = stream or sys.stderr, publisher.cfg, publisher.left(), publisher.acked_total
    bar = Bar(n, "mqtt: sending", out)

    def progress(acked: int) -> None:
        bar(acked - start)
        if publisher.events:
            sink.drain_events()

    try:                                # the line in it: a Ctrl-C right after it is one too
        print(f"mqtt: sending {n:,} message(s) to {cfg.host}:{cfg.port} before exiting ({_pace(publisher, n)}); "
              "Ctrl-C stops waiting, they stay queued", file=out)
        left = publisher.drain(progress=progress)
    except KeyboardInterrupt:
        left = -1
    finally:
        bar.close()
    sink.drain_events()
    if left > 0 and interrupted():
        left = -1
    if left < 0:
        print("mqtt: stopped waiting (Ctrl-C)", file=out)
    elif left and publisher.state == "refused":
        print("mqtt: the broker refused the connection: stopped waiting", file=out)
    elif left:
        print(f"mqtt: the broker acknowledged nothing for {CONNACK_S:g} s: stopped waiting", file=out)
    return left < 0


def _pace(publisher, n: int) -> str:
    """How the ``n`` waiting messages go, and how long the paced ones take: as fast as the broker
    takes them while connected, but for a backlog queued before the connection, at
    ``resend_per_s``; all of them at that pace once a publisher not connected yet connects."""
    per_s = publisher.cfg.resend_per_s
    rate = f"{per_s:g} a second, mqtt.resend_per_s"
    backlog = publisher.backlog()
    if backlog is None:
        return f"not connected: once it is, they are its backlog, sent at {rate}: about {math.ceil(n / per_s):,} s"
    if backlog:
        return (f"the {backlog:,} queued before the connection at {rate}, about {math.ceil(backlog / per_s):,} s; "
                "the rest as fast as the broker takes them")
    return "as fast as the broker takes them"


def publisher_of(sink: RotatingSink):
    """The sink's MQTT publisher, or None."""
    return sink.publisher if isinstance(sink, TeeSink) else None


def sink_log_level(kind: str, fields: dict) -> int | None:
    """The journal level of a sink event: INFO for a disk_error that reports a recovery (logging
    resumed, salvage), None (the kind's level) otherwise (retention's deletions: INFO, its kind's)."""
    if kind == "disk_error" and (fields.get("details") or {}).get("action") in _DISK_NEWS:
        return logging.INFO
    return None


def route_sink_events(sink: RotatingSink, log: EventLog) -> None:
    """The sink's events (salvage, disk errors, retention) go to the event log: /cm/events,
    the recent events and the journal. Queued ones (salvage at start) go now."""
    sink.on_event = lambda kind, message, **fields: log.emit(
        kind, None, message, log_level=sink_log_level(kind, fields), **fields)
    if isinstance(sink, TeeSink):
        sink.on_publisher_event = lambda kind, message, level, fields: log.emit(
            kind, None, message, log_level=level, **fields)
        sink.drain_events()
