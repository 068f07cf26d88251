"""`cmsensord calibrate` end to end: simulator capture -> calibrate -> replay --config SITE.yaml."""

from __future__ import annotations

import os
import re
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from cmsensord.sinks.mcap_sink import read_messages
from processes import ENV, on_terminal


def run(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, env=ENV,
                          timeout=timeout)


@pytest.fixture(scope="module")
def degrading(tmp_path_factory):
    """600 s of the degrading motor, RMS mode: healthy at first, failing at the end."""
    path = tmp_path_factory.mktemp("cal") / "degrading.bin"
    p = run("firmware_sim", "--scenario", "degrading", "--duration", "600", "--seed", "3", "--out", str(path))
    assert p.returncode == 0, p.stderr
    return path


def _severity(out_dir: Path, channel="ch0"):
    msgs = read_messages(next(out_dir.glob("*.mcap")))
    sev = [(t, m) for topic, t, m in msgs if topic == f"/cm/{channel}/severity"]
    t0 = sev[0][0] - 1_000_000_000          # the first decision ends 1 s after the first block
    return [((t - t0) / 1e9, m) for t, m in sev]


def test_calibrate_writes_a_site_file_that_keeps_the_healthy_period_silent(degrading, tmp_path):
    site = tmp_path / "site.yaml"
    p = run("cmsensord", "calibrate", str(degrading), "--to", "150", "--out", str(site))
    assert p.returncode == 0, p.stderr
    assert "healthy period: 0.0-150.0 board s, 100 blocks/s" in p.stdout
    assert "ch0: highest outlier count per decision on the healthy period at R_1:" in p.stdout
    assert ("ch0: f_r 28.66 Hz is the configuration's monitor.f_r: nothing gave this machine's shaft speed "
            "(no tacho, no --rpm, no indicators.rpm, no rpm in the capture); if it turns at another speed, give "
            "--rpm RPM\n") in p.stdout
    ch = yaml.safe_load(site.read_text())["channels"][0]
    assert ch["name"] == "ch0" and ch["baseline"] > 0 and ch["r_max"] > ch["r_min"] > 0
    again = tmp_path / "again.yaml"
    assert run("cmsensord", "calibrate", str(degrading), "--to", "150", "--out", str(again)).returncode == 0
    assert again.read_bytes() == site.read_bytes()

    out = tmp_path / "logs"
    p = run("cmsensord", "replay", str(degrading), "--config", str(site), "--out", str(out))
    assert p.returncode == 0, p.stderr
    sev = _severity(out)
    assert all(m["severity_index"] == 0.0 for t, m in sev if t <= 150.5)
    assert max(m["severity_index"] for _, m in sev) == 1.0
    last = sev[-1][1]
    assert {"severity_akf", "severity_level", "level_ratio"} <= set(last)
    assert last["severity_index"] == max(last["severity_akf"], last["severity_level"])


def test_calibrate_on_a_base_config_keeps_its_settings(degrading, tmp_path):
    base = tmp_path / "base.yaml"
    base.write_text("monitor:\n  c: 0.5\nchannels:\n  - name: motor_de\n    z_c: 3.0\n")
    site = tmp_path / "site.yaml"
    p = run("cmsensord", "calibrate", str(degrading), "--to", "100", "--config", str(base), "--out", str(site))
    assert p.returncode == 0, p.stderr
    cfg = yaml.safe_load(site.read_text())
    assert cfg["monitor"]["c"] == 0.5
    assert cfg["channels"][0]["name"] == "motor_de" and cfg["channels"][0]["z_c"] == 3.0


def test_calibrate_says_nothing_of_f_r_when_the_speed_is_given(degrading, tmp_path):
    p = run("cmsensord", "calibrate", str(degrading), "--to", "150", "--rpm", "1500", "--out", str(tmp_path / "s.yaml"))
    assert p.returncode == 0, p.stderr
    assert "ch0           25.000 --rpm" in p.stdout
    assert "monitor.f_r" not in p.stdout


def test_calibrate_healthy_period_as_a_percentage_of_the_capture(degrading, tmp_path):
    """--to 25% of a 600-s capture is --to 150: the same site file, byte for byte."""
    by_s, by_pct = tmp_path / "s.yaml", tmp_path / "p.yaml"
    assert run("cmsensord", "calibrate", str(degrading), "--to", "150", "--out", str(by_s)).returncode == 0
    p = run("cmsensord", "calibrate", str(degrading), "--from", "0%", "--to", "25%", "--out", str(by_pct))
    assert p.returncode == 0, p.stderr
    assert "healthy period: 0.0-150.0 board s, 100 blocks/s" in p.stdout
    assert by_pct.read_bytes() == by_s.read_bytes()


