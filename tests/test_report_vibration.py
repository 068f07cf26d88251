"""``cmsensord report`` of a replayed import (RAW, no dates: hours into the recording) with a
bearing, alarm rules on the velocity, acceleration RMS, envelope RMS and a bearing line, and
captures on alarms and on the failure: the captures' times in the recording, and the trends
and labels a vibration analyst reads."""

from __future__ import annotations

import json
import re

import pytest

from processes import cmsensord
from tests.test_import_names import R2F, run_to_failure

pytest.importorskip("matplotlib", reason="the report extra")

#: BPFO of this bearing at 1800 rpm: 4 x 30 Hz x (1 - 7.5 / 39.13) = 97.0 Hz, where the
#: run-to-failure recording's impacts come
BASE = """\
indicators:
  machine_group: 2
  foundation: rigid
bearings:
  - {name: de, channel: bearing, elements: 8, ball_diameter: 7.5, pitch_diameter: 39.13, contact_angle_deg: 0}
alarms:
  rules:
    - {name: vel_iso, indicator: velocity_rms_mm_s, alert_zone: C, danger_zone: D}
    - {name: rms_trend, indicator: accel_rms, alert_x_baseline: 2.0, danger_x_baseline: 4.0}
    - {name: env, indicator: envelope_rms, alert_x_baseline: 3.0, danger_x_baseline: 6.0}
    - {name: bpfo, indicator: de.bpfo, alert_x_baseline: 4.0}
capture:
  triggers: [alarm_alert, failure]
  pre_s: 0.5
  post_s: 0.5
  min_interval_s: 0
"""


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> tuple[str, dict[str, dict]]:
    """The run-to-failure recording imported 10 minutes a snapshot, calibrated with BASE on its
    first quarter, replayed and reported: (page, figure metadata by id)."""
    work = tmp_path_factory.mktemp("report_vibration")
    (work / "base.yaml").write_text(BASE)
    d = run_to_failure(work)
    for args in (("import", str(d), *R2F, "--snapshot-interval", "600", "--out", "r.bin"),
                 ("calibrate", "r.bin", "--to", "25%", "--config", "base.yaml", "--out", "site.yaml"),
                 ("replay", "r.bin", "--config", "site.yaml", "--out", "logs"),
                 ("report", "logs", "--out", "r.html", "--png", "png")):
        p = cmsensord(*args, cwd=work)
        assert p.returncode == 0, p.stderr
    page = (work / "r.html").read_text(encoding="utf-8")
    metas = {m["id"]: m for m in json.loads(re.search(
        r'<script type="application/json" id="figures">(.*?)</script>', page, re.S).group(1))}
    return page, metas


def test_a_captures_title_gives_its_time_in_the_recording_as_the_events_table_does(report):
    """Each capture's title: its time in hours into the recording, where the events table has
    its trigger (before: the replay's clock read as hours, 498906.610 h)."""
    page, metas = report
    rows = re.findall(r'<tr class="kind-([a-z_]+)"><td class="t">(\d+\.\d+) h</td><td>[^<]*</td>'
                      r'<td>[^<]*</td><td>([^<]*)</td>', page)
    captured = [float(t) for kind, t, _ in rows if kind == "capture"]
    headings = [m["heading"] for m in metas.values() if m["kind"] == "capture"]
    assert len(headings) == len(captured) >= 2
    for heading, hours in zip(headings, captured):
        assert heading.startswith(f"bearing: capture at {hours:.3f} h — trigger "), (heading, hours)
    assert headings[0].startswith("bearing: capture at 5.000 h — trigger alarm_alert: bpfo/bearing: de.bpfo ")
