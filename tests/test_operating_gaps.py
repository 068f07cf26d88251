"""Frames lost for less than ``tacho.timeout_s`` (a UART dropping bytes) are no coast-down.

The record spanning such a gap carries the tacho's speed extrapolated over it, up to 10 % off
either way (a high one raises the running value the coast-down is measured from, a low one
then falls below it: 1582 rpm of 1720); the operating state took it as a coast-down and cleared
a danger alarm whose value stood at 7.9 mm/s, near twice the danger level.  A record with
lost samples gives the operating state no reading (it keeps its state), as a record without a
speed does.
"""

from __future__ import annotations

from processes import cmsensord, run_module

CONFIG = """\
alarms:
  operating:
    source: speed
    running_above: 300
    stopped_below: 200
    coastdown_suppress_s: 30
  rules:
    - name: velocity
      indicator: velocity_rms_mm_s
      alert_zone: C
      danger_zone: D
"""


def test_frames_lost_shorter_than_the_tacho_timeout_keep_the_machine_running(tmp_path):
    whole = tmp_path / "f.bin"
    p = run_module("firmware_sim", "--scenario", "faulty", "--mode", "raw", "--tacho", "--duration", "40",
                   "--out", str(whole))
    assert p.returncode == 0, p.stderr
    data = whole.read_bytes()
    cut = bytearray()
    pos = 0
    for k in range(1, 8):                   # 7 gaps of ~0.28 s (15,000 bytes), under the 0.5-s timeout
        at = len(data) * k // 8
        cut += data[pos:at]
        pos = at + 15000
    cut += data[pos:]
    (tmp_path / "gaps.bin").write_bytes(bytes(cut))
    (tmp_path / "op.yaml").write_text(CONFIG)
    p = cmsensord("replay", "gaps.bin", "--config", "op.yaml", "--out", "o", "-v", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    lines = p.stderr.splitlines()
    assert sum(ln.startswith("WARNING frames_lost: ") for ln in lines) == 7, p.stderr
    assert [ln for ln in lines if ln.startswith(("INFO operating_state", "ERROR alarm_", "WARNING alarm_"))] == [
        "INFO operating_state: operating state stopped -> running (speed 1720 rpm)",
        "ERROR alarm_danger: velocity/ch0: velocity_rms_mm_s 7.891 mm/s (velocity RMS, 10-1000 Hz) reached the "
        "danger level 4.5 mm/s",
    ]