@pytest.mark.parametrize("args, line, code", [
    (["--from", "90%", "--to", "10%"], "cmsensord: calibrate: --to 10 % is not after --from 90 %: the healthy "
                                       "period runs from --from to --to (board seconds, or % of the capture)", 2),
    (["--to", "0"], "cmsensord: calibrate: --to 0 is not after --from 0: the healthy period runs from --from to "
                    "--to (board seconds, or % of the capture)", 2),
    (["--from", "50", "--to", "40"], "cmsensord: calibrate: --to 40 is not after --from 50: the healthy period "
                                     "runs from --from to --to (board seconds, or % of the capture)", 2),
    (["--from", "90%", "--to", "500"], "cmsensord: calibrate: {cap}: no observations between 90 % and 500 "
                                       "(board seconds, or % of the capture; it holds 600.0 s)", 2),
    (["--to", "120%"], "cmsensord calibrate: error: argument --to: expected board seconds >= 0 or a percentage "
                       "0-100%, got '120%' (see cmsensord calibrate --help)", 2),
    (["--from", "early"], "cmsensord calibrate: error: argument --from: expected board seconds >= 0 or a "
                          "percentage 0-100%, got 'early' (see cmsensord calibrate --help)", 2),
    (["--rpm", "6000"], "cmsensord: configuration error: calibrate: ch0.f_r: 100 Hz must be below the 100 "
                        "observations per decision (100 blocks/s x decision_period_s 1); for a machine this fast "
                        "give a longer decision: monitor: {{decision_period_s: 2}} in --config BASE.yaml\n", 78),
    (["--from", "700"], "cmsensord: calibrate: {cap}: no observations between 700 and", 2),
    (["--to", "1"], "cmsensord: calibrate: channel ch0: the healthy period holds 100 observation(s) (1 s), fewer "
                    "than the 2 decision periods learning needs (200, 2 s: the first is the filters' transient); "
                    "give a longer one (--to 2 or later)", 2),
    (["--from", "10", "--to", "11.5"], "cmsensord: calibrate: channel ch0: the healthy period holds 150 "
                                       "observation(s) (1.5 s), fewer than the 2 decision periods learning needs "
                                       "(200, 2 s: the first is the filters' transient); give a longer one (--to 12 "
                                       "or later)", 2),
])
def test_calibrate_errors_are_one_line(degrading, tmp_path, args, line, code):
    p = run("cmsensord", "calibrate", str(degrading), *args, "--out", str(tmp_path / "s.yaml"))
    assert p.returncode == code
    assert p.stderr.startswith(line.format(cap=degrading)), p.stderr
    assert len(p.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "s.yaml").exists() and not (tmp_path / "s.yaml.part").exists()


@pytest.mark.parametrize("out, line", [
    ("{tmp}", "cmsensord: calibrate: {tmp}: is a directory; give --out a file name, e.g. {tmp}/site.yaml"),
    ("{tmp}/no/s.yaml", "cmsensord: calibrate: {tmp}/no/s.yaml: cannot write the site file: no directory {tmp}/no"),
])
def test_calibrate_to_an_output_it_cannot_write_is_one_line_before_the_read(tmp_path, out, line):
    """--out is checked first: the capture given does not exist, and the --out line is the one told."""
    p = run("cmsensord", "calibrate", str(tmp_path / "nope.bin"), "--out", out.format(tmp=tmp_path))
    assert p.returncode == 2
    assert p.stderr.strip() == line.format(tmp=tmp_path)
    assert sorted(tmp_path.iterdir()) == []


def test_calibrate_to_a_fifo_leaves_it_and_is_one_line(tmp_path):
    """--out naming a FIFO (or a device: /dev/full, as root) is refused before the capture is read:
    the site file written beside it and renamed over it replaced it with a regular file."""
    cap = tmp_path / "cap.bin"
    assert run("firmware_sim", "--scenario", "healthy", "--duration", "5", "--out", str(cap)).returncode == 0
    out = tmp_path / "site.yaml"
    os.mkfifo(out)
    p = run("cmsensord", "calibrate", str(cap), "--out", str(out))
    assert (p.returncode, p.stderr) == (2, f"cmsensord: calibrate: {out}: is a FIFO, not a regular file: the site "
                                           "file would replace it; give --out a file name\n")
    assert stat.S_ISFIFO(os.lstat(out).st_mode)


def test_calibrate_when_the_site_file_cannot_be_written_is_one_line(degrading):
    """A write that fails after the read (a directory that takes no new file: /proc, even for root)
    is one line after the table, and nothing is left."""
    out = Path("/proc/cmsensord-site.yaml")
    p = run("cmsensord", "calibrate", str(degrading), "--to", "150", "--out", str(out))
    assert p.returncode == 2
    assert "healthy period: 0.0-150.0 board s" in p.stdout
    assert p.stderr.strip().splitlines() == [
        f"cmsensord: calibrate: {out}: cannot write the site file: No such file or directory"]
    assert not out.exists() and not Path(f"{out}.part").exists()


