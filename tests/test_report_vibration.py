"""``cmsensord report`` of a replayed import (RAW, no dates: hours into the recording) with a
bearing, alarm rules on the velocity, acceleration RMS, envelope RMS and a bearing line, and
captures on alarms and on the failure: the captures' times in the recording, and the trends
and labels a vibration analyst reads."""

from __future__ import annotations

import json
import re
from pathlib import Path

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
def report(tmp_path_factory) -> tuple[str, dict[str, dict], Path]:
    """The run-to-failure recording imported 10 minutes a snapshot, calibrated with BASE on its
    first quarter, replayed and reported: (page, figure metadata by id, the work directory)."""
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
    return page, metas, work


def test_a_captures_title_gives_its_time_in_the_recording_as_the_events_table_does(report):
    """Each capture's title: its time in hours into the recording, where the events table has
    its trigger (not the replay's clock read as hours, 498906.610 h)."""
    page, metas, _ = report
    rows = re.findall(r'<tr class="kind-([a-z_]+)"><td class="t">(\d+\.\d+) h</td><td>[^<]*</td>'
                      r'<td>[^<]*</td><td>([^<]*)</td>', page)
    captured = [float(t) for kind, t, _ in rows if kind == "capture"]
    headings = [m["heading"] for m in metas.values() if m["kind"] == "capture"]
    assert len(headings) == len(captured) >= 2
    for heading, hours in zip(headings, captured):
        assert heading.startswith(f"bearing: capture at {hours:.3f} h — trigger "), (heading, hours)
    assert headings[0].startswith("bearing: capture at 5.000 h — trigger alarm_alert: bpfo/bearing: de.bpfo ")


def _alarm_levels(work: Path) -> dict[str, tuple[str, float | None, float | None]]:
    """Each rule's indicator and alert and danger levels as the log's /cm/alarms table last gave them."""
    from cmsensord.sinks.mcap_sink import read_messages

    out: dict[str, tuple[str, float | None, float | None]] = {}
    for topic, _, m in read_messages(next((work / "logs").glob("*.mcap"))):
        for row in m.get("alarms", []) if topic == "/cm/alarms" else ():
            old = out.get(row["rule"], (row["indicator"], None, None))
            out[row["rule"]] = (row["indicator"], row.get("alert_level", old[1]), row.get("danger_level", old[2]))
    return out


def test_raw_indicators_draw_accel_envelope_and_bearing_line_trends_with_their_rules_levels(report):
    """RAW mode: the acceleration RMS, the envelope RMS and the bearing's four defect lines each on
    axes of their own under the velocity, with the levels of the rules on them (rms_trend, env,
    bpfo) as the log's alarm table gives them (guards against velocity and shape only, those
    rules' levels nowhere though their alarms fired)."""
    _, metas, work = report
    fig = metas["bearing-indicators"]
    assert fig["panels"] == [["velocity_rms_mm_s"], ["accel_rms"], ["envelope_rms"],
                             ["de.ftf", "de.bpfo", "de.bpfi", "de.bsf"], ["kurtosis", "crest_factor"]]
    velocity, accel, env, lines, shape = fig["axes"]
    assert [ax["ylabel"] for ax in fig["axes"]] == [
        "velocity RMS [mm/s]", "acceleration RMS [m/s²]", "envelope RMS [m/s²]", "line, 0-peak [m/s²]",
        "kurtosis, crest factor"]
    assert lines["title"] == "bearing: bearing de defect lines in the envelope spectrum, 0-peak"
    levels = _alarm_levels(work)
    assert {rule: v[0] for rule, v in levels.items()} == {
        "vel_iso": "velocity_rms_mm_s", "rms_trend": "accel_rms", "env": "envelope_rms", "bpfo": "de.bpfo"}
    (_, bpfo, _), (_, rms_alert, rms_danger), (_, env_alert, env_danger) = \
        levels["bpfo"], levels["rms_trend"], levels["env"]
    assert accel["lines"] == ["accel_rms", f"rms_trend alert {rms_alert:g}", f"rms_trend danger {rms_danger:g}"]
    assert env["lines"] == ["envelope_rms", f"env alert {env_alert:g}", f"env danger {env_danger:g}"]
    assert lines["lines"] == ["de.ftf", "de.bpfo", "de.bpfi", "de.bsf", f"bpfo alert {bpfo:g} (de.bpfo)"]
    assert lines["styles"]["de.bpfo"] == ["#c62828", "-"] and lines["ylim"][1] > bpfo
    assert accel["ylim"][1] > rms_danger and env["ylim"][1] > env_danger
    drawn = {(d["rule"], d["level"]): d["value"] for d in fig["alarm_levels"]}
    assert drawn == {("vel_iso", "alert"): 2.8, ("vel_iso", "danger"): 4.5, ("rms_trend", "alert"): rms_alert,
                     ("rms_trend", "danger"): rms_danger, ("env", "alert"): env_alert,
                     ("env", "danger"): env_danger, ("bpfo", "alert"): bpfo}
    assert velocity["lines"][0] == "velocity_rms_mm_s" and shape["lines"][:2] == ["kurtosis", "crest_factor"]


