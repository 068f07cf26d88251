"""``cmsensord replay``: a capture file through the daemon's own Processor into MCAP."""

from __future__ import annotations

import json
import logging
import math
import os
import sys
import time
from pathlib import Path

from cmsensord.capture_print import commissioned_on
from cmsensord.config import CommissionedConfig, Config, ConfigError
from cmsensord.errors import EXIT_INTERRUPTED
from cmsensord.importing.capture_settings import capture_settings
from cmsensord.importing.channel_names import capture_channels
from cmsensord.importing.sidecar import sidecar
from cmsensord.importing.timeline import Timeline
from cmsensord.monitor.processor import Processor
from cmsensord.protocol import MAX_FRAME, Decoder
from cmsensord.service.heap import keep_freed_memory
from cmsensord.service.origin import FirstAlarms, delay_lines, origin_lines
from cmsensord.service.signals import Interrupt
from cmsensord.service.sink import open_sink, publish_lines, publisher_of, route_sink_events, send_queued
from cmsensord.service.status import run_summary
from cmsensord.source import CaptureSource, Paced, require_frames
from cmsensord.terminal_bar import Progress

log = logging.getLogger("cmsensord")

#: bytes per read of an unpaced replay: 192 KiB (3.9 s of 1 RAW channel, 1 s of 4); with the
#: heap keeping freed memory a larger read is faster still, but at 256 KiB a 4-channel RAW
#: replay's peak RSS passes 60 MB
REPLAY_CHUNK = 3 << 16


def replay(path: str, cfg: Config, *, auto_channels: bool, metadata: dict[str, str] | None = None,
           quiet: bool = False, speed: float | None = None, publish: bool = False
           ) -> tuple[int, Path | None, Processor]:
    """Process a capture file through the same decoder and Processor: as fast as possible,
    or paced at ``speed`` x the board's clock (1: real time); with ``auto_channels`` (``cfg``
    lists no channels), an imported capture's channels named as its import named them, and the
    indicator settings its sidecar gives (:func:`~cmsensord.importing.capture_settings.capture_settings`). An
    import has its :class:`~cmsensord.importing.timeline.Timeline` in the log's ``cmsensord``
    metadata (``recording_timeline``), board second 0 stamped at the ``board_zero_ns`` it
    gives. ``publish``: an ``mqtt`` section publishes the run (``--publish``); otherwise it
    is ignored.
    Returns (exit status, the last MCAP file or None if it could not be finished, the
    Processor)."""
    keep_freed_memory()         # the chain's arrays of each read from the heap, not fresh pages
    # as fast as possible: REPLAY_CHUNK reads, so each of the chain's per-call
    # costs (tacho, orders, indicators) comes a few times fewer; the messages are the same for
    # any split of the stream; the frames as columns (FrameBatch); the decoder holds a read and
    # the partial frame before it, so each read is one scan (one batch, nothing joined)
    capture = CaptureSource(path, chunk=REPLAY_CHUNK if speed is None else 1 << 12,   # LinkError before any output
                            decoder=Decoder(max_buffer=REPLAY_CHUNK + MAX_FRAME), batches=True)
    require_frames(path, "replay")      # the wrong file given: one line, exit 2, no log
    meta = sidecar(path)                # an import's: its channels' names, its snapshots
    cfg, auto_channels, warnings = capture_channels(cfg, meta, auto_channels)
    for warning in warnings:
        log.warning("%s", warning)
    cfg, _, said = capture_settings(cfg, meta)     # the snapshots' record length, the files' speed
    head = RecordingHead(path, meta, cfg.commissioned)
    # the lag a capture's post_s gives is held however long (no kill -9 to lose it to): the log
    # times are the messages' own, as a daemon's are within 10 s
    sink = open_sink(cfg, {**head.metadata, **(metadata or {})}, publish=publish,
                     command="replay", max_lag_s=math.inf)
    proc = Processor(cfg, sink, auto_channels=auto_channels, link_counters=capture.counters.as_dict)
    head.anchor(proc)
    route_sink_events(sink, proc.log)
    alarms = FirstAlarms(proc.log)
    progress = Progress(capture.size, f"replay {Path(path).name}")
    publisher = publisher_of(sink)
    interrupt = Interrupt(then=publisher.give_up.set if publisher is not None else None)
    source = capture if speed is None else Paced(capture, speed, sleep=interrupt.sleep)
    t0 = time.monotonic()
    interrupt.install()                 # to the end of the log: a Ctrl-C in finishing it is one too
    try:
        with source:
            for frames in source:
                proc.handle(frames)
                progress.update(capture.bytes_read, f"{proc.adc_seconds:.0f} s")
                if interrupt.seen:
                    break
        proc.finish()
        progress.close()
        if send_queued(sink, interrupted=lambda: interrupt.seen):
            interrupt.seen = True
    except ConfigError as exc:          # the settings against the channels, once the capture named them
        proc.event("config", None, "configuration error: " + str(exc).removeprefix(exc.source + ": "))
        proc.finish()
        raise
    finally:
        progress.close()
        out = sink.close()
        sink.release()                  # the directory's lock: a daemon may start now
        interrupt.restore()
    if not quiet:
        placed = [f"  {line}" for line in said] + origin_lines(meta, proc.views, alarms.board_s(proc.clock.anchor_ns)) \
            + delay_lines(meta, cfg) + publish_lines(sink) + _interrupted(interrupt, capture) \
            + ([head.note] if head.note else [])
        print(run_summary(proc, sink.paths, time.monotonic() - t0, placed), file=sys.stderr)
    return (EXIT_INTERRUPTED if interrupt.seen else 0), out, proc


