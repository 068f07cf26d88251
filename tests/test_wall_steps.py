"""The daemon live on a simulated board whose system clock steps (an NTP sync after a boot with
a stale clock, a board without an RTC battery): one ``time_base`` event re-anchors the stamps
to the new wall clock, forward or back, and the board-rate drift check stays quiet (guards
against a forward step measured as a board at 4 Hz, then ``board clock ahead of the wall clock``
every ~5 s for days, and a step back giving no event and stamps an hour ahead)."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from cmsensord.sinks.log_names import log_files
from cmsensord.sinks.mcap_read import read_messages
from processes import ROOT, spawn, start_board, stop

pytestmark = pytest.mark.process


def live_with_step(tmp_path, step_s: float, *, at_s: float = 3.0, run_s: float = 7.0,
                   more: str = "") -> tuple[str, list[list[tuple[str, int, dict]]]]:
    """The daemon (link.max_drift_s 2 s; ``more``: YAML) on a simulated board for ``run_s``, its
    wall clock stepped by ``step_s`` ``at_s`` in: (its stderr, the messages of each log file, in
    the order opened)."""
    sim = start_board("--scenario", "healthy", "--link", str(tmp_path / "tty"))
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"link:\n  port: {tmp_path / 'tty'}\n  max_drift_s: 2.0\n"
                   f"output:\n  dir: {tmp_path / 'logs'}\n  status_line: false\n{more}")
    d = spawn([sys.executable, str(ROOT / "tests" / "wall_step.py"), str(at_s), str(step_s), "--config", str(cfg)],
              stderr=subprocess.PIPE, text=True)
    try:
        time.sleep(run_s)
        err = stop(d)
    finally:
        sim.terminate()
        sim.wait(timeout=5)
    assert d.returncode == 0, err
    finished, _ = log_files(tmp_path / "logs", "cmsensord")
    return err, [read_messages(p) for p in finished]


def time_base(err: str, files) -> tuple[list[str], list[tuple[int, dict]]]:
    """The time_base lines of ``err`` and the time_base events of the logs (stamp, message)."""
    lines = [line for line in err.splitlines() if "time_base:" in line]
    return lines, [(s, m) for msgs in files for t, s, m in msgs if t == "/cm/events" and m["kind"] == "time_base"]


def severity_stamps(msgs) -> list[int]:
    return [s for t, s, _ in msgs if t.endswith("/severity")]


def test_a_forward_step_of_the_system_clock_re_anchors_the_stamps_once(tmp_path):
    err, files = live_with_step(tmp_path, 86400)
    lines, evs = time_base(err, files)
    assert lines == ["WARNING time_base: the system clock stepped +86400.0 s (NTP?); re-anchored: time "
                     "segment 1 stamped from the new wall clock"], lines
    [(stamp, ev)] = evs
    assert ev["details"] == {"segment": 1, "reason": "wall_step", "step_s": pytest.approx(86400, abs=0.5)}
    [msgs] = files
    stamps = severity_stamps(msgs)
    before, after = [s for s in stamps if s < stamp], [s for s in stamps if s >= stamp]
    assert len(before) >= 1 and len(after) >= 2, stamps
    assert 86395 < (after[0] - before[-1]) / 1e9 < 86405                   # the step, once
    assert abs(after[-1] / 1e9 - time.time() - 86400) < 5                  # on the new wall clock
    assert all(0.5e9 < b - a < 1.5e9 for a, b in zip(after, after[1:]))   # at the board's rate


def test_a_backward_step_of_the_system_clock_re_anchors_the_stamps_in_a_new_file(tmp_path):
    err, files = live_with_step(tmp_path, -3600)
    lines, evs = time_base(err, files)
    assert lines == ["WARNING time_base: the system clock stepped -3600.0 s (NTP?); re-anchored: time "
                     "segment 1 stamped from the new wall clock"], lines
    [(stamp, ev)] = evs
    assert ev["details"]["reason"] == "wall_step"
    assert len(files) == 2, [len(m) for m in files]                 # each file in time order
    old, new = (severity_stamps(m) for m in files)
    assert old and len(new) >= 2 and min(new) >= stamp > max(old) - 3602e9
    assert 3595 < (old[-1] - new[0]) / 1e9 < 3605 and new == sorted(new)
    assert abs(new[-1] / 1e9 - time.time() + 3600) < 5              # on the new wall clock


@pytest.mark.parametrize("step_s", [-3600, 86400])
def test_a_rule_s_delay_runs_the_stream_s_time_across_a_step(tmp_path, step_s):
    """A rule's on-delay straddling a step counts the stream's own 3 s, each file's indicator
    records in time order on their time base (guards against a step back giving every record after
    it the stamp of the last one before it, and the alert never coming)."""
    err, files = live_with_step(tmp_path, step_s, at_s=4.0, run_s=10.0, more=(
        "alarms:\n  rules:\n    - {name: acc, indicator: accel_rms, alert: 0.1, on_delay_s: 3}\n"))
    assert len(files) == (2 if step_s < 0 else 1), [len(m) for m in files]   # a step back: a new file
    assert all(m["accel_rms"] > 0.2 for msgs in files for t, _, m in msgs if t == "/cm/ch0/indicators")
    records = [s for msgs in files for t, s, _ in msgs if t == "/cm/ch0/indicators"]
    [at] = [i for i in range(1, len(records)) if abs(records[i] - records[i - 1]) > 1.5e9]   # the step, once
    old, new = records[:at], records[at:]
    assert old == sorted(set(old)) and all(0.9e9 < b - a < 1.1e9 for a, b in zip(new, new[1:])), records
    assert old and len(new) >= 4 and abs((new[0] - old[-1]) / 1e9 - step_s) < 5, records
    if step_s < 0:                                                  # each file in time order
        assert [s for t, s, _ in files[0] if t == "/cm/ch0/indicators"] == old
    shift = new[0] - old[-1] - 1_000_000_000                        # the next interval of the stream
    stream = old + [s - shift for s in new]
    due = next(i for i, s in enumerate(stream) if s >= stream[0] + 3_000_000_000)
    alerts = [s for msgs in files for t, s, m in msgs if t == "/cm/events" and m["kind"] == "alarm_alert"]
    assert due >= len(old) and alerts == [records[due]], (alerts, records, err)   # 3 s after the first
    assert [m["worst"] for t, _, m in files[-1] if t == "/cm/alarms"][-1] == "alert"


def test_a_step_back_while_the_board_is_gone_keeps_the_outage_in_the_log(tmp_path):
    """The board gone 4 s in, the system clock stepped back an hour 8 s in, the daemon killed
    (SIGKILL: a power cut) 20 s in, its log salvaged: the step is one time_base event at once,
    ``link_lost`` is in the log (written with the file the step finished), and the outage's
    diagnostics after the step are each at its own time on the new wall clock, 5 s apart.
    Guards against the step going unnoticed until the board came back, the outage's events
    held back meanwhile (lost to the kill), and every diagnostics of the outage one stamp."""
    from cmsensord.sinks.mcap_salvage import salvage_leftovers

    link = tmp_path / "tty"
    sim = start_board("--scenario", "healthy", "--link", str(link))
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"link:\n  port: {link}\n  max_drift_s: 2.0\noutput:\n  dir: {tmp_path / 'logs'}\n"
                   "  status_line: false\n")
    d = spawn([sys.executable, str(ROOT / "tests" / "wall_step.py"), "8", "-3600", "--config", str(cfg)],
              stderr=subprocess.PIPE, text=True)
    try:
        time.sleep(4.0)
        sim.terminate()
        sim.wait(timeout=5)
        time.sleep(16.0)
        d.kill()
        err = d.communicate(timeout=10)[1]
    finally:
        sim.kill()
        sim.wait()
    assert "WARNING time_base: the system clock stepped -3600.0 s (NTP?); re-anchored: time segment 1 " \
           "stamped from the new wall clock" in err.splitlines(), err
    salvage_leftovers(tmp_path / "logs", "cmsensord")
    msgs = [m for p in sorted((tmp_path / "logs").glob("*.mcap")) for m in read_messages(p, lenient=True)]
    events = {m["kind"]: s for t, s, m in msgs if t == "/cm/events"}
    assert {"start", "config", "link_lost", "time_base"} <= set(events), events
    after = [s for t, s, _ in msgs if t == "/cm/diagnostics" and events["time_base"] <= s < events["start"]]
    assert len(after) >= 2 and all(4.5e9 < b - a < 5.5e9 for a, b in zip(after, after[1:])), after
    assert abs(after[-1] / 1e9 - time.time() + 3600) < 7                # on the new wall clock
