"""The observations the AKF bank would watch, read from a capture through the daemon's path.

``read_observations`` replays a capture through the same decoder and Processor
as ``cmsensord replay`` (RAW blocks -> physical values -> block RMS, the block
clock with its missing slots, the tacho) and keeps, per channel, the block RMS of
every observation slot in [from, to] board seconds (NaN where an observation is
missing), the board's block rate and the shaft speed, and the median of each
indicator (``/cm/<ch>/indicators``, under the alarm manager's names) over the
records inside the window that miss at most ``indicators.max_missing_fraction`` of their
samples, as the daemon gives their spectral indicators (a bearing line the envelope spectrum does not resolve has none:
the replay's ``lines_unresolved`` events are among the notes, and so is the line that a RAW board's
records are shorter than ``indicators.interval_s``, or an RMS board's not that long, when they
are).  Commissioning learns from exactly what the daemon will see.
"""

from __future__ import annotations

import contextlib
import logging
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from cmsensord.alarms import Judged
from cmsensord.argtypes import Percent
from cmsensord.config import Config
from cmsensord.dsp.commissioning import idle_periods
from cmsensord.errors import CmsensordError
from cmsensord.importing.capture_settings import capture_settings
from cmsensord.importing.channel_names import capture_channels
from cmsensord.importing.sidecar import sidecar
from cmsensord.monitor.processor import Processor
from cmsensord.monitor.record_length import interval_note
from cmsensord.sinks.memory import ListSink
from cmsensord.sinks.schemas import TOPIC_EVENTS
from cmsensord.source import CaptureSource, require_frames
from cmsensord.terminal_bar import Progress

__all__ = ["Observations", "alarm_events", "read_observations", "sidecar"]


@dataclass(frozen=True)
class Observations:
    """Block RMS per observation slot of a board-time window, per channel."""

    names: list[str]
    indices: list[int]
    y: np.ndarray                 # (T, C), NaN = missing observation
    rate_hz: float                # observations per board second (fs / block_len)
    start_s: float                # board seconds of the first slot kept
    shaft_hz: float | None        # median tacho speed over the window (None: no tacho)
    rpm: float | None             # the capture's nominal speed (import sidecar), if any
    indicators: dict[str, dict[str, float]] = field(default_factory=dict)  # channel -> name -> median
    meta: dict = field(default_factory=dict)    # the import's sidecar ({}: not an import)
    notes: tuple[str, ...] = ()   # what the command says of the window (--to past the end, missing data)
    settings: dict[str, float] = field(default_factory=dict)  # indicators.* the sidecar gave (capture_settings)
    fs: float = 0.0               # the board's samples per second
    board_channels: int = 0       # the channels the board sent (the configuration may list fewer)
    capture_s: float | None = None  # the capture's board seconds (None: read only up to the window's end)
    #: channel -> why it has no signal (its signal_lost event's), for one with a decision of none in the window
    no_signal: dict[str, str] = field(default_factory=dict)

    @property
    def end_s(self) -> float:
        return self.start_s + self.y.shape[0] / self.rate_hz

    def period(self, decision_period_s: float) -> int:
        """Observation slots per decision, as the daemon counts them."""
        return max(1, int(round(decision_period_s * self.rate_hz)))


@contextlib.contextmanager
def _quiet(logger: logging.Logger):
    level = logger.level
    logger.setLevel(logging.CRITICAL)       # the replay's alarms and events are not the command's
    try:
        yield
    finally:
        logger.setLevel(level)


class _Collect:
    """The observations the banks watch, NaN where none came or the block was flat (no
    observation of the machine), and where none came."""

    def __init__(self) -> None:
        self.blocks: list[tuple[int, np.ndarray]] = []
        self.lost: list[np.ndarray] = []
        self.flat: list[np.ndarray] = []

    def __call__(self, first_slot: int, y: np.ndarray, valid: np.ndarray, seen: np.ndarray) -> None:
        self.blocks.append((first_slot, np.where(seen, y, np.nan)))
        self.lost.append(~valid)
        self.flat.append(valid & ~seen)