class RecordingHead:
    """What a log of a capture run through the Processor (``replay``, ``vkf``) says of it in its
    ``cmsensord`` metadata, by which a report tells the recording it holds (:mod:`cmsensord.report.runs`):
    the capture's real path (``source``: one capture however its path was spelled) and, of an
    import, its :class:`~cmsensord.importing.timeline.Timeline` (``recording_timeline``) with
    the log time of board second 0 (``board_zero_ns``: when the run began), where
    :meth:`anchor` stamps the Processor's board second 0; and, when the configuration was
    commissioned on this capture (``commissioned.capture`` is its real path, or names a capture no
    longer found of the same size and ends: :func:`~cmsensord.capture_print.commissioned_on`),
    the healthy period the baselines were learned from, in its board seconds (``healthy_period``:
    JSON ``{"from_s": ..., "to_s": ...}``), which the report shades
    (:mod:`cmsensord.report.healthy`); :attr:`note` says why it is not written when the
    commissioned capture is not found and this one is not known to be it."""

    def __init__(self, path: str, meta: dict, commissioned: CommissionedConfig | None = None) -> None:
        self.timeline = Timeline.from_sidecar(meta)
        self.board_zero_ns = time.time_ns()
        self.metadata = {"source": os.path.realpath(path)}
        if self.timeline:
            self.metadata["recording_timeline"] = self.timeline.to_json(self.board_zero_ns)
        learned = commissioned or CommissionedConfig()
        same, why = commissioned_on(path, learned) if learned.from_s is not None else (False, "")
        #: the line on a healthy period not written though the configuration names one (empty: none)
        self.note = f"  note: the healthy period is not shaded: {why}" if why else ""
        if same and learned.from_s is not None and learned.to_s is not None:
            self.metadata["healthy_period"] = json.dumps({"from_s": learned.from_s, "to_s": learned.to_s})

    def anchor(self, proc: Processor) -> None:
        """An import's board clock starts at 0: its second 0 at :attr:`board_zero_ns`."""
        if self.timeline:
            proc.clock.anchor(0, self.board_zero_ns)


def _interrupted(interrupt: Interrupt, capture: CaptureSource) -> list[str]:
    """The summary's line on a replay stopped by Ctrl-C: how far it got."""
    if not interrupt.seen:
        return []
    done = capture.bytes_read / max(capture.size, 1)
    return [f"  interrupted (Ctrl-C) at {done:.0%} of the capture ({capture.bytes_read:,} of {capture.size:,} "
            "bytes): the log holds what was replayed"]

