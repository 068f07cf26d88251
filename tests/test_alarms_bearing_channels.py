"""A rule on a bearing's line (`<bearing>.<line>`) watches the channel the bearing is configured
on, through the commands a user types: without `channels:` its alarms, its baselines and its
`alarm_no_baseline` warnings are of that channel alone (`cmsensord replay`, and a replay of the
site file `cmsensord calibrate` writes); a rule whose `channels:` names another channel is a
one-line configuration error (exit 78)."""

from __future__ import annotations

from pathlib import Path

import pytest

from cmsensord.sinks.mcap_sink import read_messages
from processes import cmsensord, run_module

ERROR = "cmsensord: configuration error: "
BEARING = ("bearings:\n  - {name: tb, channel: ch0, elements: 8, ball_diameter: 17.462, pitch_diameter: 72.5}\n"
           "indicators: {rpm: 1800}\n")
RULE = "alarms:\n  rules:\n    - {name: outer, indicator: tb.bpfo, alert_x_baseline: 4, on_delay_s: 3%s}\n"


@pytest.fixture(scope="module")
def capture(tmp_path_factory) -> Path:
    """12 s of the healthy motor on two channels (ch0, ch1), RAW with a tacho."""
    work = tmp_path_factory.mktemp("bearing_channels")
    p = run_module("firmware_sim", "--scenario", "healthy", "--mode", "raw", "--tacho", "--channels", "2",
                   "--duration", "12", "--out", str(work / "two.bin"))
    assert p.returncode == 0, p.stderr
    return work / "two.bin"


def replay(tmp_path: Path, capture: Path, config_file: str):
    return cmsensord("replay", str(capture), "--config", config_file, "--out", "logs", cwd=tmp_path)


def alarm_rows(logs: Path) -> list[tuple[str, list[str]]]:
    """(id, channels) of each row of the last /cm/alarms table."""
    tables = [m for t, _, m in read_messages(next(logs.glob("*.mcap"))) if t == "/cm/alarms"]
    return [(a["id"], a["channels"]) for a in tables[-1]["alarms"]]


def test_a_bearing_line_rule_watches_the_bearing_channel_only(tmp_path, capture):
    """Guards against the rule applied to ch1 too, where tb.bpfo never comes: a warning there to run
    calibrate, which can never learn that baseline, and an alarm row that never fires."""
    (tmp_path / "b.yaml").write_text("output: {status_line: false}\n" + BEARING + RULE % ""
                                     + "  baselines: [{channel: ch0, indicator: tb.bpfo, value: 0.5}]\n")
    p = replay(tmp_path, capture, "b.yaml")
    assert p.returncode == 0, p.stderr
    assert "alarm_no_baseline" not in p.stderr, p.stderr
    assert alarm_rows(tmp_path / "logs") == [("outer/ch0", ["ch0"])]


def test_the_site_file_calibrate_writes_arms_the_rule_on_the_bearing_channel(tmp_path, capture):
    """calibrate learns tb.bpfo's baseline on ch0 alone; a replay with its site file then warns of no
    baseline missing (the rule is not on ch1), and the rule's one alarm is of ch0."""
    (tmp_path / "base.yaml").write_text("output: {status_line: false}\n" + BEARING + RULE % "")
    p = cmsensord("calibrate", str(capture), "--config", "base.yaml", "--out", "site.yaml", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    site = (tmp_path / "site.yaml").read_text()
    assert "{channel: ch0, indicator: tb.bpfo," in site and "{channel: ch1, indicator: tb.bpfo," not in site
    p = replay(tmp_path, capture, "site.yaml")
    assert p.returncode == 0, p.stderr
    assert "alarm_no_baseline" not in p.stderr, p.stderr
    assert [row for row in alarm_rows(tmp_path / "logs") if row[0].startswith("outer")] == [("outer/ch0", ["ch0"])]


@pytest.mark.parametrize("command", ["replay", "calibrate"])
def test_a_bearing_line_rule_on_another_channel_is_refused(tmp_path, capture, command):
    (tmp_path / "b.yaml").write_text("output: {status_line: false}\n" + BEARING + RULE % ", channels: [ch0, ch1]")
    out = "site.yaml" if command == "calibrate" else "logs"
    p = cmsensord(command, str(capture), "--config", "b.yaml", "--out", out, cwd=tmp_path)
    assert (p.returncode, p.stderr) == (78, ERROR + "b.yaml: alarms.rules[0].channels: rule outer watches tb.bpfo, "
                                        "and bearing tb is on ch0 only: give channels: [ch0] (or none), or add a "
                                        "bearing on ch1 and a rule on its line (got 'ch1')\n")
    assert not (tmp_path / out).exists()
