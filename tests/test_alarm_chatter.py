"""A rule without delays on a value hovering at its level changes state every few seconds (a
chattering alarm): every transition is in /cm/events, while the journal writes at most 10 of
each kind per alarm in 600 s and then one summary that says so and names the remedy (it wrote
43 lines in 2 minutes: 30,000 a day)."""

from __future__ import annotations

import subprocess
import sys

from cmsensord.sinks.mcap_sink import read_messages


def test_a_chattering_alarm_is_limited_in_the_journal_and_whole_in_the_log(tmp_path):
    cap = tmp_path / "f.bin"
    subprocess.run([sys.executable, "-m", "firmware_sim", "--scenario", "faulty", "--duration", "300",
                    "--out", str(cap)], check=True, capture_output=True)
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("alarms:\n  rules:\n    - {name: rms, indicator: accel_rms, alert: 3.1, danger: 6.0}\n")
    p = subprocess.run([sys.executable, "-m", "cmsensord", "replay", str(cap), "--config", str(cfg),
                        "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    logged = [m for t, _, m in read_messages(next((tmp_path / "out").glob("*.mcap")))
              if t == "/cm/events" and m["kind"] == "alarm_alert"]
    assert len(logged) > 20                                   # it chatters: all of them in the log
    journal = [ln for ln in p.stderr.splitlines() if ln.startswith("WARNING alarm_alert: ")]
    assert len(journal) == 11, p.stderr
    assert journal[-1] == (f"WARNING alarm_alert: rms/ch0: {len(logged) - 10} more alarm_alert event(s) in "
                           f"{journal[-1].split(' in ')[1].split(':')[0]}: at most 10 per 600 s are written one "
                           "by one in the journal, all in /cm/events; an alarm that changes this often chatters: "
                           "an on_delay_s or off_delay_s on its rule steadies it"), journal[-1]
    assert f"alarm_alert {len(logged)}," in p.stderr         # the summary's counts: every one
