"""``cmsensord report LOG_OR_DIR... --out report.html [--png DIR]``: MCAP logs -> an HTML report.

Reads the logs (:mod:`.reading`), draws the figures (:mod:`.figures`, which
needs matplotlib: ``pip install 'cmsensord[report]'``) and writes one
self-contained page (:mod:`.html_page`). Without matplotlib the command says
so in one line and exits with status 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from cmsensord.errors import EXIT_USAGE, CmsensordError
from cmsensord.out_paths import out_file_refused, overwritten_input
from cmsensord.sinks.log_names import empty_files
from cmsensord.sinks.mcap_cut import EMPTY
from cmsensord.sinks.mcap_records import NOT_MCAP, not_mcap_text

__all__ = ["add_report_parser", "run_report", "MISSING_MATPLOTLIB"]

MISSING_MATPLOTLIB = ("cmsensord: report needs matplotlib: install it with "
                      "pip install 'cmsensord[report]' (or pip install matplotlib)")


def add_report_parser(sub: Any) -> None:
    r = sub.add_parser("report", help="turn MCAP logs into a self-contained HTML report with plots")
    r.add_argument("logs", nargs="+", metavar="LOG_OR_DIR", help="MCAP files (.mcap, .mcap.part) or directories")
    r.add_argument("--out", dest="sub_out", required=True, metavar="FILE", help="HTML file to write")
    r.add_argument("--png", metavar="DIR", help="also write each figure as a PNG into DIR")
    r.add_argument("--title", help="page title (default: cmsensord report and the time span)")


def run_report(args: argparse.Namespace) -> int:
    """Write the report; one line on stderr and status 2 on a user error."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        print(MISSING_MATPLOTLIB, file=sys.stderr)
        return EXIT_USAGE
    from cmsensord.report.reading import log_paths, read_logs
    paths = log_paths(args.logs)
    refused = overwritten_input(args.sub_out, paths) or out_file_refused(args.sub_out, "report.html")
    if refused:
        raise CmsensordError(refused)
    parts = read_logs(paths, sys.stderr)
    _tell_unreadable([f for data in parts for f in data.files], sum(data.messages for data in parts))
    lead = recordings_line(parts)
    for note in [lead] * bool(lead) + [note for data in parts for note in data.notes]:
        print(f"cmsensord: report: {note}", file=sys.stderr)
    drawn = [(data, _draw(data)) for data in parts]
    from cmsensord.report.html_page import render_page
    out = Path(args.sub_out)
    writing = out                           # the file a write error is of (a full disk's names none)
    try:
        out.write_text(render_page(drawn, args.title or _title(parts), lead), encoding="utf-8")
        if args.png:
            png_dir = Path(args.png)
            png_dir.mkdir(parents=True, exist_ok=True)
            for fig in (fig for _, sections in drawn for _, figs in sections for fig in figs):
                writing = png_dir / f"{fig.meta['id']}.png"
                writing.write_bytes(fig.png)
    except OSError as err:
        raise CmsensordError(f"{err.filename or writing}: cannot write: {err.strerror or err}") from None
    n = sum(len(figs) for _, sections in drawn for _, figs in sections)
    read = sum(f.left_out is None and f.error != EMPTY for data in parts for f in data.files)
    messages = sum(data.messages for data in parts)
    print(f"report: {out} ({n} figures, {messages:,} messages from {read} file(s))", file=sys.stderr)
    return 0


def recordings_line(parts: list[Any]) -> str:
    """The line on logs of several recordings (:mod:`.runs`), each drawn on its own; "" for one."""
    if len(parts) < 2:
        return ""
    names = ", ".join(f"{data.recording} ({sum(f.left_out is None for f in data.files)} file(s))" for data in parts)
    return f"these logs hold {len(parts)} different recordings, drawn apart, each over its own time: {names}."


def _title(parts: list[Any]) -> str:
    """The page's title: the time span of one recording, the names of several."""
    if len(parts) > 1:
        return "cmsensord report: " + ", ".join(data.recording for data in parts)
    data = parts[0]
    return f"cmsensord report {data.axis.text(data.start_ns)[:16]} – {data.axis.text(data.end_ns)[:16]}"


def _tell_unreadable(files: list[Any], messages: int) -> None:
    """One line on stderr for each file with damage read past (a bad chunk, intact ones after
    it), each whose read ended at damage (not MCAP, no intact chunk after it, cut short:
    what that lost) and each with messages left out (on topics not cmsensord's, or not its
    JSON: :meth:`FileInfo.not_read`). When no message could be read at all (``messages``), a user
    error (no report): the first file's damage, or that it holds no message, or none of cmsensord's."""
    read = [f for f in files if f.left_out is None]
    bad = [f for f in read if f.error]
    if not messages:
        if not bad:
            raise CmsensordError(f"{read[0].path}: no complete message in it to report"
                                 + (f" ({read[0].cut})" if read[0].cut else ""))
        if len(bad) > 1 and all(f.error == EMPTY for f in bad):
            raise CmsensordError(f"{empty_files([f.path for f in bad])}: no MCAP data in them")
        more = f" (and {len(bad) - 1} more file(s) like it)" if len(bad) > 1 else ""
        error = not_mcap_text(bad[0].path) if bad[0].error == NOT_MCAP else bad[0].error
        raise CmsensordError(f"{bad[0].path}: {error}{more}")
    if all(f.messages == f.foreign + f.unreadable for f in read):
        alien = [f for f in read if f.messages]
        more = f" (and {len(alien) - 1} more file(s) like it)" if len(alien) > 1 else ""
        raise CmsensordError(f"{alien[0].path}: no cmsensord message in it to report: of its {alien[0].messages:,} "
                             f"message(s), {alien[0].not_read()}{more}")
    empty = [f.path for f in read if f.error == EMPTY]
    if empty:
        print(f"cmsensord: report: {empty_files(empty)}: left out", file=sys.stderr)
    for f in read:
        if f.error == EMPTY:
            continue
        if f.skipped:
            print(f"cmsensord: report: {f.path}: {len(f.skipped)} damaged stretch(es) skipped (the first: "
                  f"{f.skipped[0]}); the report holds the {f.messages:,} message(s) of its intact chunks",
                  file=sys.stderr)
        if f.error:
            print(f"cmsensord: report: {f.path}: {f.error}; the report holds its {f.messages:,} message(s) "
                  "before that", file=sys.stderr)
        if f.not_read():
            print(f"cmsensord: report: {f.path}: of its {f.messages:,} message(s), {f.not_read()}: left out",
                  file=sys.stderr)


def _draw(data: Any) -> list[tuple[str, list[Any]]]:
    """(heading, figures) per channel, in channel-name order (the heading names the recording
    among several)."""
    from cmsensord.report import figures
    sections = []
    for name in sorted(data.channels):
        ch = data.channels[name]
        figs = []
        if ch.severity:
            figs.append(figures.severity_figure(data, ch))
        for fig in (figures.indicators_figure(ch, data.axis, data.healthy), figures.orders_figure(ch),
                    figures.campbell_figure(ch)):
            if fig is not None:
                figs.append(fig)
        figs.extend(figures.capture_figure(cap, i, data.axis) for i, cap in enumerate(ch.captures))
        sections.append((f"Channel {name}" + (f" of {data.recording}" if data.recording else ""), figs))
    return sections