def read_observations(capture: str | Path, cfg: Config, *, auto_channels: bool = True,
                      from_s: float = 0.0, to_s: float | None = None) -> Observations:
    """Replay ``capture`` up to ``to_s`` and keep the observations in [from_s, to_s] (board
    seconds; a :class:`~cmsensord.argtypes.Percent` is that share of the capture's board time,
    which is then read whole).

    ``auto_channels``: the configuration lists no channels: an imported capture's channels are
    named as its import named them (as ``cmsensord replay`` names them), else the board's.
    """
    if to_s is not None and (isinstance(to_s, Percent) == isinstance(from_s, Percent) or not from_s) \
            and to_s <= from_s:
        raise CmsensordError(f"calibrate: --to {_said(to_s)} is not after --from {_said(from_s)}: the healthy "
                             "period runs from --from to --to (board seconds, or % of the capture)")
    require_frames(capture, "calibrate")
    meta = sidecar(capture)
    cfg, auto_channels, said = capture_channels(cfg, meta, auto_channels)
    if said:
        raise CmsensordError(f"calibrate: {said[0]}; calibrate learns it from such a --config BASE.yaml")
    cfg, settings, set_lines = capture_settings(cfg, meta)     # as a replay of the capture runs
    collect = _Collect()
    upto = None if isinstance(from_s, Percent) or isinstance(to_s, Percent) else to_s
    proc, sink = _replay(capture, cfg, auto_channels, upto, collect)
    if not collect.blocks:
        raise CmsensordError(f"calibrate: {capture}: no observations (no RMS or RAW frames)")
    rate = proc.fs / proc.block_len
    y, lost = np.concatenate([b for _, b in collect.blocks]), np.concatenate(collect.lost)
    flat = np.concatenate(collect.flat)
    total = y.shape[0] / rate
    first = int(np.floor(min(_seconds(from_s, total), total) * rate))
    last = y.shape[0] if to_s is None else int(np.floor(min(_seconds(to_s, total), total) * rate))
    if last <= first:
        end = "the end" if to_s is None else _said(to_s)
        raise CmsensordError(f"calibrate: {capture}: no observations between {_said(from_s)} and {end} "
                             f"(board seconds, or % of the capture; it holds {total:.1f} s)")
    shaft = _shaft_hz(sink, proc, first / rate, last / rate)
    rpm = meta.get("rpm")
    names = [ch.name for ch in proc.channels]
    medians, lossy = _indicator_medians(sink, proc, first / rate, last / rate)   # by the Processor's names
    return Observations(names=names, indices=[ch.index for ch in proc.channels],
                        y=y[first:last], rate_hz=rate, start_s=first / rate, shaft_hz=shaft,
                        rpm=float(rpm) if rpm else None,
                        indicators={name: medians[ch.name] for name, ch in zip(names, proc.channels)
                                    if ch.name in medians}, meta=meta,
                        notes=tuple(set_lines) + _window_notes(lost[first:last], rate, total, to_s)
                        + lossy + _capped(cfg, proc) + _unresolved(sink) + _flat_notes(flat[first:last], names),
                        settings=settings, fs=float(proc.fs), board_channels=proc.setup.n_board,
                        capture_s=total if upto is None or proc.adc_seconds <= upto + 2.0 else None,
                        no_signal=_no_signal(sink, proc, first / rate, last / rate))


def _window_notes(lost: np.ndarray, rate: float, total: float, to_s: float | None) -> tuple[str, ...]:
    """A line when ``--to`` is past the capture's end, and one on the observations the window
    misses (``lost``: blocks the board lost, or an import left out)."""
    notes = []
    if to_s is not None and not isinstance(to_s, Percent) and to_s > total + 1.0 / rate:
        notes.append(f"--to {to_s:g} is past the capture's end ({total:.1f} board s): the healthy period ends there")
    missing = int(np.count_nonzero(lost.any(axis=1)))
    if missing:
        notes.append(f"the healthy period misses {missing / rate:.1f} s of its {lost.shape[0] / rate:.1f} s "
                     "(blocks the board lost, or the import left out): learned from the rest")
    return tuple(notes)


def _capped(cfg: Config, proc: Processor) -> tuple[str, ...]:
    """The line that the RAW board's records are shorter than ``indicators.interval_s`` (more
    samples than a record holds at its rate: :func:`~cmsensord.monitor.record_length.capped_interval`),
    or the RMS board's not that long (not a whole number of its blocks:
    :func:`~cmsensord.monitor.record_length.rounded_interval`), so the indicator baselines are
    medians over records of that length."""
    st = proc.setup.status
    line = None if st is None else interval_note(cfg, st.mode, st.fs, st.block_len)
    return (line,) if line else ()


def _unresolved(sink: ListSink) -> tuple[str, ...]:
    """The ``lines_unresolved`` events of the replay (each once: bearing lines the envelope
    spectrum's bins do not resolve, so the site file has no baseline of them)."""
    return tuple(m["message"] for topic, _, m in sink.messages
                 if topic == TOPIC_EVENTS and m.get("kind") == "lines_unresolved")