def test_the_bearing_lines_drawn_are_the_logs(report):
    """The bearing-line trend holds each record's 0-peak amplitude of the line (its largest one
    within the axes), read from the indicators' bearings[].lines."""
    from cmsensord.sinks.mcap_sink import read_messages

    _, metas, work = report
    records = [m for topic, _, m in read_messages(next((work / "logs").glob("*.mcap")))
               if topic == "/cm/bearing/indicators" and m.get("bearings")]
    top = max(m["bearings"][0]["lines"][k]["amplitude"] for m in records for k in ("ftf", "bpfo", "bpfi", "bsf"))
    lines = metas["bearing-indicators"]["axes"][3]
    assert lines["ylim"][1] == pytest.approx(top * 1.5)


def test_the_velocity_figure_states_the_iso_grading_the_records_carry(report):
    """Beside the velocity: the ISO 10816-3 zone boundaries the indicator records carry, the
    machine group and foundation they belong to, and the velocity band."""
    page, metas, _ = report
    iso = "ISO 10816-3 zone boundaries A/B 1.4, B/C 2.8, C/D 4.5 mm/s: machine group 2 (medium, 15-300 kW), " \
          "rigid foundation"
    fig = metas["bearing-indicators"]
    assert fig["iso"] == iso
    assert fig["axes"][0]["title"] == f"bearing: velocity RMS over 10-1000 Hz, ISO 10816-3 zones A-D shaded\n{iso}"
    assert f"<figcaption>bearing: indicators. Velocity RMS over 10-1000 Hz; {iso}.</figcaption>" in page


@pytest.mark.parametrize(("bounds", "text"), [
    ([2.3, 4.5, 7.1], "ISO 10816-3 zone boundaries A/B 2.3, B/C 4.5, C/D 7.1 mm/s: group 1 on a rigid or group 2 "
                      "on a flexible foundation (the log does not say which)"),
    ([3.5, 7.1, 11.0], "ISO 10816-3 zone boundaries A/B 3.5, B/C 7.1, C/D 11 mm/s: machine group 1 "
                       "(large, > 300 kW), flexible foundation"),
    ([1.0, 2.0, 3.0], "ISO 10816-3 zone boundaries A/B 1, B/C 2, C/D 3 mm/s"),
])
def test_the_iso_line_names_a_group_and_foundation_only_as_far_as_the_boundaries_tell(bounds, text):
    from cmsensord.report.figures import iso_text
    from cmsensord.report.log_data import ChannelData

    assert iso_text(ChannelData("ch0", zone_boundaries=bounds)) == text


def test_capture_spectra_say_they_are_rms_per_bin(report):
    """The capture's spectrum and envelope spectrum are RMS per bin (a sine of RMS a reads a),
    the indicators' bearing lines 0-peak: each label says which, not only the unit."""
    _, metas, _ = report
    cap = metas["bearing-capture-0"]
    assert [ax["ylabel"] for ax in cap["axes"]] == [
        "waveform [m/s²]", "spectrum\nRMS per bin [m/s²]", "envelope spectrum\nRMS per bin [m/s²]",
        "envelope spectrum\nRMS per bin [m/s²]"]
