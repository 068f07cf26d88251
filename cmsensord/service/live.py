"""The daemon's real-time loop: serial source -> Processor -> MCAP, with systemd and signals."""

from __future__ import annotations

import json
import logging
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence

from cmsensord import __version__
from cmsensord.config import Config, config_to_dict
from cmsensord.errors import CaptureFileError, ConfigError
from cmsensord.journal import under_journal
from cmsensord.kernels import fallback_note, fallback_warning
from cmsensord.monitor.processor import Processor
from cmsensord.out_paths import capture_refused
from cmsensord.protocol import Frame, FrameType
from cmsensord.sdnotify import Notifier
from cmsensord.service.alarm_store import keep_alarm_state
from cmsensord.service.config_file import ConfigFile
from cmsensord.service.control import ControlServer, socket_path
from cmsensord.service.dir_guard import DirGuard
from cmsensord.service.heap import keep_freed_memory
from cmsensord.service.instance import HeldDir, claim_output_dir
from cmsensord.service.signals import StopFlag
from cmsensord.service.sink import open_sink, publish_lines, publisher_of, route_sink_events
from cmsensord.service.status import StatusPace, run_summary, status_line
from cmsensord.source import BATCH_S, FAR_WAKE_S, HOLD_S, SerialSource

log = logging.getLogger("cmsensord")

#: the board's clock is compared with the wall clock only with fewer frames than this queued
DRIFT_QUEUE_MAX = 50
#: reader events logged as ERROR: a failure of the daemon's own code, for the maintainer
_ERRORS = frozenset({"reader_error", "reader_died"})
#: exit status when the reader thread has ended (EX_SOFTWARE): the unit restarts the daemon
EXIT_READER_DIED = 70


class ReaderDied(Exception):
    """The serial reader thread ended while the loop still ran (it only ends on stop)."""

#: a port open this long with never a byte is a ``link_stalled`` (a board off behind a USB adapter)
NEVER_S = 10.0
#: /cm/diagnostics at least this often (seconds), also when no decision brings one
DIAGNOSTICS_S = 5.0


def _open_capture(path: str | None, *, append: bool, inputs: Sequence[str] = ()):
    """The ``--capture`` file (None without one), opened before the sink (a path that cannot be
    written leaves no log behind), refused when it is one of ``inputs`` (the configuration and the files it
    names) or no regular file (CaptureFileError, :func:`~cmsensord.out_paths.capture_refused`).
    The daemon (``append``) adds to what an earlier run captured there, with a line saying so (a
    replay reads the daemon's restart as a gap of lost frames); a simulated run writes it afresh."""
    if not path:
        return None
    refused = capture_refused(path, inputs)
    if refused is not None:
        raise CaptureFileError(refused)
    try:
        before = os.path.getsize(path) if append and os.path.isfile(path) else 0
        capture = open(path, "ab" if append else "wb")
    except OSError as exc:
        raise CaptureFileError(f"{path}: cannot write the capture file: {exc.strerror or exc}; give --capture "
                               "a file in a writable directory") from None
    if before:
        log.info("capture: appending to %s (%.1f MB captured there before: a replay reads this restart "
                 "as a gap)", path, before / 1e6)
    return capture


def named_files(cfg: Config) -> list[str]:
    """The files ``cfg`` names: microphone calibrations, MQTT credentials and TLS files."""
    files = [ch.calibration for ch in cfg.channels] + [cfg.acoustic.calibration]
    if cfg.mqtt is not None:
        files += [getattr(cfg.mqtt, key) for key in ("password_file", "ca_file", "certfile", "keyfile")]
    return [str(f) for f in files if f]


