"""Latches and acknowledgements over a daemon's restart, through the commands a user types: a
daemon on a simulated board (faulty, then healthy) stopped with SIGTERM and started again,
`cmsensord status` and `cmsensord ack` on it, the journal lines and the MCAP log; the state
file corrupt, or of rules changed since; `cmsensord replay` and `--simulate` leave it alone."""

from __future__ import annotations

import json
import os
import pwd
import re
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

from cmsensord.sinks.mcap_sink import read_messages
from processes import run_module, spawn, start_board, start_daemon, stop

S = 1_000_000_000
LATCHED = "alarms:\n  rules:\n    - {name: sev, indicator: severity_index, alert: 0.3, danger: 0.6, latch: true}\n"
PLAIN = "alarms:\n  rules:\n    - {name: sev, indicator: severity_index, alert: 0.3, danger: 0.6}\n"


def status(tmp_path: Path) -> dict | None:
    p = run_module("cmsensord", "status", "--config", str(tmp_path / "cmsensord.yaml"), "--json")
    return json.loads(p.stdout) if p.returncode == 0 else None


def wait_row(tmp_path: Path, ok, timeout: float = 60.0) -> dict:
    """The first alarm row of `cmsensord status --json` once ``ok(row)``; fails after ``timeout``."""
    end, row = time.monotonic() + timeout, {}
    while time.monotonic() < end:
        time.sleep(0.5)
        t = status(tmp_path)
        row = t["alarms"][0] if t and t.get("alarms") else {}
        if row and ok(row):
            return row
    raise AssertionError(f"not reached within {timeout:g} s: {row}")


def when(sec: int) -> str:
    return datetime.fromtimestamp(sec).strftime("%Y-%m-%d %H:%M:%S")


def lines(err: str, kind: str) -> list[str]:
    return [ln for ln in err.splitlines() if ln.split(":")[0].endswith(" " + kind)]


def alarm_events(log_dir: Path, newest: bool = True) -> list[dict]:
    path = sorted(log_dir.glob("*.mcap"))[-1 if newest else 0]
    return [m for t, _, m in read_messages(path) if t == "/cm/events" and m["kind"].startswith("alarm_")]


def test_a_latched_alarm_stays_latched_over_a_restart(tmp_path):
    """Danger latched on the faulty board; the healthy board swapped in and the daemon restarted:
    `cmsensord status` still shows the latch, an alarm_restored line says so, `cmsensord ack`
    then clears it, and the state file holds nothing more."""
    link, state = tmp_path / "ttyBOARD", tmp_path / "logs" / "cmsensord-alarms.json"
    board = start_board("--scenario", "faulty", "--speed", "20", "--link", str(link))
    d = start_daemon(tmp_path, link, config=LATCHED)
    before = wait_row(tmp_path, lambda r: r["level"] == "danger")
    stop(d)                                                 # in danger at the stop
    board.terminate()
    board.wait(timeout=5)
    board = start_board("--scenario", "healthy", "--speed", "20", "--link", str(link))
    try:
        d = start_daemon(tmp_path, link, config=LATCHED)
        # the healthy board's values do not confirm the danger active at the stop: after its wait
        # (30 s of stream time) the restored level goes, the latch stays
        row = wait_row(tmp_path, lambda r: r.get("value") == 0.0 and "restored" not in r)
        assert (row["level"], row["live"], row["latched"], row["acknowledged"]) == ("danger", "normal", True, False)
        assert row["since"] == before["since"]
        text = run_module("cmsensord", "status", "--config", str(tmp_path / "cmsensord.yaml")).stdout
        assert "ALARM danger sev/ch0" in text and text.rstrip().endswith("latched"), text
        p = run_module("cmsensord", "ack", "--all", "--config", str(tmp_path / "cmsensord.yaml"))
        assert p.stdout.strip() == "acknowledged 1 alarm(s): sev/ch0", p.stdout + p.stderr
    finally:
        err = stop(d)
        board.terminate()
        board.wait(timeout=5)
    # the faulty board's value may have eased to the alert band by the time the daemon stopped
    [restored] = lines(err, "alarm_restored")
    assert re.fullmatch(re.escape(f"WARNING alarm_restored: sev/ch0: danger latched since "
                                  f"{when(before['since']['sec'])}") + r"(, alert at the stop)?"
                        + re.escape(f" (not acknowledged), from {state}"), restored), restored
    assert lines(err, "alarm_danger") == [] and lines(err, "alarm_not_restored") == []
    assert [(m["kind"], m["alarm"]) for m in alarm_events(tmp_path / "logs")] == [
        ("alarm_restored", "sev/ch0"), ("alarm_ack", "sev/ch0"), ("alarm_clear", "sev/ch0")]
    tables = [m for t, _, m in read_messages(sorted((tmp_path / "logs").glob("*.mcap"))[-1]) if t == "/cm/alarms"]
    assert (tables[0]["worst"], tables[0]["alarms"][0]["latched"]) == ("danger", True)   # the retained table
    assert json.loads(state.read_text())["alarms"] == {}


