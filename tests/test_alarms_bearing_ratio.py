"""Alarm rules on a bearing line's ratio (how far it stands out of the envelope spectrum around
it) through the commands a user types: the simulated motor's outer-race defect raises the whole
envelope floor, so every line's amplitude passes k x its healthy baseline and an amplitude rule
on BPFI fires on it too; the ratio rules raise the outer race alone.  The 6206's 2 x BPFI window
holds 3 x BPFO, said once at the start."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from processes import run_module

#: the README's worked example on the simulated board (its 6206), delays short for a 12-s capture
BASE = """\
output:
  status_line: false
bearings:
  - {name: de, channel: ch0, elements: 9, ball_diameter: 9.525, pitch_diameter: 46}
alarms:
  rules:
    - {name: de_outer_race, indicator: de.bpfo_ratio, alert_x_baseline: 2.0, on_delay_s: 5, latch: true}
    - {name: de_inner_race, indicator: de.bpfi_ratio, alert_x_baseline: 2.0, on_delay_s: 5, latch: true}
    - {name: de_inner_amplitude, indicator: de.bpfi, alert_x_baseline: 4.0, on_delay_s: 5}
"""


def ok(module: str, *args: str):
    p = run_module(module, *args)
    assert p.returncode == 0, p.stderr
    return p


@pytest.fixture(scope="module")
def replayed(tmp_path_factory) -> tuple[dict, str]:
    """calibrate on 12 s of the healthy motor, then the faulty one replayed with the site file:
    (the learned baselines, the replay's stderr)."""
    work: Path = tmp_path_factory.mktemp("bearing_ratio")
    (work / "base.yaml").write_text(BASE)
    for sc in ("healthy", "faulty"):
        ok("firmware_sim", "--scenario", sc, "--mode", "raw", "--tacho", "--duration", "12",
           "--out", str(work / f"{sc}.bin"))
    ok("cmsensord", "calibrate", str(work / "healthy.bin"), "--config", str(work / "base.yaml"),
       "--out", str(work / "site.yaml"))
    site = yaml.safe_load((work / "site.yaml").read_text())
    learned = {b["indicator"]: b["value"] for b in site["alarms"]["baselines"]}
    p = ok("cmsensord", "replay", str(work / "faulty.bin"), "--config", str(work / "site.yaml"),
           "--out", str(work / "out"))
    return learned, p.stderr


def test_calibrate_learns_each_line_ratio(replayed):
    learned, _ = replayed
    assert {f"de.{k}_ratio" for k in ("bpfo", "bpfi", "bpfo_2x", "ftf")} <= set(learned)
    assert 1 < learned["de.bpfo_ratio"] < 3 and 1 < learned["de.bpfi_ratio"] < 3


def test_an_outer_race_fault_raises_the_outer_race_ratio_alarm_only(replayed):
    _, stderr = replayed
    alarms = [ln for ln in stderr.splitlines() if "alarm_" in ln and ln.startswith(("WARNING", "ERROR"))]
    assert alarms == [
        "WARNING alarm_alert: de_inner_amplitude/ch0: de.bpfi 0.2739 m/s² (BPFI of bearing de, envelope 0-pk) "
        "reached the alert level 0.04832 m/s²",
        "WARNING alarm_alert: de_outer_race/ch0: de.bpfo_ratio 5.793 (BPFO of bearing de over the envelope "
        "spectrum around it) reached the alert level 4.064",
    ]


def test_a_line_window_holding_another_line_harmonic_is_said_once(replayed):
    _, stderr = replayed
    said = [ln for ln in stderr.splitlines() if "line_harmonics:" in ln]
    assert said == ["WARNING line_harmonics: bearing de on ch0: bpfi_2x's window (311.4 Hz ±2 %) holds 3 x bpfo "
                    "(306.8 Hz): a defect at bpfo raises de.bpfi_2x too (judge bpfi by de.bpfi_ratio)"]


def test_the_units_the_alarm_lines_give_are_those_of_the_indicator_records():
    """One table of units (config.alarm_indicators.QUANTITIES): each record value's unit is the one
    its field's description in the /cm/<ch>/indicators schema gives, and a bearing line's too."""
    from cmsensord.config.alarm_indicators import RECORD_VALUES, unit_of
    from cmsensord.sinks.schemas import SCHEMAS

    props = SCHEMAS["indicators"]["properties"]
    line = props["bearings"]["items"]["properties"]["lines"]["properties"]["bpfo"]["properties"]

    def bracket(description: str) -> str:
        found = re.search(r"\[([^\]]+)\]", description)
        return found.group(1).replace("^2", "²") if found else ""

    for name in RECORD_VALUES:
        if name != "zone":
            assert unit_of(name) == bracket(props[name]["description"]), name
    assert unit_of("de.bpfo") == bracket(line["amplitude"]["description"]) == "m/s²"
    assert unit_of("de.bpfo_ratio") == ""