class _Watch:
    """What the loop notices besides frames: queue drops, a stalled link (no bytes, or bytes but
    no valid frame, for ``link.stall_s``), the end of a simulation.  A turn of the loop that
    comes longer than ``link.stall_s`` (and the loop's longest wait) after the one before
    follows a freeze of the process (SIGSTOP, a paused VM, a machine stuck on I/O): the reader
    stood still too, and what the board sent meanwhile waits in the port, so the link is judged
    at the next turn, once the reader has had the loop's wait to read it."""

    def __init__(self, cfg: Config, proc: Processor, source: SerialSource,
                 duration_s: float | None, sim_done: threading.Event | None):
        self.cfg, self.proc, self.source = cfg, proc, source
        self.duration_s, self.sim_done = duration_s, sim_done
        self.stalled = False
        self.stall_why = ""                     # "no bytes" or "bytes but no valid frame"
        self.idle_since: float | None = None
        self.drops_seen = 0
        self.last_frame = time.monotonic()      # a valid frame, or the start
        self.turned = self.last_frame           # the loop's newest turn (:meth:`done`)

    def frame_wait(self, now: float) -> float:
        """Seconds without a valid frame: since the newest, or since the port was opened when that
        is later (frames from before a replug say nothing of the bytes after it)."""
        return now - max(self.last_frame, self.source.reader.opened_at)

    def link_events(self) -> None:
        """The reader's link events (stamped when they happened, on the stream's time base:
        :meth:`~cmsensord.monitor.diagnostics.Diagnostics.wall_stamp`) and the queue's drops become events."""
        proc, events, queue = self.proc, self.source.events, self.source.queue
        while events:
            wall_ns, kind, message = events.popleft()
            if kind in _ERRORS:
                proc.event(kind, None, message, proc.diag.wall_stamp(wall_ns), log_level=logging.ERROR)
            else:
                proc.event(kind, None, message, proc.diag.wall_stamp(wall_ns))
        if queue.drops != self.drops_seen:
            proc.event("queue_overflow", None, f"processing fell behind: {queue.drops - self.drops_seen} "
                       f"frame(s) dropped from the queue, oldest RAW blocks first ({queue.drops} "
                       f"in all, {queue.raw_drops} RAW)", count=queue.drops - self.drops_seen,
                       raw_total=queue.raw_drops)
            self.drops_seen = queue.drops

    def done(self, got_frames: bool, now: float) -> bool:
        """True when the run is over (simulated board finished); notes a stalled link."""
        gap, self.turned = now - self.turned, now
        if self.duration_s is not None and self.proc.board_seconds >= self.duration_s:
            return True                 # the simulated board's clock reached the end of the run
        if got_frames:
            self.idle_since = None
            self.stalled = False
            self.last_frame = now
            return False
        self.idle_since = self.idle_since or now
        if self.sim_done is not None and self.sim_done.is_set() and now - self.idle_since > 1.0:
            return True                 # the simulated board has sent everything and it is read
        reader, link = self.source.reader, self.cfg.link
        if self.stalled or not reader.connected.is_set():
            return False
        if gap > max(link.stall_s, FAR_WAKE_S):
            return False                # frozen: the reader's turn to read what came first
        # link_quiet first: what the board sent is in the file before the event (and its journal
        # line) says the link stalled; the one after the event makes the event durable too
        last_bytes = self.source.last_bytes
        if now - last_bytes > link.stall_s and self.proc.anchor_ns is not None:
            self.stalled, self.stall_why = True, "no bytes"
            self.proc.link_quiet()
            self.proc.event("link_stalled", None, f"{link.port}: no bytes for {link.stall_s:g} s",
                            self.proc.diag.wall_stamp())
        elif now - last_bytes > NEVER_S and self.proc.anchor_ns is None and not self.source.counters.bytes_received:
            self.stalled, self.stall_why = True, "no bytes since the port opened"
            self.proc.event("link_stalled", None, f"{link.port}: open for {NEVER_S:g} s and no byte yet (is "
                            "the board powered and sending? the right port?)", self.proc.diag.wall_stamp())
        elif self.frame_wait(now) > link.stall_s and now - last_bytes <= link.stall_s:
            self.stalled, self.stall_why = True, "bytes but no valid frame"
            self.proc.link_quiet()
            self.proc.event("link_stalled", None, f"{link.port}: bytes but no valid frame for "
                            f"{self.frame_wait(now):.1f} s (wrong baud rate, or line noise?)",
                            self.proc.diag.wall_stamp())
            self.proc.write_diagnostics(self.proc.diag.wall_stamp())
        if self.stalled:
            self.proc.link_quiet()
        return False

    def stall_text(self, now: float) -> str:
        """The stall in progress, for the status line ("" when frames come)."""
        if not self.stalled:
            return ""
        return f"{self.cfg.link.port}: stalled, {self.stall_why} for {now - self.last_frame:.0f} s"

    def diagnostics(self, now: float) -> None:
        """``/cm/diagnostics`` when no decision wrote one for ``DIAGNOSTICS_S``, stamped when it is
        written (on the stream's time base: during an outage each at its own time)."""
        if now - self.proc.diag.at >= DIAGNOSTICS_S:
            self.proc.write_diagnostics(self.proc.diag.wall_stamp())