def test_an_acknowledged_danger_is_not_raised_again_after_a_restart(tmp_path):
    """Danger acknowledged on the faulty board, the daemon restarted on it: the severity index
    climbs back from 0 while the chain starts again, the alarm stays danger and acknowledged
    (by whom and when said), and no alarm_alert or alarm_danger is raised anew."""
    link, state = tmp_path / "ttyBOARD", tmp_path / "logs" / "cmsensord-alarms.json"
    board = start_board("--scenario", "faulty", "--speed", "20", "--link", str(link))
    try:
        d = start_daemon(tmp_path, link, config=PLAIN)
        wait_row(tmp_path, lambda r: r["level"] == "danger")
        p = run_module("cmsensord", "ack", "sev/ch0", "--config", str(tmp_path / "cmsensord.yaml"))
        assert p.stdout.strip() == "acknowledged 1 alarm(s): sev/ch0", p.stdout + p.stderr
        acked = wait_row(tmp_path, lambda r: r["acknowledged"])
        stop(d)
        d = start_daemon(tmp_path, link, config=PLAIN)
        row = wait_row(tmp_path, lambda r: r.get("live") == "danger")
    finally:
        err = stop(d)
        board.terminate()
        board.wait(timeout=5)
    assert [m["kind"] for m in alarm_events(tmp_path / "logs")] == ["alarm_restored"]
    index = [m["severity_index"] for t, _, m in read_messages(sorted((tmp_path / "logs").glob("*.mcap"))[-1])
             if t == "/cm/ch0/severity"]
    assert index[0] < 0.3 and max(index) >= 0.6, index            # the chain started again from 0
    assert (row["level"], row["acknowledged"], row["since"]) == ("danger", True, acked["since"])
    saved = json.loads(state.read_text())["alarms"]["sev/ch0"]
    assert saved["acked_by"] == pwd.getpwuid(os.getuid()).pw_name
    assert lines(err, "alarm_restored") == [
        f"WARNING alarm_restored: sev/ch0: danger since {when(acked['since']['sec'])} (acknowledged "
        f"{when(saved['acked_ns'] // S)} by {saved['acked_by']}), from {state}"]


def test_a_corrupt_state_file_is_one_warning_and_the_daemon_runs_on(tmp_path):
    (tmp_path / "logs").mkdir()
    state = tmp_path / "logs" / "cmsensord-alarms.json"
    torn = '{"format": "cmsensord-alarms", "version": 1, "alarms": {"sev/ch0": {"rule": "s'
    state.write_text(torn)
    try:
        json.loads(torn)
    except ValueError as exc:
        why = str(exc)
    link = tmp_path / "ttyBOARD"
    board = start_board("--scenario", "faulty", "--speed", "20", "--link", str(link))
    try:
        d = start_daemon(tmp_path, link, config=LATCHED)
        wait_row(tmp_path, lambda r: r["level"] == "danger")
    finally:
        err = stop(d)
        board.terminate()
        board.wait(timeout=5)
    assert d.returncode == 0 and "Traceback" not in err
    assert [ln for ln in err.splitlines() if "alarm_state_error:" in ln] == [
        f"WARNING alarm_state_error: {state}: not JSON (truncated?): {why}: kept as cmsensord-alarms.json.bad; "
        "no latch or acknowledgement is restored"]
    counts = next(ln for ln in err.splitlines() if ln.startswith("  events: "))
    assert "alarm_state_error 1," in counts and "alarm_danger 1," in counts, counts
    assert (tmp_path / "logs" / "cmsensord-alarms.json.bad").read_text() == torn
    assert json.loads(state.read_text())["alarms"]["sev/ch0"]["latched"] == "danger"   # kept anew
    assert [m["kind"] for m in alarm_events(tmp_path / "logs")][:1] == ["alarm_state_error"]