def test_calibrate_of_a_missing_capture(tmp_path):
    p = run("cmsensord", "calibrate", str(tmp_path / "nope.bin"), "--out", str(tmp_path / "s.yaml"))
    assert p.returncode == 2
    assert p.stderr.strip() == f"cmsensord: {tmp_path / 'nope.bin'}: capture file not found"


def test_f_r_at_the_decision_size_is_a_configuration_error(degrading, tmp_path):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text("monitor:\n  f_r: 100\n")
    p = run("cmsensord", "replay", str(degrading), "--config", str(cfg), "--out", str(tmp_path / "o"))
    assert p.returncode == 78
    assert p.stderr.strip() == (
        f"cmsensord: configuration error: {cfg}: monitor.f_r: must be below the 100 observations per "
        "decision (decision_period_s 1 x 100 blocks/s): at or above it no decision can flag an anomaly; "
        "for a machine this fast give decision_period_s: 2 (got 100.0)")
    cfg.write_text("monitor:\n  f_r: 100\n  decision_period_s: 2\n")        # the advice: a replay
    p = run("cmsensord", "replay", str(degrading), "--config", str(cfg), "--out", str(tmp_path / "o"))
    assert p.returncode == 0, p.stderr


def test_faulty_capture_sets_r_max(degrading, tmp_path):
    faulty = tmp_path / "faulty.bin"
    p = run("firmware_sim", "--scenario", "faulty", "--duration", "30", "--seed", "4", "--out", str(faulty))
    assert p.returncode == 0, p.stderr
    plain, with_faulty = tmp_path / "plain.yaml", tmp_path / "faulty.yaml"
    assert run("cmsensord", "calibrate", str(degrading), "--to", "150", "--out", str(plain)).returncode == 0
    p = run("cmsensord", "calibrate", str(degrading), "--to", "150", "--faulty", str(faulty),
            "--out", str(with_faulty))
    assert p.returncode == 0, p.stderr
    a = yaml.safe_load(plain.read_text())["channels"][0]
    b = yaml.safe_load(with_faulty.read_text())["channels"][0]
    assert b["r_max"] > a["r_max"] and b["baseline"] == a["baseline"]
    assert "# R_n: the largest R that still flags the faulty capture" in with_faulty.read_text()


def test_calibrate_table_keeps_its_columns_under_a_long_channel_name(tmp_path):
    """An import's channel named as its file names it (XJTU-SY: Horizontal_vibration_signals):
    every row of the table as long as its heading, the names' column as wide as the longest."""
    from tests.test_import_names import R2F, run_to_failure

    d = run_to_failure(tmp_path)
    name = "Horizontal_vibration_signals"
    p = run("cmsensord", "import", str(d), *R2F, "--names", name, "--out", str(tmp_path / "r.bin"))
    assert p.returncode == 0, p.stderr
    p = run("cmsensord", "calibrate", str(tmp_path / "r.bin"), "--to", "25%", "--out", str(tmp_path / "s.yaml"))
    assert p.returncode == 0, p.stderr
    lines = p.stdout.splitlines() + p.stderr.splitlines()
    head = next(ln for ln in lines if ln.startswith("channel "))
    row = next(ln for ln in lines if ln.startswith(f"{name} "))
    assert len(row) == len(head) and head.index("f_r Hz") == len(name) + 2, (head, row)


