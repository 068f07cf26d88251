"""`cmsensord status` of a running daemon: the alarm table gives the unit of each alarm's value
and levels, and the status line says how many other alarms show a level, in words."""

from __future__ import annotations

import json
import re
import time

from cmsensord.service.control import SOCKET_NAME
from processes import board_on_pty, run_module, start_daemon, stop

RULES = """\
alarms:
  rules:
    - {name: de_velocity, indicator: velocity_rms_mm_s, alert: 2.8, danger: 40, latch: true}
    - {name: de_kurtosis, indicator: kurtosis, alert: 10, latch: true}
"""


def test_status_gives_units_and_names_the_other_alarms(tmp_path):
    cfg = tmp_path / "cmsensord.yaml"
    with board_on_pty("--scenario", "degrading", "--mode", "raw", "--tacho", "--duration", "24",
                      "--speed", "4") as port:
        d = start_daemon(tmp_path, port, config=RULES)
        try:
            deadline = time.monotonic() + 60
            rows: list = []
            while time.monotonic() < deadline:
                time.sleep(1.0)
                if (tmp_path / "logs" / SOCKET_NAME).exists():
                    p = run_module("cmsensord", "status", "--config", str(cfg), "--json")
                    rows = json.loads(p.stdout).get("alarms", []) if p.returncode == 0 else []
                    if len(rows) == 2 and all(r["latched"] for r in rows):
                        break
            assert [r["level"] for r in rows] == ["alert", "alert"], rows
            text = run_module("cmsensord", "status", "--config", str(cfg)).stdout.splitlines()
        finally:
            stop(d)
    assert " ALARM alert de_velocity/ch0 and 1 more at alert or danger | rx " in text[0], text[0]
    assert text[1] == "operating state: running, worst: alert (de_velocity/ch0), speed 1720 rpm"
    assert text[2] == ("ALARM                    LEVEL   LIVE         VALUE    ALERT   DANGER UNIT   FLAGS")
    assert re.fullmatch(r"de_velocity/ch0          alert   \w+ +[0-9.]+      2\.8       40 mm/s   latched",
                        text[3]), text[3]
    assert re.fullmatch(r"de_kurtosis/ch0          alert   \w+ +[0-9.]+       10        - -      latched",
                        text[4]), text[4]
