"""The alarm manager through the commands a user types: a degrading motor's RAW capture
replayed with an alarms config (events, /cm/alarms, journal lines); a running daemon
acknowledged over its control socket (`cmsensord ack`, `cmsensord status`)."""

from __future__ import annotations

import json
import os
import pwd
import time
from pathlib import Path

import pytest

from cmsensord.service.control import SOCKET_NAME
from cmsensord.sinks.mcap_sink import read_messages
from cmsensord.sinks.schemas import SCHEMAS
from processes import board_on_pty, run_module, start_daemon, stop

S = 1_000_000_000
ALARMS = """\
alarms:
  operating: {source: speed, running_above: 600, startup_suppress_s: 2}
  rules:
    - {name: de_velocity, indicator: velocity_rms_mm_s, alert_zone: C, danger: 9.5,
       on_delay_s: 2, off_delay_s: 2}
    - {name: de_kurtosis, indicator: kurtosis, alert: 6, latch: true}
"""


def ok(module: str, *args: str):
    p = run_module(module, *args)
    assert p.returncode == 0, p.stderr
    return p


def stamp(m: dict) -> int:
    return m["timestamp"]["sec"] * S + m["timestamp"]["nsec"]


@pytest.fixture(scope="module")
def degrading(tmp_path_factory):
    """24 s of the degrading motor (RAW, tacho) replayed with two alarm rules."""
    work = tmp_path_factory.mktemp("alarm_replay")
    (work / "site.yaml").write_text("output:\n  status_line: false\n" + ALARMS)
    ok("firmware_sim", "--scenario", "degrading", "--mode", "raw", "--tacho", "--duration", "24",
       "--out", str(work / "deg.bin"))
    p = ok("cmsensord", "replay", str(work / "deg.bin"), "--config", str(work / "site.yaml"),
           "--out", str(work / "out"))
    msgs = list(read_messages(next((work / "out").glob("*.mcap"))))
    return msgs, p.stderr


def test_replay_raises_the_alarms_of_the_degrading_motor(degrading):
    msgs, stderr = degrading
    recs = [m for t, _, m in msgs if t == "/cm/ch0/indicators"]
    events = [m for t, _, m in msgs if t == "/cm/events" and m["kind"].startswith("alarm_")]
    got = [(m["kind"], m["alarm"], m["previous_level"], m["alarm_level"]) for m in events]
    assert got == [("alarm_alert", "de_velocity/ch0", "normal", "alert"),
                   ("alarm_alert", "de_kurtosis/ch0", "normal", "alert"),
                   ("alarm_danger", "de_velocity/ch0", "alert", "danger"),
                   ("alarm_alert", "de_velocity/ch0", "danger", "alert")]
    v = [(stamp(r), r["velocity_rms_mm_s"]) for r in recs]
    # on-delay 2 s: the alert comes with the record 2 s after the first one over the B/C boundary
    first_over = next(t for t, x in v if x >= 2.8)
    assert stamp(events[0]) == first_over + 2 * S
    # the danger with the first record over 9.5 held for 2 s; the ease 2 s after the first below 9.5 x 0.95
    over = next(t for t, x in v if x >= 9.5)
    assert all(x >= 9.5 * 0.95 for t, x in v if over <= t <= over + 2 * S)
    assert stamp(events[2]) == over + 2 * S
    below = next(t for t, x in v if t > stamp(events[2]) and x < 9.5 * 0.95)
    assert stamp(events[3]) == below + 2 * S
    # the kurtosis alert at once, with the first record over 6
    assert stamp(events[1]) == next(stamp(r) for r in recs if r["kurtosis"] >= 6)
    # each line names the quantity, its value with the unit and what it is (the velocity RMS: over which
    # band), the level with the unit
    assert [ln for ln in stderr.splitlines() if ln.startswith(("WARNING alarm_", "ERROR alarm_"))] == [
        "WARNING alarm_alert: de_velocity/ch0: velocity_rms_mm_s 5.122 mm/s (velocity RMS, 10-1000 Hz) reached the "
        "alert level 2.8 mm/s",
        "WARNING alarm_alert: de_kurtosis/ch0: kurtosis 16.81 reached the alert level 6",
        "ERROR alarm_danger: de_velocity/ch0: velocity_rms_mm_s 10.68 mm/s (velocity RMS, 10-1000 Hz) reached the "
        "danger level 9.5 mm/s",
        "WARNING alarm_alert: de_velocity/ch0: eased from danger to alert (velocity_rms_mm_s 6.338 mm/s)"]