def _flat_notes(flat: np.ndarray, names: list[str]) -> tuple[str, ...]:
    """A line per channel with flat blocks (``flat``: (T, C) of the healthy period), not learned
    from (``monitor.flat_signal``)."""
    return tuple(f"{name}: {n} flat block(s) in the healthy period (every sample one ADC count: a loose "
                 "connector or cable?): not learned from" for name, n in zip(names, flat.sum(axis=0).tolist()) if n)


def _replay(capture: str | Path, cfg: Config, auto_channels: bool, to_s: float | None,
            observe: _Collect | None = None, finish: bool = False,
            what: str = "the healthy period", judged: Judged | None = None) -> tuple[Processor, ListSink]:
    """The Processor after a replay of ``capture`` up to ``to_s`` board seconds (and 2 s more;
    a :class:`~cmsensord.argtypes.Percent` or None: all of it), and the messages it wrote.
    ``finish``: also after a stop short of the end (what the stream left pending is written).
    ``judged``: the alarm manager keeps every value it judges in it
    (:attr:`~cmsensord.alarms.manager.AlarmManager.judged`).
    On a terminal a progress bar says how far it is (``what``: of what)."""
    cfg = replace(cfg, output=replace(cfg.output, akf_trace=False, status_line=False))
    sink = ListSink()
    proc = Processor(cfg, sink, auto_channels=auto_channels, observe=observe)
    proc.alarms.judged = judged
    with _quiet(logging.getLogger("cmsensord")), CaptureSource(capture) as source:
        progress = Progress(source.size, f"calibrate {Path(capture).name}: {what}")
        try:
            for frames in source:            # the default monitor's events mean nothing here
                proc.handle(frames)
                progress.update(source.bytes_read, f"{proc.adc_seconds:.0f} s" + (
                    f" of {to_s:.0f} s" if to_s is not None and not isinstance(to_s, Percent) else ""))
                if to_s is not None and not isinstance(to_s, Percent) and proc.adc_seconds > to_s + 2.0:
                    if finish:
                        proc.finish()
                    break
            else:
                proc.finish()
        finally:
            progress.close()
    return proc, sink


def alarm_events(capture: str | Path, cfg: Config, end_s: float,
                 judged: Judged | None = None) -> list[tuple[float, dict]]:
    """The alarm events (``alarm_alert``, ``alarm_danger``, ``alarm_clear``) that a replay of
    ``capture`` with ``cfg`` (a site configuration: its channels named) writes up to ``end_s``
    board seconds, each with its board second, in order; with the indicator settings the
    capture's sidecar gives, as ``cmsensord replay`` of it runs
    (:func:`~cmsensord.importing.capture_settings.capture_settings`).  ``judged``: gets every
    value the alarm manager judged, its ``origin_ns`` the stamp of board second 0."""
    cfg, _, _ = capture_settings(cfg, sidecar(capture))
    proc, sink = _replay(capture, cfg, False, end_s, finish=True, what="its alarms", judged=judged)
    if proc.clock.slot0_t0 is None:
        return []
    t0 = proc.clock.slot_stamp_ns(0)
    if judged is not None:
        judged.origin_ns = t0
    changes = [((stamp - t0) / 1e9, m) for topic, stamp, m in sink.messages
               if topic == TOPIC_EVENTS and m.get("kind") in ("alarm_alert", "alarm_danger", "alarm_clear")]
    return [(t, m) for t, m in changes if t <= end_s + 1e-3]


def _seconds(at: float, total_s: float) -> float:
    """Board seconds of ``at`` (a :class:`~cmsensord.argtypes.Percent`: of ``total_s``)."""
    return at.seconds(total_s) if isinstance(at, Percent) else at


def _said(at: float) -> str:
    return str(at) if isinstance(at, Percent) else f"{at:g}"