def saved_latch(rule: str, level: str, since_ns: int, **levels: float) -> dict:
    return {"rule": rule, "indicator": "severity_index", "latch": True, "levels": levels, "level": level,
            "live": "normal", "latched": level, "acknowledged": False, "since_ns": since_ns}


def test_latches_of_rules_gone_or_changed_are_said(tmp_path):
    """A latch of a rule no longer configured is dropped with an alarm_not_restored line; one
    whose levels changed since is kept, the change said."""
    (tmp_path / "logs").mkdir()
    state = tmp_path / "logs" / "cmsensord-alarms.json"
    since = (int(time.time()) - 3600) * S
    state.write_text(json.dumps({"format": "cmsensord-alarms", "version": 1, "alarms": {
        "old/ch0": saved_latch("old", "danger", since, alert=0.3, danger=0.6),
        "sev/ch0": saved_latch("sev", "alert", since, alert=0.2, danger=0.5)}}))
    link = tmp_path / "ttyBOARD"
    board = start_board("--scenario", "healthy", "--speed", "20", "--link", str(link))
    try:
        d = start_daemon(tmp_path, link, config=LATCHED)
        row = wait_row(tmp_path, lambda r: "value" in r)
    finally:
        err = stop(d)
        board.terminate()
        board.wait(timeout=5)
    assert (row["level"], row["live"], row["latched"]) == ("alert", "normal", True)
    assert lines(err, "alarm_not_restored") == [
        f"WARNING alarm_not_restored: old/ch0: danger latched since {when(since // S)}, normal at the stop "
        f"(not acknowledged) not restored: the configuration has no rule old now, from {state}"]
    assert lines(err, "alarm_restored") == [
        f"WARNING alarm_restored: sev/ch0: alert latched since {when(since // S)}, normal at the stop "
        "(not acknowledged); its "
        "levels changed since (alert 0.2 -> 0.3, danger 0.5 -> 0.6): the latch is kept, the value judged "
        f"afresh, from {state}"]
    kept = json.loads(state.read_text())["alarms"]
    assert list(kept) == ["sev/ch0"] and kept["sev/ch0"]["levels"] == {"alert": 0.3, "danger": 0.6}


def test_replay_and_simulate_leave_the_state_file_alone(tmp_path):
    """A replay is not the machine's present, nor is a simulated board: neither restores the
    latch in the output directory's state file, nor writes it."""
    site = tmp_path / "site.yaml"
    site.write_text("output:\n  status_line: false\n" + LATCHED)
    state = tmp_path / "out" / "cmsensord-alarms.json"
    state.parent.mkdir()
    held = json.dumps({"format": "cmsensord-alarms", "version": 1, "alarms": {
        "sev/ch0": saved_latch("sev", "alert", 1_700_000_000 * S, alert=0.3, danger=0.6)}})
    state.write_text(held)
    assert run_module("firmware_sim", "--scenario", "faulty", "--duration", "8",
                      "--out", str(tmp_path / "f.bin")).returncode == 0
    p = run_module("cmsensord", "replay", str(tmp_path / "f.bin"), "--config", str(site), "--out", str(state.parent))
    assert p.returncode == 0, p.stderr
    assert [m["kind"] for m in alarm_events(state.parent)] == ["alarm_alert", "alarm_danger"]
    p = run_module("cmsensord", "--simulate", "--scenario", "faulty", "--duration", "8", "--speed", "20",
                   "--config", str(site), "--out", str(state.parent))
    assert p.returncode == 0, p.stderr
    assert "alarm_restored" not in p.stderr and "ERROR alarm_danger: sev/ch0" in p.stderr
    assert state.read_text() == held


