"""The one-line status (stderr, systemd STATUS=) and the exit summary of a run."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path


def status_line(proc, source=None) -> str:
    """ADC time, each channel's severity and flags (a channel of the run no longer in the board's
    stream: that it is not), the worst active alarm, and (live) the link and queue counters."""
    parts = [f"[{proc.adc_seconds:8.1f} s]"]
    for v in proc.views:
        if v.left_s is not None:
            parts.append(f"{v.name} (not in the stream)")
            continue
        flags = "".join(str(a) for a in v.anomaly)
        parts.append(f"{v.name} S={v.severity:.1f} out/s={v.outliers_first:3d} F={flags}")
    alarm = proc.alarms.summary() if getattr(proc, "alarms", None) is not None else None
    if alarm:
        parts.append(alarm)
    if source is not None:
        c = source.counters
        lost = proc.segments.link({"frames_lost": c.frames_lost})["frames_lost"]
        parts.append(f"| rx {c.bytes_received} B, frames {sum(c.frames.values())}, "
                     f"lost {lost}, crc {c.crc_failures}")
        queue = source.queue
        parts.append(f"q {len(queue)} drop {queue.drops}")
        if source.link_down:
            parts.append(f"| {source.link_down}")
    return " ".join(parts)


#: under the journal, the status line is printed once in this many seconds (systemd's STATUS=
#: carries it every second): a trace of the state in the journal, not 86,400 lines a day
JOURNAL_STATUS_S = 60.0


class StatusPace:
    """When the status line is printed: at each call (once a second), or, when stderr is the
    journal, at the first call and then once in :data:`JOURNAL_STATUS_S`."""

    def __init__(self, journal: bool) -> None:
        self.every = JOURNAL_STATUS_S if journal else 0.0
        self.next = float("-inf")

    def due(self, now: float) -> bool:
        if now < self.next:
            return False
        self.next = now + self.every
        return True


#: the newest MCAP logs of a run the exit summary names (the older ones counted): a daemon
#: rotating every hour for months keeps its summary short
NAMED_LOGS = 5


def log_lines(paths: Sequence[Path]) -> list[str]:
    """``MCAP log: PATH`` of the newest :data:`NAMED_LOGS` of ``paths`` (oldest first), after a
    line counting the older ones when there are more."""
    older = len(paths) - NAMED_LOGS
    head = ([f"MCAP logs: {older} older one(s) of this run in {paths[0].parent}; the newest {NAMED_LOGS}:"]
            if older > 0 else [])
    return head + [f"MCAP log: {p}" for p in paths[max(older, 0):]]


def run_summary(proc, paths: list[Path], wall_s: float, placed: Sequence[str] = ()) -> str:
    """What a run wrote and saw, printed at its end (``placed``: lines after the channels', where
    an imported recording's severity levels and alarms came: :mod:`cmsensord.service.origin`)."""
    lines = log_lines(paths) + [
             f"  {proc.adc_seconds:.1f} s of ADC time in {wall_s:.1f} s wall "
             f"({proc.observations} observations, {proc.missing_observations} missing, "
             f"{proc.frames_lost} frames lost)"]
    period = proc.severity.decider.nominal_period / proc.severity.rate if proc.severity is not None else 1.0
    for v in proc.views:
        absent = absent_note(v)
        if not v.judged:
            span = "it was in the stream for less" if absent else "the recording is shorter"
            lines.append(f"  {v.name}: no decision ({span} than two decision periods "
                         f"of {period:.3g} s; the first is the filters' transient){absent}")
            continue
        held = " (held: no signal, see signal_lost)" if v.no_signal else ""
        before = f" and {v.restarts_before} time(s) before" if v.restarts_before else ""
        restarted = (f"; its filters restarted at {', '.join(f'{t:.0f} s' for t in v.restarts)}{before} "
                     "(a new set of channels)" if v.restarts else "")
        lines.append(f"  {v.name}: final severity {v.severity:.1f}{held}, max {v.max_severity:.1f}, "
                     f"{v.failures} failure event(s), {v.decisions} decisions{restarted}{absent}")
        lines.append(f"  {v.name}: {v.timeline.render()}")
    bounds = getattr(proc, "rms_bounds", None)      # the Processor's (an imported recording's has none)
    for name, n in (bounds.bad.items() if bounds is not None else ()):
        lines.append(f"  {name}: {n} RMS value(s) the board cannot send (not finite, negative or past its "
                     "ADC's range): missing observations, see the decode_error events")
    lines += placed
    if proc.event_counts:
        lines.append("  events: " + ", ".join(f"{k} {n}" for k, n in sorted(proc.event_counts.items())))
    link = link_line(proc.link())
    if link:
        lines.append(link)
    return "\n".join(lines)


def absent_note(view) -> str:
    """``; not in the stream 40-50 s, since 70 s``: the ADC seconds the channel of ``view`` was
    not in the board's stream (and has not been since), the older ones past those its view keeps
    counted (``... since 70 s, and 12 time(s) before``); "" when it always was."""
    spans = [f"{a:.0f}-{b:.0f} s" for a, b in view.absences]
    if view.left_s is not None:
        spans.append(f"since {view.left_s:.0f} s")
    before = f", and {view.absences_before} time(s) before" if view.absences_before else ""
    return f"; not in the stream {', '.join(spans)}{before}" if spans else ""


def link_line(counters: dict[str, int]) -> str:
    """The bytes of the link that were no good frame (docs/PROTOCOL.md rules 1-2, and frames received
    twice: cmsensord.frame_repeats), on one line; "" when there were none."""
    junk, crc, bad, twice = (counters.get(k, 0) for k in ("bytes_discarded", "crc_failures", "header_rejects",
                                                          "frames_repeated"))
    if not (junk or crc or bad):
        return ""
    return (f"  link: {junk} of {counters.get('bytes_received', 0)} bytes in no frame "
            f"({crc} CRC failure(s), {bad} bad header(s)" + (f", {twice} frame(s) received twice)" if twice else ")"))