def test_a_healthy_period_that_holds_the_fault_is_said_with_where_a_steady_one_ends(degrading, tmp_path):
    """The whole run to failure given as healthy: calibrate says which of its decisions are
    already at level_alert x the baseline (the replay grades them 0.5) and, as the level rises
    well before them, one --to: the rise's, the earlier, said why once (the steady stretch within
    2 x its own median, to 266 s, learns the rise: 21 of its decisions flagged by R_1); calibrated
    to it, nothing is said.  Calibrated to 266, no level is graded in the period, and the rise
    is said with its --to."""
    p = run("cmsensord", "calibrate", str(degrading), "--out", str(tmp_path / "all.yaml"))
    assert p.returncode == 0, p.stderr
    assert ("ch0: warning: 141 decision(s) of the healthy period are already at >= 2 x its baseline "
            "(level_alert: severity 0.5) in 391.0-541.0 board s: the machine may already be changing there "
            "(a fault starting); the level already rises before them (next warning)\n"
            "ch0: warning: the level rises through the healthy period: its last quarter's median is 6.44 x its first "
            "quarter's, rising from 85.0 board s: wear or a fault starting, or a change of load; learned from, it "
            "raises the baseline and widens every margin: a period ending before it learns the machine's own level "
            "(--to 85); the steady stretch from the start, whose levels stay within 2 x its own median, runs on past "
            "the rise and would learn it\n") in p.stdout
    assert re.findall(r"--to (\d+)", p.stdout) == ["85"], p.stdout
    assert "would be flagged (0 by R_1, 141 by their level >= 2 x baseline)" in p.stdout
    p = run("cmsensord", "calibrate", str(degrading), "--to", "85", "--out", str(tmp_path / "advised.yaml"))
    assert p.returncode == 0, p.stderr
    assert "warning" not in p.stdout and "; 0 healthy decision(s) would be flagged\n" in p.stdout
    out = tmp_path / "all"
    assert run("cmsensord", "replay", str(degrading), "--config", str(tmp_path / "all.yaml"),
               "--out", str(out)).returncode == 0
    first = next(t for t, m in _severity(out) if m["severity_index"] >= 0.5)
    assert first == pytest.approx(392.0, abs=0.05)            # the decision 391-392 s, as said

    site = tmp_path / "site.yaml"
    p = run("cmsensord", "calibrate", str(degrading), "--to", "266", "--out", str(site))
    assert p.returncode == 0, p.stderr
    assert "already at" not in p.stdout
    assert "; 21 healthy decision(s) would be flagged (21 by R_1, 0 by their level >= 2 x baseline)\n" in p.stdout
    # below 2 x, the level still rises through 0-266 s (the fault's onset, at 150 s): said, with the --to before it
    assert ("ch0: warning: the level rises through the healthy period: its last quarter's median is 1.56 x its first "
            "quarter's, rising from 111.0 board s: wear or a fault starting, or a change of load; learned from, it "
            "raises the baseline and widens every margin: a period ending before it learns the machine's own level "
            "(--to 111)\n") in p.stdout
    p = run("cmsensord", "calibrate", str(degrading), "--to", "111", "--out", str(tmp_path / "before.yaml"))
    assert p.returncode == 0, p.stderr
    assert "warning" not in p.stdout
    out = tmp_path / "steady"
    assert run("cmsensord", "replay", str(degrading), "--config", str(site), "--out", str(out)).returncode == 0
    sev = _severity(out)
    assert all(m["severity_level"] == 0.0 for t, m in sev if t <= 266.5)
    assert max(m["severity_level"] for t, m in sev) >= 0.5


@pytest.fixture(scope="module")
def loud_start(tmp_path_factory):
    """An imported recording of 60 snapshots whose first six are three times as loud (a start-up)."""
    d = tmp_path_factory.mktemp("loud")
    x = np.random.default_rng(5).standard_normal((60, 5120, 1))
    x[:6] *= 3.0
    np.savez(d / "start.npz", acc=x, fs=5120.0, t_s=np.arange(60) * 600.0)
    cap = d / "start.bin"
    p = run("cmsensord", "import", str(d / "start.npz"), "--unit", "g", "--names", "pump", "--out", str(cap))
    assert p.returncode == 0, p.stderr
    return cap


def test_a_loud_start_of_the_healthy_period_is_said_with_where_the_steady_stretch_begins(loud_start, tmp_path):
    """The warning names the loud snapshots in the recording and gives the --from after them;
    from there, nothing is said."""
    p = run("cmsensord", "calibrate", str(loud_start), "--rpm", "600", "--out", str(tmp_path / "s.yaml"))
    assert p.returncode == 0, p.stderr
    assert ("pump: warning: 5 decision(s) of the healthy period are already at >= 2 x its baseline "
            "(level_alert: severity 0.5) in 1.0-6.0 board s, in the recording: start.npz[1] (1.7 % of the "
            "record, 0.1667 h in) to the end of start.npz[5] (10.0 % of the record, 0.8336 h in): a start-up or a "
            "disturbance; its steady stretch to the end begins at --from 6 (levels within 2 x its own "
            "median)\n") in p.stdout
    p = run("cmsensord", "calibrate", str(loud_start), "--rpm", "600", "--from", "6", "--out", str(tmp_path / "s.yaml"))
    assert p.returncode == 0, p.stderr
    assert "warning" not in p.stdout and "pump: highest outlier count" in p.stdout


RULES = """alarms:
  rules:
    - {name: rms_x2, indicator: accel_rms, alert_x_baseline: 2, danger_x_baseline: 4}
    - {name: iso, indicator: velocity_rms_mm_s, alert_zone: C, danger_zone: D}
"""