def test_a_latch_saved_by_the_last_run_is_shown_and_acknowledged_before_data_comes(tmp_path):
    """Restarted with the board off: the alarms are made with the first data, but the status
    line and table already show the latched danger the last run saved, and `cmsensord ack` takes
    it (guards against nothing shown and `no alarm named 'sev/ch0'`)."""
    link = tmp_path / "ttyBOARD"
    board = start_board("--scenario", "faulty", "--speed", "20", "--link", str(link))
    d = start_daemon(tmp_path, link, config=LATCHED)
    try:
        wait_row(tmp_path, lambda r: r["level"] == "danger")
    finally:
        stop(d)
        board.terminate()
        board.wait(timeout=5)
    d = start_daemon(tmp_path, link, config=LATCHED)             # no board on the port now
    cfg = str(tmp_path / "cmsensord.yaml")
    try:
        text, end = "", time.monotonic() + 20
        while "ALARM" not in text and time.monotonic() < end:
            time.sleep(0.5)
            text = run_module("cmsensord", "status", "--config", cfg).stdout
        acked = run_module("cmsensord", "ack", "sev/ch0", "--config", cfg)
        after = run_module("cmsensord", "status", "--config", cfg).stdout
    finally:
        err = stop(d)
    assert "ALARM danger sev/ch0 (saved by the last run; waiting for data)" in text, text
    assert "worst: danger (sev/ch0)" in text and text.rstrip().endswith("latched saved"), text
    assert (acked.returncode, acked.stdout) == (0, "acknowledged 1 alarm(s): sev/ch0\n"), acked.stdout + acked.stderr
    assert after.rstrip().endswith("danger  -                -      0.3      0.6 -      acknowledged saved"), after
    user = pwd.getpwuid(os.getuid()).pw_name
    assert lines(err, "alarm_ack") == [f"WARNING alarm_ack: sev/ch0 acknowledged by {user} (danger, saved by the "
                                       "last run; danger at its stop, judged again when data comes)"], err
    rec = json.loads((tmp_path / "logs" / "cmsensord-alarms.json").read_text())["alarms"]["sev/ch0"]
    assert (rec["latched"], rec["level"], rec["acknowledged"]) == ("normal", "danger", True)
    assert (rec["alert_level"], rec["danger_level"]) == (0.3, 0.6)        # the levels in force, saved


def test_a_latch_raised_on_a_full_disk_is_saved_once_space_returns(small_fs, tmp_path):
    """The state file cannot be written while the disk is full: one warning, then the daemon
    tries again (it tried only at the next change, never while a latch just held)."""
    from test_disk_full import fill

    link, logs = tmp_path / "ttyBOARD", small_fs / "logs"
    board = start_board("--scenario", "faulty", "--speed", "20", "--link", str(link))
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text(f"link:\n  port: {link}\n  max_drift_s: 0\noutput:\n  dir: {logs}\n  status_line: false\n"
                   f"  retain_mb: 0\n  min_free_mb: 0\n  retry_s: 1.0\n{LATCHED}")
    logs.mkdir()
    filler = fill(small_fs, leave=0)
    d = spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg)], stderr=subprocess.PIPE, text=True)
    try:
        wait_row(tmp_path, lambda r: r["level"] == "danger")
        filler.unlink()
        time.sleep(3.0)                                      # 60 s of stream time at 20x
    finally:
        err = stop(d)
        board.terminate()
        board.wait(timeout=5)
    assert len(lines(err, "alarm_state_error")) == 1, err[-3000:]
    assert f"INFO alarm state: written to {logs / 'cmsensord-alarms.json'} again" in err, err[-3000:]
    saved = json.loads((logs / "cmsensord-alarms.json").read_text())["alarms"]
    assert saved["sev/ch0"]["latched"] == "danger", saved