def board_time_parts(frames: list[Frame], span: int) -> list[list[Frame]]:
    """``frames`` cut into runs of less than ``span`` board samples (t0 from a run's first
    frame; a t0 stepping back starts a run).  One batch of a board faster than real time
    (a simulation) spans many BATCH_S of board time; handled whole, the messages it writes
    would come out of log-time order by up to that span, and the sink holds such messages
    back that long before they are in the file (cmsensord/sinks/reorder.py)."""
    if not frames or frames[-1].t0_unwrapped - frames[0].t0_unwrapped < span:
        return [frames]
    parts, start, first = [], 0, frames[0].t0_unwrapped
    for i, f in enumerate(frames):
        t0 = f.t0_unwrapped
        if t0 - first >= span or t0 < first:
            parts.append(frames[start:i])
            start, first = i, t0
    parts.append(frames[start:])
    return parts


def output_parts(frames: list[Frame], wake_t0: Callable[[], int | None], span: int,
                 longest: int) -> Iterator[list[Frame]]:
    """``frames`` in the parts to handle one after the other: each ends with the block that
    completes the next output (``wake_t0()``, asked again after each part is handled) and
    spans less than ``longest`` board samples; without such a block, :func:`board_time_parts`
    of ``span``.  A part then holds at most one decision period or /orders block, so what it
    writes is in log-time order as with parts of ``span`` (an AKF trace's slots before the
    decision of their period), while a slow stream (RMS: 1 s a decision) takes one call per
    output instead of one per ``span``."""
    rest = frames
    while rest:
        wake, first = wake_t0(), rest[0].t0_unwrapped
        if wake is None or wake < first:    # none, or one waiting for more than its frames
            part = board_time_parts(rest, span)[0]
        else:                               # up to that block's last frame
            end = next((i for i, f in enumerate(rest) if f.t0_unwrapped > wake or f.t0_unwrapped < first
                        or f.t0_unwrapped - first >= longest), len(rest))
            part = rest[:max(end, 1)]
        yield part
        rest = rest[len(part):]


def can_wait(frames: list[Frame], start: int, wake: int | None, far: int) -> bool:
    """Whether ``frames[start:]`` (past the block that completed an output) may wait for the
    block completing the next one, ``wake``: all RMS frames of one stretch of the board's clock
    (nothing in them is written before that output: a STATUS frame, a loss or a reset is handled
    at once), and that block more than ``far`` board samples past the newest of them."""
    first, last = frames[start].t0_unwrapped, frames[-1].t0_unwrapped
    return (wake is not None and wake - last > far and last >= first
            and all(f.type is FrameType.RMS and not f.lost_before for f in frames[start:]))


