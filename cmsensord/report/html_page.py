"""The report as one self-contained HTML page: inline CSS, PNG figures as base64 data URIs, no network.

Each figure is a ``<figure class="plot" data-meta="...">`` whose ``data-meta``
attribute holds its metadata as JSON (:class:`~cmsensord.report.figures.Figure`);
the same list is in ``<script type="application/json" id="figures">``.
Times are local times (ISO 8601 with the UTC offset), or an imported recording's own
(:mod:`.time_axis`). Logs of several recordings (:mod:`.runs`) give a part each, under the
recording's name: its cards, channels, events, link and disk, over its own time.
"""

from __future__ import annotations

import base64
import html
import json
from typing import Any

from cmsensord.report.log_data import MAX_EVENTS, LogData
from cmsensord.report.runs import BOARD_LOGS

__all__ = ["render_page"]

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",sans-serif;margin:0 auto;max-width:1150px;padding:0 16px 40px;
color:#1d1d1f;background:#fff}
h1{font-size:1.6em;margin:18px 0 4px}h2{font-size:1.25em;border-bottom:2px solid #1f4e99;padding-bottom:3px;
margin-top:30px}h2.recording{font-size:1.5em;border-bottom-width:5px;margin-top:48px}
h3{font-size:1.05em;margin:18px 0 6px}
.sub{color:#555;margin:0 0 12px}
table{border-collapse:collapse;font-size:.9em;margin:6px 0 14px}
td,th{border:1px solid #ccc;padding:3px 8px;text-align:left;vertical-align:top}
th{background:#eef2f8}td.t{white-space:nowrap}td.n{text-align:right;font-variant-numeric:tabular-nums}
figure.plot{margin:10px 0 18px}figure.plot img{max-width:100%;border:1px solid #ddd}
figcaption{font-size:.85em;color:#555}
.kind-failure td,.kind-alarm_danger td{background:#fde7e9}.kind-alarm_alert td{background:#fff3e0}
.kind-disk_error td,.kind-link_lost td{background:#fff8d6}
.events{max-height:520px;overflow:auto;display:block}
.cards{display:flex;gap:12px;flex-wrap:wrap}.card{border:1px solid #ccd;border-radius:6px;padding:6px 12px;
min-width:150px}.card b{display:block;font-size:1.3em}
"""


def _figure_html(fig: Any) -> str:
    src = base64.b64encode(fig.png).decode("ascii")
    meta = html.escape(json.dumps(fig.meta), quote=True)
    return (f'<figure class="plot" id="{html.escape(fig.meta["id"])}" data-meta="{meta}">'
            f'<img alt="{html.escape(fig.meta["title"])}" src="data:image/png;base64,{src}">'
            f'<figcaption>{html.escape(fig.meta.get("caption") or fig.meta["title"])}</figcaption></figure>')


def _cards(data: LogData) -> str:
    span = (data.end_ns - data.start_ns) / 1e9 if data.start_ns is not None and data.end_ns is not None else 0.0
    items = [("from", data.axis.text(data.start_ns)), ("to", data.axis.text(data.end_ns)),
             ("duration", f"{span / 3600:.2f} h" if span >= 3600 else f"{span:.0f} s"),
             ("messages", f"{data.messages:,}"), ("files", str(len(data.files))),
             ("events", f"{sum(data.event_counts.values()):,}")]
    return '<div class="cards">' + "".join(
        f'<div class="card">{html.escape(k)}<b>{html.escape(v)}</b></div>' for k, v in items) + "</div>"


def _events_table(data: LogData) -> str:
    counts = ", ".join(f"{html.escape(k)} {n}" for k, n in sorted(data.event_counts.items()))
    rows = "".join(
        f'<tr class="kind-{html.escape(ev["kind"])}"><td class="t">{data.axis.text(t, ms=True)}</td>'
        f'<td>{html.escape(ev["kind"])}</td>'
        f'<td>{html.escape(str(ev["channel"] or ""))}</td><td>{html.escape(ev["message"])}</td></tr>'
        for t, ev in data.events)
    more = sum(data.event_counts.values()) - len(data.events)
    note = f"<p>The first {MAX_EVENTS} events are listed; {more} more are counted above.</p>" if more > 0 else ""
    return (f"<h2>Events{_of(data)}</h2><p>By kind: {counts or 'none'}</p>{note}"
            f'<table class="events" id="{_id(data, "events")}"><tr><th>{data.axis.column}</th><th>kind</th>'
            f"<th>channel</th><th>message</th></tr>{rows}</table>")


def _of(data: LogData) -> str:
    """After a heading: whose it is, among several recordings."""
    return f" of {html.escape(data.recording)}" if data.recording else ""


def _id(data: LogData, name: str) -> str:
    """An element's id, after its recording's (:attr:`.runs.Recording.ident`) among several recordings."""
    return html.escape(f"{data.recording_id}-{name}" if data.recording else name)


def _file_state(f: Any) -> str:
    if f.left_out:
        return html.escape(f.left_out)
    if f.batch_only:
        return "read for its batch VKF orders only (the rest repeats the replay's); " + _read_state(f)
    if f.not_read():
        return html.escape(f"messages left out: {f.not_read()}; ") + _read_state(f)
    return _read_state(f)


def _read_state(f: Any) -> str:
    skipped = f"damaged: {len(f.skipped)} stretch(es) skipped (the first: {f.skipped[0]}); " if f.skipped else ""
    if f.error:
        return html.escape(f"{skipped}{'' if f.error == f.cut else 'damaged: '}{f.error}; read up to there")
    return html.escape(skipped) + ("complete" if f.complete else "unfinished (read up to its last complete record)")


def _diagnostics_table(data: LogData) -> str:
    link = data.link_counters()
    rows = "".join(f'<tr><td>{html.escape(k)}</td><td class="n">{v:,}</td></tr>' for k, v in link.items())
    rows += (f'<tr><td>largest processing lag</td><td class="n">{data.max_lag_s:.3f} s</td></tr>'
             f'<tr><td>largest queue depth</td><td class="n">{data.max_queue_depth:,}</td></tr>'
             f'<tr><td>queue drops</td><td class="n">{data.total_queue_drops():,}</td></tr>')
    disk = {k: data.event_counts.get(k, 0) for k in ("disk_error", "salvage")}
    files = "".join(
        f'<tr><td>{html.escape(f.path)}</td><td class="n">{f.bytes:,}</td><td class="n">{f.messages:,}</td>'
        f'<td>{_file_state(f)}</td></tr>'
        for f in data.files)
    return (f"<h2>Link and disk{_of(data)}</h2><h3>Link counters and processing</h3>"
            f'<table id="{_id(data, "link")}"><tr><th>counter</th><th>total</th></tr>{rows}</table>'
            f'<p id="{_id(data, "runs")}">Link counters summed over {data.runs()} run(s) (a daemon start, a '
            f"replay).</p><h3>Disk</h3><p>disk_error events: {disk['disk_error']}, salvaged files: "
            f"{disk['salvage']}</p>"
            f'<table id="{_id(data, "files")}"><tr><th>file</th><th>bytes</th><th>messages</th><th>state</th></tr>'
            f"{files}</table>")


def render_page(parts: list[tuple[LogData, list[tuple[str, list[Any]]]]], title: str, lead: str = "") -> str:
    """The whole page: of each recording (``parts``: its data and its (heading, figures) sections;
    ``lead``: the line on them, when there are several) its overview cards, a section of figures
    per channel, events, link and disk."""
    body = [f"<h1>{html.escape(title)}</h1>"]
    if lead:
        body.append(f'<p class="sub note" id="recordings">{html.escape(lead)}</p>')
    for data, sections in parts:
        if data.recording:
            name = "Logs of a board (no imported recording)" if data.recording == BOARD_LOGS \
                else f"Recording {data.recording}"
            body.append(f'<h2 class="recording" id="{_id(data, "recording")}">{html.escape(name)}</h2>')
        body += [f'<p class="sub">{html.escape(data.axis.caption(data.start_ns))}</p>',
                 *(f'<p class="sub note">{html.escape(note)}</p>' for note in data.notes), _cards(data)]
        for heading, figs in sections:
            body.append(f"<h2>{html.escape(heading)}</h2>")
            body.extend(_figure_html(f) for f in figs)
            if not figs:
                body.append("<p>Nothing to draw for this channel.</p>")
        body.append(_events_table(data))
        body.append(_diagnostics_table(data))
    metas = json.dumps([f.meta for _, sections in parts for _, figs in sections for f in figs]).replace("</", "<\\/")
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title><style>{_CSS}</style></head><body>\n"
            + "\n".join(body)
            + f'\n<script type="application/json" id="figures">{metas}</script>\n</body></html>\n')
