"""``cmsensord report``'s figures of a degrading motor (RAW, tacho) replayed with two alarm rules
and a capture on alarm_danger: legends clear of the data, failure and alarm_danger lines told
apart, one spelling of m/s², the rules' alarm levels on the trends they watch."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from processes import cmsensord, run_module

pytest.importorskip("matplotlib", reason="the report extra")

SITE = """\
output:
  status_line: false
capture:
  triggers: [alarm_danger]
alarms:
  operating: {source: speed, running_above: 600, startup_suppress_s: 2}
  rules:
    - {name: de_velocity, indicator: velocity_rms_mm_s, alert_zone: C, danger: 9.5,
       on_delay_s: 2, off_delay_s: 2}
    - {name: de_kurtosis, indicator: kurtosis, alert: 6, danger: 12, latch: true}
"""


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> tuple[str, dict[str, dict], Path]:
    """24 s of the degrading motor replayed with SITE, and its report: (page, figure metadata by
    id, the PNG directory). The log holds alarm_alert, alarm_danger, failure and a capture."""
    work = tmp_path_factory.mktemp("report_figures")
    (work / "site.yaml").write_text(SITE)
    p = run_module("firmware_sim", "--scenario", "degrading", "--mode", "raw", "--tacho", "--duration", "24",
                   "--out", str(work / "deg.bin"))
    assert p.returncode == 0, p.stderr
    p = cmsensord("replay", "deg.bin", "--config", "site.yaml", "--out", "out", cwd=work)
    assert p.returncode == 0, p.stderr
    p = cmsensord("report", "out", "--out", "r.html", "--png", "png", cwd=work)
    assert p.returncode == 0, p.stderr
    page = (work / "r.html").read_text(encoding="utf-8")
    metas = {m["id"]: m for m in json.loads(re.search(
        r'<script type="application/json" id="figures">(.*?)</script>', page, re.S).group(1))}
    return page, metas, work / "png"


def test_the_legends_of_the_trends_are_beside_their_axes_not_over_the_data(report):
    """Each legend of the severity and indicator figures lies right of its axes (not at the
    top left inside, over the severity's step to 1.0 and the level's start)."""
    _, metas, _ = report
    for fid in ("ch0-severity", "ch0-indicators"):
        for ax in metas[fid]["axes"]:
            x0, y0, x1, y1 = ax["legend_box"]
            assert x0 > 1.0 and y1 <= 1.001, (fid, ax["title"], ax["legend_box"])


def test_failure_and_alarm_danger_lines_are_told_apart_and_named(report):
    """The severity figure marks the failure (solid) and the alarm_danger (dash-dot) events in
    colours of their own, each named in the legend (not the same crimson dashes)."""
    _, metas, _ = report
    styles = metas["ch0-severity"]["axes"][0]["styles"]
    failure = styles["failure (the severity model: its last AKF flags)"]
    danger = styles["alarm_danger (a rule's danger level reached)"]
    alert = styles["alarm_alert (a rule's alert level reached)"]
    assert failure == ["#b00020", "-"] and danger == ["#d81b60", "-."] and alert[1] == "--"
    assert len({tuple(s) for s in styles.values()}) == len(styles)       # every line its own look


def test_capture_figures_write_m_s2_as_the_trends_do(report):
    """The capture's messages carry m/s^2; every figure writes m/s² (guards against m/s^2 on the
    capture beside m/s² on the trends)."""
    _, metas, _ = report
    cap = metas["ch0-capture-0"]
    assert [ax["ylabel"] for ax in cap["axes"]] == ["waveform [m/s²]", "spectrum\nRMS per bin [m/s²]",
                                                    "envelope spectrum\nRMS per bin [m/s²]"]
    labels = [ax["ylabel"] for m in metas.values() for ax in m["axes"]]
    assert not [t for t in labels if "^" in t] and "order RMS [m/s²]" in labels


def test_each_rules_alert_and_danger_levels_are_drawn_on_its_indicators_trend(report):
    """The alert and danger levels of de_velocity (alert_zone C: 2.8, danger 9.5) on the velocity
    trend, of de_kurtosis (6, 12) on the kurtosis one, as the log's /cm/alarms table gives them,
    dashed and labelled with the rule's name."""
    from cmsensord.sinks.mcap_sink import read_messages

    _, metas, png = report
    rows = [row for topic, _, m in read_messages(next((png.parent / "out").glob("*.mcap")))
            if topic == "/cm/alarms" for row in m["alarms"] if "danger_level" in row]
    levels = {row["rule"]: (row["alert_level"], row["danger_level"]) for row in rows}
    assert levels == {"de_velocity": (2.8, 9.5), "de_kurtosis": (6.0, 12.0)}
    velocity, *_, shape = metas["ch0-indicators"]["axes"]
    assert velocity["lines"][1:] == ["de_velocity alert 2.8", "de_velocity danger 9.5"]
    assert shape["lines"][2:] == ["de_kurtosis alert 6", "de_kurtosis danger 12"]
    assert velocity["styles"]["de_velocity danger 9.5"] == ["#b00020", "--"] and velocity["ylim"][1] > 9.5
    assert metas["ch0-indicators"]["alarm_levels"] == [
        {"rule": "de_velocity", "indicator": "velocity_rms_mm_s", "level": "alert", "value": 2.8},
        {"rule": "de_velocity", "indicator": "velocity_rms_mm_s", "level": "danger", "value": 9.5},
        {"rule": "de_kurtosis", "indicator": "kurtosis", "level": "alert", "value": 6.0},
        {"rule": "de_kurtosis", "indicator": "kurtosis", "level": "danger", "value": 12.0}]
    assert metas["ch0-severity"]["alarm_levels"] == []          # no rule on severity_index