def run_live(cfg: Config, *, auto_channels: bool, duration_s: float | None = None,
             sim_done: threading.Event | None = None, capture_path: str | None = None,
             metadata: dict[str, str] | None = None, open_port: Callable | None = None,
             simulated: bool = False, inputs: Sequence[str] = (), config_file: ConfigFile | None = None) -> int:
    """The real-time loop: reader thread -> bounded queue -> Processor -> MCAP (``open_port``:
    how the reader opens the port, default pyserial's ``Serial``; ``inputs``: the configuration's
    files, which the ``--capture`` file must not be, nor one ``cfg`` names), the output directory held
    against a second daemon (:mod:`.instance`) from before its sink salvages what it finds there.
    The alarm state is restored from and kept in the output directory's state file
    (:mod:`.alarm_store`) by the daemon holding the directory's lock only, and a capture is
    appended to; ``simulated`` (``--simulate``: a simulated board, not the machine): neither, and
    retention counts and deletes only this run's files (the machine's logs of the prefix are
    left alone).  A refused ``--capture`` (:func:`~cmsensord.out_paths.capture_refused`) raises
    CaptureFileError before the output directory is made or locked.  ``config_file``: the daemon's
    configuration file, read again at a SIGHUP to say whether it holds other settings than the
    running ones (:mod:`.config_file`)."""
    inputs = [*inputs, *named_files(cfg)]
    refused = capture_refused(capture_path, inputs) if capture_path else None
    if refused is not None:             # before the directory and its lock are made
        raise CaptureFileError(refused)
    fd = claim_output_dir(cfg.output.dir)
    held = HeldDir(cfg.output.dir, fd) if fd is not None else None
    try:
        return _run_live(cfg, auto_channels=auto_channels, duration_s=duration_s, sim_done=sim_done,
                         capture_path=capture_path, metadata=metadata, open_port=open_port,
                         simulated=simulated, held=held, inputs=inputs, config_file=config_file)
    finally:
        if held is not None:
            held.close()


def _run_live(cfg: Config, *, auto_channels: bool, duration_s: float | None, sim_done: threading.Event | None,
              capture_path: str | None, metadata: dict[str, str] | None, open_port: Callable | None,
              simulated: bool, held: HeldDir | None, inputs: Sequence[str],
              config_file: ConfigFile | None) -> int:
    keep_freed_memory()                 # each call's arrays from the heap, not fresh zeroed pages
    stop = StopFlag()
    stop.install()
    stop.install_reopen()
    keep_alarms = not simulated and held is not None
    capture = _open_capture(capture_path, append=keep_alarms, inputs=inputs)
    sink = open_sink(cfg, metadata or {}, background_salvage=True, publish=True, command="the daemon",
                     own_files=simulated)
    source = SerialSource.from_link(cfg.link, capture=capture, open_port=open_port)
    queue = source.queue
    sink.wake = queue.poke              # a salvage event is made durable at once, not a batch later
    stop.wake = queue.poke              # SIGTERM ends the wait for frames
    proc: Processor
    publisher = publisher_of(sink)
    proc = Processor(cfg, sink, auto_channels=auto_channels, link_counters=source.counters.as_dict,
                     arrived=lambda: source.reader.newest,
                     diagnostics=lambda: {"queue_depth": len(queue), "queue_drops": queue.drops,
                                          "lag_s": round(proc.lag_s(), 3),
                                          **({"mqtt": publisher.diagnostics()} if publisher else {})})
    t_start = time.monotonic()
    proc.event("start", None, f"cmsensord {__version__} on {cfg.link.port}")
    route_sink_events(sink, proc.log)       # salvage at start, disk errors: events from now on
    if keep_alarms:
        keep_alarm_state(cfg, proc)         # latches and acknowledgements of the run before
    control = _control(cfg, proc)           # cmsensord ack / status
    if control is not None:
        control.wake = queue.poke           # a request is answered at once, not at the loop's next wake-up
    log.info("effective settings: %s", json.dumps(config_to_dict(cfg), default=str))
    warning = fallback_warning()
    if warning:
        log.warning("%s", warning)
    status = 0
    refused: ConfigError | None = None
    with source:
        try:
            _loop(cfg, proc, sink, source, stop, _Watch(cfg, proc, source, duration_s, sim_done), control,
                  DirGuard(held, control, _emitter(proc), time.monotonic()), config_file)
        except ReaderDied as died:
            proc.event("reader_died", None, str(died), log_level=logging.ERROR)
            status = EXIT_READER_DIED
        except ConfigError as exc:      # the settings against the board's channels, once it sent them
            refused = exc
            proc.event("config", None, "configuration error: " + str(exc).removeprefix(exc.source + ": "),
                       log_level=logging.ERROR)
        finally:
            if stop.event.is_set():     # SIGTERM: a salvage under way stops between records
                sink.stop_salvage()
            source.stop()
            for frames in source if refused is None else ():    # what the reader queued before it stopped
                proc.handle(frames)
            if control is not None:
                control.close()
            proc.finish()
            proc.event("stop", None, f"cmsensord stopping ({stop.why()})", proc.diag.wall_stamp())
            sink.close()
            _close_capture(capture, source)
    print(run_summary(proc, sink.paths, time.monotonic() - t_start, publish_lines(sink)), file=sys.stderr)
    if capture_path:
        stopped = source.reader.capture_error
        print(f"  capture: {capture_path}" + (f" (stopped: {stopped}; what came after is not in it)"
                                               if stopped else ""), file=sys.stderr)
    if refused is not None:
        raise refused
    return status