def test_alarm_table_follows_the_operating_state_and_holds_the_latch(degrading):
    msgs, _ = degrading
    tables = [m for t, _, m in msgs if t == "/cm/alarms"]
    states = [m["operating_state"] for m in tables]
    assert states[:3] == ["stopped", "starting", "running"]
    start = next(stamp(m) for m in tables if m["operating_state"] == "starting")
    run = next(stamp(m) for m in tables if m["operating_state"] == "running")
    assert run - start == 2 * S                         # startup_suppress_s
    last = {a["id"]: a for a in tables[-1]["alarms"]}
    assert tables[-1]["worst"] == "alert"
    assert last["de_kurtosis/ch0"]["level"] == "alert" and last["de_kurtosis/ch0"]["live"] == "normal"
    assert last["de_kurtosis/ch0"]["latched"] is True
    assert last["de_velocity/ch0"]["level"] == "alert" and last["de_velocity/ch0"]["alert_level"] == 2.8
    # no union types: every field present is of its one type (absent when unknown)
    import jsonschema
    row = SCHEMAS["alarms"]["properties"]["alarms"]["items"]["properties"]
    assert all(isinstance(p["type"], str) for p in row.values())
    for m in tables:
        jsonschema.validate(m, SCHEMAS["alarms"])


def status(cfg: Path) -> dict:
    p = run_module("cmsensord", "status", "--config", str(cfg), "--json")
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout)


def test_latched_alarm_acknowledged_over_the_control_socket(tmp_path):
    """A running daemon on a degrading board: the kurtosis alarm latches, the machine eases,
    `cmsensord ack --all` clears it, `cmsensord ack NAME` then has nothing to acknowledge;
    `cmsensord status` shows the table before and after."""
    rule = ("alarms:\n  rules:\n    - {name: de_kurtosis, indicator: kurtosis, alert: 10, latch: true}\n")
    cfg = tmp_path / "cmsensord.yaml"
    with board_on_pty("--scenario", "degrading", "--mode", "raw", "--tacho", "--duration", "24",
                      "--speed", "4") as port:
        d = start_daemon(tmp_path, port, config=rule)
        try:
            deadline = time.monotonic() + 60
            row: dict = {}
            while time.monotonic() < deadline:
                time.sleep(1.0)
                if (tmp_path / "logs" / SOCKET_NAME).exists():
                    t = status(cfg)
                    row = t["alarms"][0] if t.get("alarms") else {}
                    if row.get("latched") and row.get("live") == "normal":
                        break
            assert row.get("level") == "alert" and row["live"] == "normal" and row["latched"], row
            text = run_module("cmsensord", "status", "--config", str(cfg))
            assert "de_kurtosis/ch0" in text.stdout and "latched" in text.stdout, text.stdout
            assert "ALARM alert de_kurtosis/ch0" in text.stdout             # the status line
            p = run_module("cmsensord", "ack", "--all", "--config", str(cfg))
            assert (p.returncode, p.stdout) == (0, "acknowledged 1 alarm(s): de_kurtosis/ch0\n"), p.stdout + p.stderr
            after = status(cfg)
            assert after["alarms"][0]["level"] == "normal" and after["worst"] == "normal"
            assert "| rx " in after["status"] and " frames " in after["status"], after["status"]   # the whole line
            again = run_module("cmsensord", "ack", "de_kurtosis/ch0", "--config", str(cfg))
            assert again.returncode == 0 and again.stdout.strip() == (
                "nothing to acknowledge: de_kurtosis/ch0 shows no level (normal)"), again.stdout
            bad = run_module("cmsensord", "ack", "nope", "--config", str(cfg))
            assert bad.returncode == 1 and "no alarm named 'nope'" in bad.stderr
        finally:
            err = stop(d)
    assert f"WARNING alarm_ack: de_kurtosis/ch0 acknowledged by {pwd.getpwuid(os.getuid()).pw_name} (alert, " \
           "now normal)" in err
    assert "WARNING alarm_clear: de_kurtosis/ch0: alert cleared" in err
    events = [m for t, _, m in read_messages(next((tmp_path / "logs").glob("*.mcap")))
              if t == "/cm/events" and m["kind"].startswith("alarm_")]
    assert [(m["kind"], m["alarm_level"]) for m in events] == [("alarm_alert", "alert"), ("alarm_ack", "normal"),
                                                         ("alarm_clear", "normal")]
    assert not (tmp_path / "logs" / SOCKET_NAME).exists()               # removed at exit