def _indicator_medians(sink: ListSink, proc: Processor, start: float,
                       end: float) -> tuple[dict[str, dict[str, float]], tuple[str, ...]]:
    """Per channel, the median of each indicator over the records in [start, end] board seconds
    that miss at most ``indicators.max_missing_fraction`` of their samples (the limit up to which
    the daemon gives a record's spectral indicators), of the values each record carries (the zone
    left out: it is graded, not measured), the machine running: the records whose ``accel_rms``
    says it stopped, and its starts and stops beside them
    (:func:`~cmsensord.dsp.commissioning.idle_periods`), are left out, as calibrate leaves them
    out of the severity's model.  With them, the line on the records left out for lost samples
    (:func:`_lossy_notes`)."""
    from cmsensord.monitor.alarms import indicator_values

    if proc.clock.slot0_t0 is None:
        return {}, ()
    t0 = proc.clock.slot_stamp_ns(0)
    limit = proc.cfg.indicators.max_missing_fraction
    records: dict[str, list[dict[str, float]]] = {}
    counts: dict[str, list[int]] = {}            # channel -> [left out, in the period]
    for topic, stamp, m in sink.messages:
        if not topic.endswith("/indicators"):
            continue
        t_end = (stamp - t0) / 1e9
        if t_end - m["interval_s"] < start - 1e-3 or t_end > end + 1e-3:
            continue
        count = counts.setdefault(m["channel"], [0, 0])
        count[1] += 1
        if not m.get("missing_fraction", 1.0) <= limit:
            count[0] += 1
            continue
        records.setdefault(m["channel"], []).append(
            {k: v for k, v in indicator_values({k: v for k, v in m.items() if v is not None}).items()
             if k != "zone" and np.isfinite(v)})
    out = {}
    for ch, recs in records.items():
        idle = idle_periods(np.array([r.get("accel_rms", np.nan) for r in recs], dtype=np.float64))
        running = [r for r, i in zip(recs, idle) if not i] or recs
        values: dict[str, list[float]] = {}
        for r in running:
            for k, v in r.items():
                values.setdefault(k, []).append(v)
        out[ch] = {k: float(np.median(v)) for k, v in values.items()}
    return out, _lossy_notes(counts, limit)


def _lossy_notes(counts: dict[str, list[int]], limit: float) -> tuple[str, ...]:
    """The line on the indicator records of the healthy period left out for missing more than
    ``limit`` of their samples (``counts``: channel -> [left out, records]), per channel when the
    channels differ, naming the channels left with no record at all (no indicator baseline) and
    what gives them one."""
    lossy = {ch: c for ch, c in counts.items() if c[0]}
    if not lossy:
        return ()
    why = f"more than {100 * limit:g} % of their samples lost (indicators.max_missing_fraction {limit:g})"
    if len({tuple(c) for c in counts.values()}) == 1:
        left, total = next(iter(lossy.values()))
        said = f"{left} of {total} indicator record(s) of the healthy period left out: {why}"
    else:
        said = f"indicator records of the healthy period left out, {why}: " + ", ".join(
            f"{ch} {c[0]} of {c[1]}" for ch, c in lossy.items())
    empty = [ch for ch, c in lossy.items() if c[0] == c[1]]
    if empty:
        said += (f"; so no indicator baseline for {', '.join(empty)}: calibrate on a healthy period from a "
                 "better link, or give a higher indicators.max_missing_fraction in --config BASE.yaml")
    return (said,)


def _shaft_hz(sink: ListSink, proc: Processor, start: float, end: float) -> float | None:
    """Median f_r of the decisions in the window, when the tacho gave it."""
    if proc.tacho is None or not proc.cfg.tacho.f_r_from_tacho:
        return None
    vals = [m["f_r"] for t, _, m in sink.messages if t.endswith("/severity") and "f_r" in m]
    if not vals:
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return float(np.nanmedian(vals))


def _no_signal(sink: ListSink, proc: Processor, start: float, end: float) -> dict[str, str]:
    """Per channel with a decision ending in (start, end] board seconds that had no signal because
    its samples were flat (``monitor.flat_signal``): why, as its ``signal_lost`` event said it. A
    level under ``monitor.signal_floor`` is left out: the machine may have stopped, and the
    stopped decisions are not learned from anyway (:func:`idle_periods`)."""
    if proc.clock.slot0_t0 is None:
        return {}
    t0 = proc.clock.slot_stamp_ns(0)
    said: dict[str, dict] = {}                  # per channel: its last signal_lost event so far
    out: dict[str, str] = {}
    for topic, stamp, m in sorted(sink.messages, key=lambda x: (x[1], x[0] != "/cm/events")):
        if topic == "/cm/events" and m.get("kind") == "signal_lost":
            said[str(m.get("channel"))] = m
        elif topic.endswith("/severity") and m.get("signal_lost") \
                and start + 1e-3 < (stamp - t0) / 1e9 <= end + 1e-3:
            why = said.get(m["channel"])
            if why is not None and "level_ratio" not in why:        # flat, not quiet
                out[m["channel"]] = why["message"].partition("no signal: ")[2].partition(": a sensor")[0]
    return out