def test_a_latched_alarm_acknowledged_while_active_clears_when_the_value_falls_and_stays_cleared(tmp_path):
    """`cmsensord ack` while the latched danger is still on (the operator's usual action); the
    faulty board swapped for a healthy one: the alarm clears (guards against it staying at danger,
    'acknowledged', refusing any further ack, over a restart too)."""
    link = tmp_path / "ttyBOARD"
    cfg = str(tmp_path / "cmsensord.yaml")
    board = start_board("--scenario", "faulty", "--speed", "20", "--link", str(link))
    d = start_daemon(tmp_path, link, config=LATCHED)
    try:
        wait_row(tmp_path, lambda r: r.get("live") == "danger")
        acked = run_module("cmsensord", "ack", "--all", "--config", cfg)
        assert acked.stdout.strip() == "acknowledged 1 alarm(s): sev/ch0", acked.stdout + acked.stderr
        board.terminate()
        board.wait(timeout=5)
        board = start_board("--scenario", "healthy", "--speed", "20", "--link", str(link))
        row = wait_row(tmp_path, lambda r: r.get("live") == "normal")
    finally:
        err = stop(d)
        board.terminate()
        board.wait(timeout=5)
    assert (row["level"], row["latched"], row["acknowledged"]) == ("normal", False, False), row
    kinds = [m["kind"] for m in alarm_events(tmp_path / "logs")]
    after = kinds[len(kinds) - 1 - kinds[::-1].index("alarm_ack") + 1:]
    # the healthy board's severity may pass through the alert band on its way down (eased to alert)
    assert after in (["alarm_clear"], ["alarm_alert", "alarm_clear"]), err[-3000:]
    assert json.loads((tmp_path / "logs" / "cmsensord-alarms.json").read_text())["alarms"] == {}


def run_healthy(tmp_path: Path, config: str, ok=lambda r: "value" in r) -> tuple[dict, str]:
    """A daemon with ``config`` on the healthy board until its first alarm row is ``ok``: that row
    and its stderr (it exited 0, no traceback)."""
    link = tmp_path / "ttyBOARD"
    board = start_board("--scenario", "healthy", "--speed", "20", "--link", str(link))
    try:
        d = start_daemon(tmp_path, link, config=config)
        row = wait_row(tmp_path, ok)
    finally:
        err = stop(d)
        board.terminate()
        board.wait(timeout=5)
    assert d.returncode == 0 and "Traceback" not in err, err[-3000:]
    return row, err


def test_a_stamp_out_of_range_in_the_state_file_is_one_warning_and_the_daemon_runs_on(tmp_path):
    """since_ns 10**30 (or acked_ns -10**20): guards against an OverflowError ending the daemon at
    every restart, the file left in place."""
    (tmp_path / "logs").mkdir()
    state = tmp_path / "logs" / "cmsensord-alarms.json"
    for key, stamp in (("since_ns", 10**30), ("acked_ns", -10**20)):
        rec = {**saved_latch("sev", "alert", 1_700_000_000 * S, alert=0.3, danger=0.6), key: stamp}
        if key == "acked_ns":
            rec.update(latched="normal", live="alert", acknowledged=True)
        held = json.dumps({"format": "cmsensord-alarms", "version": 1, "alarms": {"sev/ch0": rec}})
        state.write_text(held)
        row, err = run_healthy(tmp_path, LATCHED)
        assert lines(err, "alarm_state_error") == [
            f"WARNING alarm_state_error: {state}: alarm 'sev/ch0': {key} {stamp} is out of range (a stamp in ns, "
            "1970 to 2262): kept as cmsensord-alarms.json.bad; no latch or acknowledgement is restored"]
        assert lines(err, "alarm_restored") == [] and row["level"] == "normal"
        assert (tmp_path / "logs" / "cmsensord-alarms.json.bad").read_text() == held


BASELINE = ("alarms:\n  rules:\n    - {name: base, indicator: accel_rms, alert_x_baseline: 2}\n"
            "  baselines: [{channel: ch0, indicator: accel_rms, value: %s}]\n")


def test_an_alert_of_a_baseline_level_is_judged_afresh_after_a_new_baseline(tmp_path):
    """The alert above 2 x 0.1 at the stop; restarted with the baseline 1.0 learned since (the
    healthy board's 0.69 m/s² is below 2 x 1.0): not the same episode, said, and normal (guards
    against the multiplier alone compared: the same alert restored, no word of the new level)."""
    state = tmp_path / "logs" / "cmsensord-alarms.json"
    before, _ = run_healthy(tmp_path, BASELINE % "0.1", lambda r: r["level"] == "alert")
    saved = json.loads(state.read_text())["alarms"]["base/ch0"]
    row, err = run_healthy(tmp_path, BASELINE % "1.0", lambda r: r.get("alert_level") == 2.0)
    assert lines(err, "alarm_not_restored") == [
        f"WARNING alarm_not_restored: base/ch0: alert since {when(before['since']['sec'])} (not acknowledged) not "
        f"restored: its levels changed since (baseline on ch0 0.1 -> 1.0): judged afresh against them, from {state}"]
    assert lines(err, "alarm_restored") == [] and lines(err, "alarm_alert") == []
    assert (row["level"], "restored" in row) == ("normal", False)
    assert saved["levels"] == {"alert_x_baseline": 2.0, "baselines": {"ch0": 0.1}}