def test_alarms_the_healthy_period_itself_shows_are_said(loud_start, tmp_path):
    """With the base configuration's alarm rules, calibrate replays the healthy period with the
    site file it wrote and says each alarm shown there (raised in it, or standing all through it
    from before), as the replay itself then places it; quietly otherwise, and no log lines."""
    base = tmp_path / "base.yaml"
    base.write_text(RULES)
    site = tmp_path / "site.yaml"
    p = run("cmsensord", "calibrate", str(loud_start), "--rpm", "600", "--config", str(base), "--out", str(site))
    assert p.returncode == 0, p.stderr
    assert ("alarm rms_x2/pump: warning: shown within the healthy period, raised 1 time(s): alert at 1.0 board s "
            "(accel_rms 29.64 m/s² (acceleration RMS) reached the alert level 19.64 m/s²); its levels are within "
            "what this machine did then: "
            "check the rule's levels, or whether the period was healthy\n"
            "alarm rms_x2/pump: in the recording: alert at start.npz[0] (0.0 % of the record, 0 h in)\n"
            ) in p.stdout        # the first record is the first snapshot (indicators.interval_s 0.996)
    assert "ERROR" not in p.stderr and "alarm_" not in p.stderr
    p = run("cmsensord", "replay", str(loud_start), "--config", str(site), "--out", str(tmp_path / "logs"))
    assert p.returncode == 0, p.stderr
    assert "alarm rms_x2/pump: in the recording: alert at start.npz[0] (0.0 % of the record, 0 h in)" in p.stderr

    p = run("cmsensord", "calibrate", str(loud_start), "--rpm", "600", "--from", "6", "--config", str(base),
            "--out", str(site))
    assert p.returncode == 0, p.stderr
    assert "alarm rms_x2" not in p.stdout          # raised before the period, cleared in it
    assert ("alarm iso/pump: warning: shown within the healthy period: danger since 1.0 board s, before the "
            "period, and all through it (velocity_rms_mm_s 27.87 mm/s (velocity RMS, 10-1000 Hz) reached "
            "the danger level 4.5 mm/s); ") in p.stdout
    base.write_text(RULES.splitlines(keepends=True)[0] + "".join(RULES.splitlines(keepends=True)[1:3]))
    p = run("cmsensord", "calibrate", str(loud_start), "--rpm", "600", "--from", "6", "--config", str(base),
            "--out", str(site))
    assert p.returncode == 0, p.stderr
    assert "alarms: none of the 1 rule(s) shown within the healthy period (replayed with the site file)\n" in p.stdout


def _calibrate_with_rule(tmp_path, capture, start: str, more: str) -> subprocess.CompletedProcess:
    """``calibrate --from start`` of ``capture`` with one rule, accel_rms at 2 x its baseline and ``more``."""
    base = tmp_path / "base.yaml"
    base.write_text(f"alarms:\n  rules:\n    - {{name: rms_x2, indicator: accel_rms, alert_x_baseline: 2, {more}}}\n")
    p = run("cmsensord", "calibrate", str(capture), "--rpm", "600", "--from", start, "--config", str(base),
            "--out", str(tmp_path / "site.yaml"))
    assert p.returncode == 0, p.stderr
    return p


def test_alarm_delays_that_span_much_of_an_imported_recording_are_said(loud_start, tmp_path):
    """Snapshots of 1 s every 600 s laid end to end: a rule's 3-s on-delay needs 3 snapshots in
    a row, 30 minutes of the machine's life; calibrate says so as it writes the rules, as the
    replay's summary does."""
    p = _calibrate_with_rule(tmp_path, loud_start, "6", "on_delay_s: 3")
    assert ("note: alarm delays count the capture's seconds, one of which is 602 s of the recording here (its "
            "snapshots end to end): a delay of 3 s spans 1,807 s of it\n") in p.stdout, p.stdout


def test_an_alarm_of_the_record_ending_at_the_periods_start_is_not_said_to_be_shown_within_it(tmp_path):
    """--from at a snapshot's end: the alarm the snapshot before the period raises is stamped at
    the period's start; it is the snapshot's, not the healthy period's (calibrate advised to
    check the rule's levels, of a rule the healthy snapshots never come near)."""
    x = np.random.default_rng(5).standard_normal((60, 5120, 1))
    x[:6] *= 3.0
    x[5] *= 3.0                                 # the last loud snapshot, 9 x: danger there only
    np.savez(tmp_path / "start.npz", acc=x, fs=5120.0, t_s=np.arange(60) * 600.0)
    cap = tmp_path / "start.bin"
    p = run("cmsensord", "import", str(tmp_path / "start.npz"), "--unit", "g", "--names", "pump", "--out", str(cap))
    assert p.returncode == 0, p.stderr
    p = _calibrate_with_rule(tmp_path, cap, "10%", "danger_x_baseline: 6")
    assert "healthy period in the recording: start.npz[6] (10.0 % of the record" in p.stdout, p.stdout
    assert "alarms: none of the 1 rule(s) shown within the healthy period (replayed with the site file)\n" \
        in p.stdout, p.stdout


