"""``cmsensord summary`` and ``cmsensord report`` show a message at its own stamp (its publish
time), also one the sink wrote with a clamped log time (:mod:`cmsensord.sinks.reorder`)."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import pytest
from mcap.reader import make_reader

from cmsensord.monitor import messages
from cmsensord.sinks.mcap_file import McapSink
from processes import cmsensord

S = 1_000_000_000


def _iso(ns: int) -> str:
    return datetime.fromtimestamp(ns / S).astimezone().isoformat(timespec="milliseconds")


def _late_event_log(tmp_path: Path) -> tuple[Path, int]:
    """A log whose sink got an event 18 s after a later message (an event held back longer than
    the reorder window): it is written with a clamped log time.  (The log, its first stamp.)"""
    t0 = 1_790_000_000 * S
    sink = McapSink(tmp_path / "late")
    for stamp, kind, msg in ((10, "config", "first"), (30, None, None), (12, "frames_lost", "late"),
                             (31, "link_lost", "last")):
        if kind is None:
            sink.write("/cm/ch0/severity", "severity", t0 + stamp * S,
                       {"channel": "ch0", "severity_index": 0.1, "level": 1, "anomaly": [0], "outliers": [0],
                        "f_r": 0.1, "r": [0.01], "failure": False, "missing": 0, "transient": False})
        else:
            sink.write(*messages.event(t0 + stamp * S, kind, None, msg, {}))
    assert sink.reorder.clamped == 1
    return sink.close(), t0


def test_summary_and_report_show_a_clamped_message_at_its_own_time(tmp_path):
    log, t0 = _late_event_log(tmp_path)
    with open(log, "rb") as f:
        late = [m for _, c, m in make_reader(f).iter_messages(log_time_order=False) if b'"late"' in m.data]
    assert [(m.publish_time - t0, m.log_time - t0) for m in late] == [(12 * S, 30 * S)]
    text = cmsensord("summary", str(log)).stdout
    assert f"\nstart: {_iso(t0 + 10 * S)}\n" in text and f"\nend: {_iso(t0 + 31 * S)}\n" in text
    assert (f"\nevents: 3 shown\n  {_iso(t0 + 10 * S)} config: first\n  {_iso(t0 + 12 * S)} frames_lost: late\n"
            f"  {_iso(t0 + 31 * S)} link_lost: last\n") in text
    pytest.importorskip("matplotlib", reason="the report extra")
    p = cmsensord("report", str(log), "--out", str(tmp_path / "r.html"))
    assert p.returncode == 0, p.stderr
    page = (tmp_path / "r.html").read_text(encoding="utf-8")
    rows = [datetime.fromtimestamp((t0 + k * S) / S).isoformat(sep=" ", timespec="milliseconds")
            for k in (10, 12, 31)]
    at = [page.index(f'<td class="t">{when}</td><td>{kind}</td>')
          for when, kind in zip(rows, ("config", "frames_lost", "link_lost"))]
    assert at == sorted(at)