def test_a_baseline_alert_saved_without_its_baseline_is_restored_as_the_same_episode(tmp_path):
    """A state file whose records do not hold the baselines their levels were resolved against is
    taken as resolved against the present ones: the alert is restored, the rule confirms it, and
    no alarm_alert is raised anew."""
    (tmp_path / "logs").mkdir()
    state = tmp_path / "logs" / "cmsensord-alarms.json"
    since = (int(time.time()) - 600) * S
    state.write_text(json.dumps({"format": "cmsensord-alarms", "version": 1, "alarms": {"base/ch0": {
        "rule": "base", "indicator": "accel_rms", "latch": False, "levels": {"alert_x_baseline": 2.0},
        "level": "alert", "live": "alert", "latched": "normal", "acknowledged": False, "since_ns": since}}}))
    row, err = run_healthy(tmp_path, BASELINE % "0.1", lambda r: r.get("live") == "alert")
    assert lines(err, "alarm_restored") == [
        f"WARNING alarm_restored: base/ch0: alert since {when(since // S)} (not acknowledged), from {state}"]
    assert lines(err, "alarm_alert") == [] and row["since"]["sec"] == since // S
    assert json.loads(state.read_text())["alarms"]["base/ch0"]["levels"]["baselines"] == {"ch0": 0.1}


def status_before_data(tmp_path: Path, recs: dict, config: str) -> tuple[subprocess.CompletedProcess, dict]:
    """The daemon started with the board off and ``recs`` in its alarm state file: the text of
    `cmsensord status` once it answers, and its --json answer."""
    (tmp_path / "logs").mkdir(exist_ok=True)
    (tmp_path / "logs" / "cmsensord-alarms.json").write_text(json.dumps(
        {"format": "cmsensord-alarms", "version": 1, "alarms": recs}))
    d = start_daemon(tmp_path, tmp_path / "no-board", config=config)
    cfg = str(tmp_path / "cmsensord.yaml")
    try:
        end, p = time.monotonic() + 20, None
        while time.monotonic() < end:
            time.sleep(0.3)
            p = run_module("cmsensord", "status", "--config", cfg)
            if p.returncode == 0:
                break
        answer = json.loads(run_module("cmsensord", "status", "--config", cfg, "--json").stdout)
    finally:
        stop(d)
    assert p is not None and p.returncode == 0, p and p.stderr
    return p, answer


def test_a_saved_alarm_waiting_for_data_shows_no_live_level(tmp_path):
    """Restarted with the board off, a latched danger the last run saved (danger too at its stop):
    `cmsensord status` shows the latch, its levels (the rule's saved settings), and its live level
    as not known ("-", absent in --json), not "normal" (guards against the table saying the value
    is back to normal with no value yet)."""
    rec = {**saved_latch("sev", "danger", (int(time.time()) - 60) * S, alert=0.3, danger=0.6), "live": "danger"}
    p, answer = status_before_data(tmp_path, {"sev/ch0": rec}, LATCHED)
    row = "sev/ch0                  danger  -                -      0.3      0.6 -      latched saved"
    assert p.stdout.splitlines()[-1] == row, p.stdout
    assert "live" not in answer["alarms"][0] and answer["alarms"][0]["saved"] is True, answer


BANDS = ("alarms:\n  rules:\n"
         "    - {name: band, indicator: accel_rms, alert: 0.3, danger: 0.6, latch: true,\n"
         "       bands: [{below_rpm: 600, alert: 0.1, danger: 0.2}]}\n"
         "    - {name: slow, indicator: accel_rms, alert: 0.3, danger: 0.6, latch: true,\n"
         "       bands: [{below_rpm: 600, alert: 0.1, danger: 0.2}]}\n"
         "    - {name: base, indicator: accel_rms, alert_x_baseline: 2.0, danger_x_baseline: 4.0, latch: true}\n"
         "    - {name: old, indicator: accel_rms, alert_x_baseline: 2.0, latch: true}\n"
         "  baselines: [{channel: ch0, indicator: accel_rms, value: 0.25}]\n")