def test_a_level_rising_from_the_start_of_the_period_gives_no_too_short_period(tmp_path):
    """A level that rises from the first snapshots: no --to a handful of decisions long is
    advised (calibrate could not learn from it), the engineer is told to choose another period."""
    x = np.random.default_rng(5).standard_normal((60, 5120, 1)) * np.linspace(1.0, 2.0, 60)[:, None, None]
    np.savez(tmp_path / "ramp.npz", acc=x, fs=5120.0, t_s=np.arange(60) * 600.0)
    cap = tmp_path / "ramp.bin"
    p = run("cmsensord", "import", str(tmp_path / "ramp.npz"), "--unit", "g", "--names", "pump", "--out", str(cap))
    assert p.returncode == 0, p.stderr
    p = run("cmsensord", "calibrate", str(cap), "--rpm", "600", "--out", str(tmp_path / "site.yaml"))
    assert p.returncode == 0, p.stderr
    said = [ln for ln in p.stdout.splitlines() if "rises" in ln]
    assert len(said) == 1 and said[0].startswith("pump: warning: the level rises through the healthy period: its "
                                                 "last quarter's median is 1.67 x its first quarter's, rising from "
                                                 "4.0 board s (in the recording: ramp.npz[4] "), p.stdout
    assert said[0].endswith(": only 3 decision(s) before it: choose a steady period of this machine (--from/--to)")