def test_ack_without_a_daemon_is_a_one_line_error(tmp_path):
    p = run_module("cmsensord", "ack", "--all", "--socket", str(tmp_path / "none.sock"))
    assert p.returncode == 1 and p.stderr.count("\n") == 1
    assert p.stderr.startswith(f"cmsensord: no daemon answers on {tmp_path / 'none.sock'}")


def test_calibrate_learns_indicator_baselines_that_relative_alarms_use(tmp_path):
    """`cmsensord calibrate` of a healthy RAW capture writes alarms.baselines (keeping BASE's
    rules); replaying the faulty motor with that site file raises the k x baseline alarm."""
    base = tmp_path / "base.yaml"
    base.write_text("output:\n  status_line: false\nalarms:\n  rules:\n"
                    "    - {name: vel, indicator: velocity_rms_mm_s, alert_x_baseline: 2.0, danger_x_baseline: 4.0}\n")
    for sc in ("healthy", "faulty"):
        ok("firmware_sim", "--scenario", sc, "--mode", "raw", "--tacho", "--duration", "6",
           "--out", str(tmp_path / f"{sc}.bin"))
    site = tmp_path / "site.yaml"
    ok("cmsensord", "calibrate", str(tmp_path / "healthy.bin"), "--to", "5", "--config", str(base),
       "--out", str(site))
    import yaml
    alarms = yaml.safe_load(site.read_text())["alarms"]
    assert alarms["rules"][0]["name"] == "vel"
    learned = {b["indicator"]: b["value"] for b in alarms["baselines"] if b["channel"] == "ch0"}
    assert learned["velocity_rms_mm_s"] == pytest.approx(1.8, rel=0.1)    # the healthy motor (zone B)
    assert learned["kurtosis"] == pytest.approx(3.0, abs=0.4)
    got = {}
    for sc in ("healthy", "faulty"):
        ok("cmsensord", "replay", str(tmp_path / f"{sc}.bin"), "--config", str(site), "--out", str(tmp_path / sc))
        msgs = list(read_messages(next((tmp_path / sc).glob("*.mcap"))))
        got[sc] = [m for t, _, m in msgs if t == "/cm/events" and m["kind"].startswith("alarm_")]
        table = [m for t, _, m in msgs if t == "/cm/alarms"][-1]["alarms"][0]
        assert table["alert_level"] == pytest.approx(2 * learned["velocity_rms_mm_s"], rel=1e-6)
    assert got["healthy"] == []
    assert [m["kind"] for m in got["faulty"]] == ["alarm_danger"]         # ~8.3 mm/s > 4 x 1.8


def test_the_control_socket_works_in_a_deep_output_directory(tmp_path):
    """A socket path longer than sun_path's 108 bytes (a deep output.dir) still binds and answers."""
    import socket

    from cmsensord.service.control import ControlServer, _answers

    deep = tmp_path / ("d" * 80) / ("e" * 80)
    deep.mkdir(parents=True)
    server = ControlServer(deep / "cmsensord.sock")
    try:
        assert len(str(deep / "cmsensord.sock")) > 108 and (deep / "cmsensord.sock").is_socket()
        with socket.socket(socket.AF_UNIX) as s:       # the plain path is too long for connect()
            try:
                s.connect(str(deep / "cmsensord.sock"))
                too_long = False
            except OSError:
                too_long = True
        assert too_long
        assert _answers(deep / "cmsensord.sock")          # connect() through the short name
    finally:
        server.close()
    assert not (deep / "cmsensord.sock").exists()


def test_every_event_field_is_declared_with_one_type(degrading):
    """The alarm events' fields validate against the event schema, and each field an event carries
    is declared there: ``level`` is the severity's integer everywhere; an alarm's levels are
    ``alarm_level`` and ``previous_level`` (a consumer storing ``level`` got a string and an int)."""
    import jsonschema

    msgs, _ = degrading
    events = [m for t, _, m in msgs if t == "/cm/events"]
    assert {m["kind"] for m in events} >= {"alarm_alert", "alarm_danger", "severity_change"}
    declared = set(SCHEMAS["event"]["properties"])
    for m in events:
        jsonschema.validate(m, SCHEMAS["event"])
        assert set(m) <= declared, (m["kind"], set(m) - declared)