def test_saved_alarms_waiting_for_data_show_the_levels_they_were_judged_by(tmp_path):
    """Restarted with the board off, `cmsensord status` shows each saved alarm's alert and danger
    levels as a live row would: those in force when saved (a speed band's 0.1/0.2, not the rule's
    0.3/0.6), a baseline level from the saved baseline; where the record holds no such number,
    what the level depends on (`by speed`, `2xbase`), never "-" for a level the rule has."""
    since = (int(time.time()) - 60) * S
    bands = {"alert": 0.3, "danger": 0.6, "bands": [{"below_rpm": 600, "alert": 0.1, "danger": 0.2}]}
    recs = {"band/ch0": {**saved_latch("band", "alert", since), "levels": bands, "alert_level": 0.1,
                         "danger_level": 0.2},
            "slow/ch0": {**saved_latch("slow", "alert", since), "levels": bands},
            "base/ch0": {**saved_latch("base", "alert", since),
                         "levels": {"alert_x_baseline": 2.0, "danger_x_baseline": 4.0, "baselines": {"ch0": 0.25}}},
            "old/ch0": {**saved_latch("old", "alert", since), "levels": {"alert_x_baseline": 2.0}}}
    recs = {name: {**rec, "indicator": "accel_rms"} for name, rec in recs.items()}
    p, answer = status_before_data(tmp_path, recs, BANDS)
    assert p.stdout.splitlines()[-4:] == [
        "band/ch0                 alert   -                -      0.1      0.2 m/s²   latched saved",
        "slow/ch0                 alert   -                - by speed by speed m/s²   latched saved",
        "base/ch0                 alert   -                -      0.5        1 m/s²   latched saved",
        "old/ch0                  alert   -                -   2xbase        - m/s²   latched saved"], p.stdout
    rows = {r["id"]: r for r in answer["alarms"]}
    assert (rows["band/ch0"]["alert_level"], rows["band/ch0"]["danger_level"]) == (0.1, 0.2)
    assert (rows["slow/ch0"]["alert_on"], rows["slow/ch0"]["danger_on"]) == ("by speed", "by speed")
    assert rows["old/ch0"]["alert_on"] == "2xbase" and "danger_level" not in rows["old/ch0"], rows


def test_a_saved_alarm_of_a_rule_edited_since_shows_the_levels_in_force_now(tmp_path):
    """Restarted with the board off after the rule's levels were edited (0.3/0.6 -> 0.5/1.0) and a
    baseline learned again (0.25 -> 0.4): `cmsensord status` showed the levels saved, which are no
    longer in force (its next value is judged against the new ones); it shows the rule's levels
    now. A saved alarm of a rule no longer configured shows none."""
    since = (int(time.time()) - 60) * S
    recs = {"sev/ch0": {**saved_latch("sev", "danger", since, alert=0.3, danger=0.6), "alert_level": 0.3,
                        "danger_level": 0.6},
            "base/ch0": {**saved_latch("base", "alert", since), "alert_level": 0.5, "danger_level": 1.0,
                         "levels": {"alert_x_baseline": 2.0, "danger_x_baseline": 4.0, "baselines": {"ch0": 0.25}}},
            "gone/ch0": {**saved_latch("gone", "alert", since, alert=0.3), "alert_level": 0.3}}
    recs = {name: {**rec, "indicator": "accel_rms"} for name, rec in recs.items()}
    p, _ = status_before_data(tmp_path, recs, (
        "alarms:\n  rules:\n"
        "    - {name: sev, indicator: accel_rms, alert: 0.5, danger: 1.0, latch: true}\n"
        "    - {name: base, indicator: accel_rms, alert_x_baseline: 2.0, danger_x_baseline: 4.0, latch: true}\n"
        "  baselines: [{channel: ch0, indicator: accel_rms, value: 0.4}]\n"))
    assert p.stdout.splitlines()[-3:] == [
        "sev/ch0                  danger  -                -      0.5        1 m/s²   latched saved",
        "base/ch0                 alert   -                -      0.8      1.6 m/s²   latched saved",
        "gone/ch0                 alert   -                -        -        - m/s²   latched saved"], p.stdout