def _close_capture(capture, source: SerialSource) -> None:
    """Close the ``--capture`` file; its last buffered bytes failing to go (a full disk) is the
    capture's error, said in the summary, not a traceback."""
    if capture is None:
        return
    try:
        capture.close()
    except OSError as exc:
        reader = source.reader
        reader.capture_error = reader.capture_error or f"capture file: {exc.strerror or exc}"


def _control(cfg: Config, proc: Processor) -> ControlServer | None:
    """The control socket in the output directory (None, with a config event, if it cannot be made)."""
    path = socket_path(cfg.output.dir)
    try:
        return ControlServer(path)
    except OSError as exc:
        proc.event("config", None, f"control socket {path} not started ({exc.strerror or exc}): "
                   "cmsensord ack and status cannot reach this daemon")
        return None


def _emitter(proc: Processor) -> Callable[[str, str, int, dict], None]:
    """Events of the daemon's surroundings (:class:`DirGuard`'s), stamped by the wall clock."""
    return lambda kind, message, level, details: proc.event(kind, None, message, proc.diag.wall_stamp(),
                                                           log_level=level, details=details)


def _process(cfg: Config, proc: Processor, source: SerialSource, watch: _Watch,
             control: ControlServer | None, frames: list) -> None:
    """One batch of frames through the Processor, then what comes between batches."""
    span = round(BATCH_S * proc.fs)
    # with the AKF trace (~100 messages a slot's second, the sink's reorder window holding some),
    # parts of BATCH_S as before: longer ones kept a decision's messages unflushed ~0.1 s longer
    longest = span if cfg.output.akf_trace else round(HOLD_S * proc.fs)
    done = 0
    for part in output_parts(frames, proc.wake_t0, span, longest):
        proc.handle(part)
        done += len(part)
        if done < len(frames) and not cfg.output.akf_trace and can_wait(frames, done, proc.wake_t0(), 2 * span):
            source.keep(frames[done:])      # handled with the block completing the next output
            break
    source.wake_at(proc.wake_t0(), proc.fs)     # batches end where an /orders block or a decision does
    if control is not None:
        control.apply(proc)                 # acks and status requests, between batches
    if frames and watch.sim_done is None and len(source.queue) < DRIFT_QUEUE_MAX:
        proc.check_wall(cfg.link.max_drift_s)   # not behind: the lag is the board's clock
    watch.link_events()
    if not frames and not source.waiting:       # no data moves the events' release on: the wall clock does
        if watch.sim_done is None:
            proc.check_wall(cfg.link.max_drift_s, idle=True)    # a step of it in an outage, at once
        proc.idle(proc.diag.wall_stamp())       # nor the alarm state's saves
        # the wall clock on the stream's time base (re-anchored at a step of it), not the newest
        # stamp: a board ahead of the wall clock releases its events with its decisions, as a replay
        proc.log.release(proc.clock.on_base_ns(proc.clock_ns()))