def test_what_the_healthy_period_lacks_is_said(degrading, tmp_path):
    """A --to past the end, blocks missing in the period, and a period of a few decisions are
    each one line; the site file is still written."""
    site = tmp_path / "s.yaml"
    p = run("cmsensord", "calibrate", str(degrading), "--from", "550", "--to", "700", "--out", str(site))
    assert p.returncode == 0, p.stderr
    assert "note: --to 700 is past the capture's end (600.0 board s): the healthy period ends there\n" in p.stdout
    assert "missing" not in p.stdout
    holed = tmp_path / "holed.bin"
    data = degrading.read_bytes()
    holed.write_bytes(data[:len(data) // 10] + data[len(data) // 10 + 20000:])   # 20 kB out of the first minute
    p = run("cmsensord", "calibrate", str(holed), "--to", "120", "--out", str(site))
    assert p.returncode == 0, p.stderr
    assert re.search(r"note: the healthy period misses \d+\.\d s of its 120\.0 s \(blocks the board lost, or "
                     r"the import left out\): learned from the rest\n", p.stdout), p.stdout
    p = run("cmsensord", "calibrate", str(degrading), "--to", "5", "--out", str(site))
    assert p.returncode == 0, p.stderr
    assert ("ch0: warning: learned from 4 decision(s) only: the healthy fluctuation of so few is a guess; a longer "
            "healthy period (an hour of normal running) learns it better\n") in p.stdout
    assert site.exists()


def test_the_papers_severity_has_no_level_check(degrading, tmp_path):
    """With monitor.severity: paper the level is not graded, so calibrate does not check it."""
    base = tmp_path / "base.yaml"
    base.write_text("monitor:\n  severity: paper\n")
    p = run("cmsensord", "calibrate", str(degrading), "--config", str(base), "--out", str(tmp_path / "s.yaml"))
    assert p.returncode == 0, p.stderr
    assert "already at" not in p.stdout and "by their level" not in p.stdout


def test_calibrate_shows_its_progress_on_a_terminal_and_nothing_else_without_one(degrading, tmp_path):
    """Both replays (the healthy period, then its alarms with the site file) draw a bar on a
    terminal; a pipe gets the table and no bar."""
    base = tmp_path / "base.yaml"
    base.write_text("alarms:\n  rules:\n    - {name: sev, indicator: severity_index, alert: 0.5}\n")
    args = ["calibrate", str(degrading), "--to", "150", "--config", str(base), "--out", str(tmp_path / "s.yaml")]
    status, seen = on_terminal([sys.executable, "-m", "cmsensord", *args])
    assert status == 0, seen
    assert b"\rcalibrate degrading.bin: the healthy period [" in seen and b"s of 150 s" in seen
    assert b"\rcalibrate degrading.bin: its alarms [" in seen
    p = run("cmsensord", *args)
    assert p.returncode == 0 and "\r" not in p.stderr + p.stdout and "[#" not in p.stderr


def test_a_machine_that_stops_for_most_of_the_healthy_period_is_learned_from_its_running_time(tmp_path):
    """A pump that runs 10 s, stops 30 s, ... over 120 s: without leaving the stops out, the
    stopped level was the baseline and the replay of its own healthy period a FAILURE at every
    run; now the baseline is the running level and the whole record stays at 0."""
    rng = np.random.default_rng(1)
    t = np.arange(200 * 5120) / 5120
    x = np.sin(2 * np.pi * 25 * t) * 2 + rng.standard_normal(t.size)
    for a, b in ((10, 40), (50, 80), (90, 110)):
        x[(t >= a) & (t < b)] *= 0.01
    np.save(tmp_path / "pump.npy", x.astype(np.float32))
    p = run("cmsensord", "import", str(tmp_path / "pump.npy"), "--fs", "5120", "--block-len", "64", "--unit", "g",
            "--names", "pump", "--out", str(tmp_path / "pump.bin"))
    assert p.returncode == 0, p.stderr
    p = run("cmsensord", "calibrate", str(tmp_path / "pump.bin"), "--to", "120", "--rpm", "1500",
            "--out", str(tmp_path / "site.yaml"))
    assert p.returncode == 0, p.stderr
    assert ("pump: 86 decision(s) with the machine stopped (level below 10 % of its running level), starting or "
            "stopping: not learned from\n") in p.stdout
    assert "warning" not in p.stdout
    base = yaml.safe_load((tmp_path / "site.yaml").read_text())["channels"][0]["baseline"]
    assert base == pytest.approx(np.sqrt(2 ** 2 / 2 + 1) * 9.80665, rel=0.05)    # the running RMS, in m/s2
    p = run("cmsensord", "replay", str(tmp_path / "pump.bin"), "--config", str(tmp_path / "site.yaml"),
            "--out", str(tmp_path / "logs"))
    assert p.returncode == 0, p.stderr
    assert max(m["severity_index"] for _, m in _severity(tmp_path / "logs", "pump")) == 0.0
    (tmp_path / "base.yaml").write_text("alarms:\n  rules:\n    - {name: rms_x2, indicator: accel_rms, "
                                        "alert_x_baseline: 2}\n")
    p = run("cmsensord", "calibrate", str(tmp_path / "pump.bin"), "--to", "120", "--rpm", "1500", "--config",
            str(tmp_path / "base.yaml"), "--out", str(tmp_path / "alarms.yaml"))
    assert p.returncode == 0, p.stderr
    learned = yaml.safe_load((tmp_path / "alarms.yaml").read_text())["alarms"]["baselines"]
    rms = next(b["value"] for b in learned if b["indicator"] == "accel_rms")
    assert rms == pytest.approx(np.sqrt(2 ** 2 / 2 + 1) * 9.80665, rel=0.05)      # the indicators' too
    assert "alarm rms_x2" not in p.stdout


def test_a_machine_too_fast_for_one_second_decisions_calibrates_with_the_decision_the_error_gives(degrading, tmp_path):
    """6000 rpm (100 Hz) against 100 observations a decision: the error's advice, a 2-s decision,
    calibrates, and the site file keeps it."""
    base = tmp_path / "base.yaml"
    base.write_text("monitor: {decision_period_s: 2}\n")
    p = run("cmsensord", "calibrate", str(degrading), "--rpm", "6000", "--to", "150", "--config", str(base),
            "--out", str(tmp_path / "s.yaml"))
    assert p.returncode == 0, p.stderr
    assert yaml.safe_load((tmp_path / "s.yaml").read_text())["monitor"]["decision_period_s"] == 2
    assert "ch0          100.000 --rpm" in p.stdout


def test_with_several_channels_warned_of_one_bound_keeps_each_ones_steady_stretch(tmp_path):
    """Two bearings whose level triples from snapshot 48 and 52 of 60: each channel's --to, then
    the one that keeps both steady, and no other --to (the rise each shows is its step);
    calibrated to it, nothing is said."""
    x = np.random.default_rng(3).standard_normal((60, 5120, 2))
    x[48:, :, 0] *= 3.0
    x[52:, :, 1] *= 3.0
    np.savez(tmp_path / "two.npz", acc=x, fs=5120.0, t_s=np.arange(60) * 600.0)
    cap = tmp_path / "two.bin"
    p = run("cmsensord", "import", str(tmp_path / "two.npz"), "--unit", "g", "--names", "de,fe", "--block-len", "64",
            "--out", str(cap))
    assert p.returncode == 0, p.stderr
    p = run("cmsensord", "calibrate", str(cap), "--rpm", "600", "--out", str(tmp_path / "s.yaml"))
    assert p.returncode == 0, p.stderr
    assert "its steady stretch from the start ends at --to 48 (" in p.stdout
    assert "its steady stretch from the start ends at --to 52 (" in p.stdout
    assert "\nevery channel's steady stretch: --to 48\n" in p.stdout
    # the rise the whole period shows is the step: the steady stretch holds none, its --to is the one given
    assert ("de: warning: the level rises through the healthy period: its last quarter's median is 2.99 x its first "
            "quarter's, rising from 41.0 board s (in the recording: two.npz[41] (68.3 % of the record, 6.833 h in)): "
            "wear or a fault starting, or a change of load; learned from, it raises the baseline and widens every "
            "margin: the --to of the warning above leaves it out\n") in p.stdout
    assert re.findall(r"--to (\d+)", p.stdout) == ["48", "52", "48"], p.stdout
    p = run("cmsensord", "calibrate", str(cap), "--rpm", "600", "--to", "48", "--out", str(tmp_path / "s.yaml"))
    assert p.returncode == 0, p.stderr
    assert "warning" not in p.stdout and "every channel" not in p.stdout


def test_a_channel_with_no_sensor_is_said_at_import_and_calibrate_names_the_way_out(tmp_path):
    """A logger's spare column of zeros: the import warns; calibrate refuses it with the two ways
    to leave it out, and a base configuration listing the channels to learn calibrates."""
    rng = np.random.default_rng(2)
    x = rng.normal(0.0, 0.2, (3000, 3))
    x[:, 1] = 0.0
    (tmp_path / "d.csv").write_text("Acc X (g),Spare (g),Acc Y (g)\n" + "".join(f"{a:.4f},{b:.4f},{c:.4f}\n"
                                                                          for a, b, c in x))
    cap = tmp_path / "d.bin"
    p = run("cmsensord", "import", str(tmp_path / "d.csv"), "--fs", "1000", "--block-len", "10", "--out", str(cap))
    assert p.returncode == 0, p.stderr
    assert ("  WARNING Spare_g: every value is 0 (no sensor on it?): calibrate cannot learn it; leave it out "
            "with --channels\n") in p.stderr
    assert "WARNING Acc" not in p.stderr
    site = tmp_path / "s.yaml"
    p = run("cmsensord", "calibrate", str(cap), "--out", str(site))
    assert (p.returncode, p.stderr.strip()) == (2, (
        "cmsensord: calibrate: channel Spare_g: the healthy period's block RMS is zero: no signal on this channel "
        "(no sensor on it?): leave it out (import --channels, or a --config BASE.yaml listing the channels to "
        "learn)"))
    base = tmp_path / "base.yaml"
    base.write_text("channels:\n  - {name: Acc_X_g, index: 0}\n  - {name: Acc_Y_g, index: 2}\n")
    p = run("cmsensord", "calibrate", str(cap), "--config", str(base), "--out", str(site))
    assert p.returncode == 0, p.stderr
    assert [ch["name"] for ch in yaml.safe_load(site.read_text())["channels"]] == ["Acc_X_g", "Acc_Y_g"]


def test_the_healthy_periods_end_is_placed_where_it_ends_in_the_recording(tmp_path):
    """A period that runs to a snapshot's last sample ends at the end of it, at its end's share of
    the record and time (it named the last snapshot at its start: `to snaps.npz[11] (91.7 % of the
    record, ...)` for the whole record); one cut inside a snapshot, where the cut is; a plain
    capture has no snapshots to place it in."""
    x = np.random.default_rng(5).standard_normal((12, 5120, 1))
    np.savez(tmp_path / "snaps.npz", acc=x, fs=5120.0, t_s=np.arange(12) * 600.0)
    cap = tmp_path / "snaps.bin"
    p = run("cmsensord", "import", str(tmp_path / "snaps.npz"), "--unit", "g", "--names", "pump", "--out", str(cap))
    assert p.returncode == 0, p.stderr
    said = {}
    for window in ((), ("--to", "50%"), ("--from", "2.5", "--to", "7.5")):
        p = run("cmsensord", "calibrate", str(cap), "--rpm", "600", *window, "--out", str(tmp_path / "site.yaml"))
        assert p.returncode == 0, p.stderr
        said[window] = [line for line in p.stdout.splitlines() if line.startswith("healthy period in")]
    start = "healthy period in the recording: snaps.npz[0] (0.0 % of the record, 0 h in) to "
    assert said[()] == [start + "the end of snaps.npz[11] (100.0 % of the record, 1.834 h in)"]  # 11 x 600 s + 0.996
    assert said[("--to", "50%")] == [start + "the end of snaps.npz[5] (50.0 % of the record, 0.8336 h in)"]
    assert said[("--from", "2.5", "--to", "7.5")] == [
        "healthy period in the recording: snaps.npz[2] (20.8 % of the record, 0.3335 h in) to snaps.npz[7] "
        "(62.7 % of the record, 1.167 h in)"]
    plain = tmp_path / "plain.bin"
    assert run("firmware_sim", "--scenario", "healthy", "--duration", "5", "--out",
               str(plain)).returncode == 0
    p = run("cmsensord", "calibrate", str(plain), "--out", str(tmp_path / "plain.yaml"))
    assert p.returncode == 0, p.stderr
    assert p.stdout.splitlines()[0] == "healthy period: 0.0-5.0 board s, 100 blocks/s"
    assert "in the recording" not in p.stdout
