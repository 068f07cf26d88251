"""While the board is gone, what the daemon says about itself is stamped when it says it: the
diagnostics written every 5 s without decisions, the link's events and ``stop`` carry the wall
clock on the stream's time base, not the end of the newest observation."""

from __future__ import annotations

import time

from cmsensord.sinks.mcap_read import read_messages
from processes import start_board, start_daemon, stop

S = 1_000_000_000


def test_diagnostics_and_stop_during_an_outage_carry_the_time_they_were_written(tmp_path):
    """The board (real time, RMS) runs 4 s, then its process is killed; the daemon runs on 12 s
    without it, then gets SIGTERM: the outage's diagnostics and ``stop`` carry the time they were
    written, not the newest observation's stamp (+4 s instead of +16 s)."""
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "healthy", "--speed", "1", "--duration", "600", "--link", str(link),
                      "--flow-control")
    d = start_daemon(tmp_path, link, max_drift_s=2.0)
    try:
        time.sleep(4.0)
        gone = time.time_ns()
        sim.terminate()
        sim.wait(timeout=5)
        time.sleep(12.0)
        term = time.time_ns()
        err = stop(d)
        done = time.time_ns()
    finally:
        sim.kill()
        sim.wait()
    assert d.returncode == 0 and "Traceback" not in err, err
    msgs = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    events = {m["kind"]: t for topic, t, m in msgs if topic == "/cm/events"}
    start = events["start"]
    assert gone <= events["link_lost"] <= gone + 2 * S
    assert term <= events["stop"] <= done
    gone_s = (gone - start) / S
    outage = [(t, m["uptime_s"]) for topic, t, m in msgs if topic == "/cm/diagnostics" and m["uptime_s"] > gone_s + 1]
    assert len(outage) == 2, outage               # 5 s apart, after the last decision's
    for t, uptime in outage:                      # each at its own time (uptime: the monotonic clock's)
        assert abs((t - start) / S - uptime) < 0.05, (t - start, uptime)
    assert outage[1][0] - outage[0][0] > 4.9 * S
    diag = [t for topic, t, _ in msgs if topic == "/cm/diagnostics"]
    assert diag == sorted(diag)