def _loop(cfg: Config, proc: Processor, sink, source: SerialSource, stop: StopFlag,
          watch: _Watch, control: ControlServer | None, guard: DirGuard, config_file: ConfigFile | None) -> None:
    notify = Notifier()                 # systemd Type=notify; does nothing without NOTIFY_SOCKET
    reader = source.reader

    fallback = fallback_note()
    publisher = publisher_of(sink)

    disk = getattr(sink, "outage_state", None)

    def line_now() -> str:              # the status line; a disk outage, a missing C kernel, the broker link
        line = status_line(proc, source)
        for more in (watch.stall_text(time.monotonic()), disk() if disk is not None else ""):
            if more:
                line = f"{line} | {more}"
        if fallback:
            line = f"{line} | {fallback}"
        return f"{line} | {publisher.status()}" if publisher is not None else line

    def service_state(line: str) -> str:    # STATUS=: the status line, and what the daemon waits for
        if reader.error is not None:
            return f"reader error x{reader.errors}: {reader.error} | {line}"
        return line if reader.connected.is_set() else f"waiting for {cfg.link.port} | {line}"

    if control is not None:             # cmsensord status: the whole line, as systemd's STATUS=
        control.status_line = lambda: service_state(line_now())

    if notify.watchdog_interval_s:      # the loop wakes twice per ping interval: a ping is never late
        source.timeout = min(source.timeout, notify.watchdog_interval_s / 2)
        source.far_timeout = min(source.far_timeout, notify.watchdog_interval_s / 2)
    if notify.enabled:
        reader.connected.wait(0.2)      # a present port opens within ms: READY's STATUS says which
    notify.ready(service_state(line_now()))
    next_status = time.monotonic() + 1.0
    pace = StatusPace(under_journal())
    try:
        for frames in source:
            if not reader.is_alive():   # it ends only on stop: reading nothing, the loop must not look well
                raise ReaderDied(f"the serial reader thread has ended; exiting with status "
                                 f"{EXIT_READER_DIED} for the service manager to restart the daemon")
            notify.watchdog()           # only here: a loop stuck anywhere below stops the pings
            _process(cfg, proc, source, watch, control, frames)
            now = time.monotonic()
            if stop.reopen:             # SIGHUP: finish the current file, start a new one
                stop.reopen = False
                sink.reopen()
                _reload_note(proc, config_file)
            # frames held for the block completing the next output are frames that came; a stall
            # noticed here (its partial interval written) is made durable by this tick, not the next
            over = watch.done(bool(frames) or bool(source.waiting), now) or stop.event.is_set()
            sink.tick()                 # flush by flush_s, fsync events and by fsync_s, retry a full disk
            guard.check(now)            # the directory deleted: its lock and socket made again
            if over:
                break
            if now >= next_status:      # once a second on average (the loop wakes every WAKE_S, or each decision)
                next_status = max(next_status + 1.0, now + 0.5)
                watch.diagnostics(now)
                _status(cfg, notify, line_now, service_state, pace.due(now))
    finally:
        notify.stopping("stopping: closing the MCAP log")


def _reload_note(proc: Processor, config_file: ConfigFile | None) -> None:
    """At a SIGHUP, a ``config`` warning when the configuration file holds other settings than
    the running ones, or does not load (a reload applies none of it: :mod:`.config_file`)."""
    note = config_file.on_reload(proc.setup.calibrations) if config_file is not None else None
    if note is not None:
        proc.event("config", None, note, proc.diag.wall_stamp(), log_level=logging.WARNING)


def _status(cfg: Config, notify: Notifier, line_now: Callable[[], str],
            service_state: Callable[[str], str], printed: bool = True) -> None:
    """The status line (stderr when ``printed``: under the journal once a minute; else the debug
    log) and systemd's STATUS=, made once and only when one of them is wanted."""
    wanted = cfg.output.status_line or log.isEnabledFor(logging.DEBUG)
    if not (wanted or notify.enabled):
        return
    line = line_now()
    if cfg.output.status_line:
        if printed:
            print(line, file=sys.stderr, flush=True)
    else:
        log.debug("status: %s", line)
    if notify.enabled:
        notify.status(service_state(line))
