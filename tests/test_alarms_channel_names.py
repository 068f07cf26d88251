"""Alarm rules and bearings name channels as the channels are called: the configuration's list,
else an imported capture's names (`cmsensord import --names`), else the board's ch0, ch1, ...;
a name matching no channel is a one-line configuration error (exit 78) of `cmsensord replay`,
`cmsensord calibrate` and the daemon, once the channels are known."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cmsensord.config import ConfigError, config_from_dict
from cmsensord.sinks.mcap_sink import read_messages
from processes import board_on_pty, cmsensord, run_module, start_daemon, stop

ERROR = "cmsensord: configuration error: "
RULES = "alarms:\n  rules:\n    - {name: a, indicator: accel_rms, alert: 1, channels: [%s]}\n"
BEARING = "bearings:\n  - {name: de, channel: %s, elements: 8, ball_diameter: 17.462, pitch_diameter: 72.5}\n"


@pytest.fixture(scope="module")
def imported(tmp_path_factory) -> Path:
    """A one-channel recording imported as `horizontal` (`cmsensord import ... --names horizontal`)."""
    work = tmp_path_factory.mktemp("channel_names")
    rng = np.random.default_rng(3)
    np.save(work / "r.npy", rng.normal(0.0, 0.3, 25600 * 6))
    p = cmsensord("import", "r.npy", "--fs", "25600", "--unit", "g", "--names", "horizontal", "--out", "h.bin",
                  cwd=work)
    assert p.returncode == 0, p.stderr
    return work / "h.bin"


@pytest.fixture(scope="module")
def board_capture(tmp_path_factory) -> Path:
    """4 s of the healthy motor, one channel (ch0), RAW with a tacho."""
    work = tmp_path_factory.mktemp("board_names")
    p = run_module("firmware_sim", "--scenario", "healthy", "--mode", "raw", "--tacho", "--duration", "4",
                   "--out", str(work / "healthy.bin"))
    assert p.returncode == 0, p.stderr
    return work / "healthy.bin"


def run(command: str, capture: Path, tmp_path: Path, config: str):
    (tmp_path / "t.yaml").write_text("output:\n  status_line: false\n" + config)
    out = "site.yaml" if command == "calibrate" else "logs"
    return cmsensord(command, str(capture), "--config", "t.yaml", "--out", out, cwd=tmp_path)


def alarm_ids(logs: Path) -> list[str]:
    tables = [m for t, _, m in read_messages(next(logs.glob("*.mcap"))) if t == "/cm/alarms"]
    return [a["id"] for a in tables[-1]["alarms"]]


def test_a_rule_on_an_imported_channel_name_is_accepted_by_replay_and_calibrate(tmp_path, imported):
    p = run("replay", imported, tmp_path, RULES % "horizontal" + BEARING % "horizontal")
    assert p.returncode == 0, p.stderr
    assert alarm_ids(tmp_path / "logs") == ["a/horizontal"]
    p = run("calibrate", imported, tmp_path, RULES % "horizontal" + BEARING % "horizontal")
    assert p.returncode == 0, p.stderr
    assert "channels:\n  - name: horizontal\n" in (tmp_path / "site.yaml").read_text()


@pytest.mark.parametrize("command", ["replay", "calibrate"])
def test_the_board_default_name_of_an_imported_channel_is_refused(tmp_path, imported, command):
    """`channels: [ch0]` is refused, not accepted and never evaluated (the channel is horizontal)."""
    p = run(command, imported, tmp_path, RULES % "ch0")
    assert (p.returncode, p.stderr.splitlines()[-1]) == (78, ERROR + "t.yaml: alarms.rules[0].channels: rule a "
                                                         "names no channel (channels: horizontal) (got 'ch0')")
    p = run(command, imported, tmp_path, BEARING % "ch0")
    assert (p.returncode, p.stderr.splitlines()[-1]) == (78, ERROR + "t.yaml: bearings[0].channel: bearing de names no "
                                                         "channel (channels: horizontal) (got 'ch0')")


def test_with_a_channel_list_only_its_names_are_accepted(tmp_path, imported):
    listed = "channels: [{name: horizontal, index: 0}]\n"
    p = run("replay", imported, tmp_path, listed + RULES % "ch0")
    assert (p.returncode, p.stderr) == (78, ERROR + "t.yaml: alarms.rules[0].channels: rule a names no channel "
                                        "(channels: horizontal) (got 'ch0')\n")
    assert not (tmp_path / "logs").exists()                 # refused on loading: nothing read
    with pytest.raises(ConfigError) as err:
        config_from_dict({"channels": [{"name": "horizontal"}], "bearings": [
            {"name": "de", "channel": "ch0", "elements": 8, "ball_diameter": 17.462, "pitch_diameter": 72.5}]},
            source="f.yaml")
    assert str(err.value) == ("f.yaml: bearings[0].channel: bearing de names no channel (channels: horizontal) "
                              "(got 'ch0')")


def test_the_daemon_with_a_channel_list_refuses_a_rule_on_no_channel_at_start(tmp_path):
    """`cmsensord --config` with a channel list: the rule naming no channel of it is refused before
    the port is opened, in one line naming the rule and the channels there are (exit 78)."""
    d = start_daemon(tmp_path, tmp_path / "no-board", config=(
        "channels: [{name: horizontal, index: 0}, {name: vertical, index: 1}]\n"
        "alarms:\n  rules:\n    - {name: bearing_hot, indicator: accel_rms, alert: 1, channels: [ch0]}\n"))
    err = d.communicate(timeout=30)[1]
    assert (d.returncode, err) == (78, ERROR + f"{tmp_path / 'cmsensord.yaml'}: alarms.rules[0].channels: rule "
                                   "bearing_hot names no channel (channels: horizontal, vertical) (got 'ch0')\n")
    assert not (tmp_path / "logs").exists()


def test_a_board_channel_that_is_not_there_is_refused_by_replay(tmp_path, board_capture):
    """Without a list, `channel: ch5` was accepted on a one-channel board."""
    p = run("replay", board_capture, tmp_path, BEARING % "ch5")
    assert (p.returncode, p.stderr.splitlines()[-1]) == (78, ERROR + "t.yaml: bearings[0].channel: bearing de names no "
                                                         "channel (channels: ch0) (got 'ch5')")
    events = [m for t, _, m in read_messages(next((tmp_path / "logs").glob("*.mcap"))) if t == "/cm/events"]
    assert ("config", "configuration error: bearings[0].channel: bearing de names no channel (channels: ch0) "
            "(got 'ch5')") in [(m["kind"], m["message"]) for m in events]            # the short log says why it ends
    p = run("replay", board_capture, tmp_path, RULES % "ch0" + BEARING % "ch0")
    assert p.returncode == 0, p.stderr


def test_the_daemon_refuses_a_rule_on_no_channel_of_the_board(tmp_path):
    """The daemon knows the board's channels from its first data: a one-line error, exit 78
    (systemd does not restart it), the MCAP log closed with the reason in a config event."""
    with board_on_pty("--scenario", "healthy", "--mode", "raw", "--duration", "30", "--speed", "4") as port:
        d = start_daemon(tmp_path, port, config=RULES % "ch3")
        try:
            d.wait(timeout=60)
        finally:
            err = stop(d) if d.poll() is None else d.communicate()[1]
    assert d.returncode == 78, err
    assert err.splitlines()[-1] == (ERROR + f"{tmp_path / 'cmsensord.yaml'}: alarms.rules[0].channels: rule a names no "
                                    "channel (channels: ch0) (got 'ch3')")
    events = [m for t, _, m in read_messages(next((tmp_path / "logs").glob("*.mcap"))) if t == "/cm/events"]
    assert events[-1]["kind"] == "stop"
    assert ("config", "configuration error: alarms.rules[0].channels: rule a names no channel (channels: ch0) "
            "(got 'ch3')") in [(m["kind"], m["message"]) for m in events]


def test_a_vote_of_more_channels_than_the_board_has_is_refused_by_replay(tmp_path, board_capture):
    """`vote: 3` on a one-channel board: the voting alarm could never rise."""
    vote = "alarms:\n  rules:\n    - {name: v, indicator: velocity_rms_mm_s, alert: 2.8, vote: 3}\n"
    p = run("replay", board_capture, tmp_path, vote)
    assert (p.returncode, p.stderr.splitlines()[-1]) == (78, ERROR + "t.yaml: alarms.rules[0].vote: must be at most "
                                                         "the 1 channel(s) the rule watches (ch0): that many never "
                                                         "exceed the level together (got 3)")
    with pytest.raises(ConfigError) as err:                 # with a channel list: on loading
        config_from_dict({"channels": [{"name": "a"}, {"name": "b"}], "alarms": {"rules": [
            {"name": "v", "indicator": "accel_rms", "alert": 1, "vote": 3}]}}, source="f.yaml")
    assert str(err.value) == ("f.yaml: alarms.rules[0].vote: must be at most the 2 channel(s) the rule watches "
                              "(a, b): that many never exceed the level together (got 3)")
