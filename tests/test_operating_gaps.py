"""Frames lost for less than ``tacho.timeout_s`` (a UART dropping bytes) are no coast-down.

The record spanning such a gap carried a speed up to 10 % off either way (a high one raised the
running value the coast-down is measured from, a low one then fell below it: 1582 rpm of 1720);
the operating state took it as a coast-down and cleared a danger alarm whose value stood at
7.9 mm/s, near twice the danger level.  The tacho counts the pulses of the lost frames when the
speed on both sides says how many, else starts again after the gap (cmsensord/dsp/tacho/gaps.py),
so such a record carries the speed of the samples it holds, and the operating state reads it as
it reads any record's: on a link that loses a frame in every record it still sees the machine
start.
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


def test_a_link_losing_frames_in_every_record_still_shows_the_machine_start(tmp_path):
    """close_orders (0 -> 3000 rpm in 5 s) with 1000 bytes lost every 25,000 (~20 ms every 0.46 s):
    every record has lost samples.  Their speeds are the machine's (tests/test_tacho_gaps.py), and
    the operating state reads them: it stayed stopped when a record with lost samples gave it no
    speed."""
    whole = tmp_path / "c.bin"
    p = run_module("firmware_sim", "--scenario", "close_orders", "--mode", "raw", "--tacho", "--out", str(whole))
    assert p.returncode == 0, p.stderr
    data = whole.read_bytes()
    cut, pos = bytearray(), 0
    for at in range(20000, len(data), 25000):
        cut += data[pos:at]
        pos = at + 1000
    cut += data[pos:]
    (tmp_path / "lossy.bin").write_bytes(bytes(cut))
    (tmp_path / "op.yaml").write_text(CONFIG)
    p = cmsensord("replay", "lossy.bin", "--config", "op.yaml", "--out", "o", "-v", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    lines = p.stderr.splitlines()
    assert sum(ln.startswith("WARNING frames_lost: ") for ln in lines) == 10, p.stderr
    assert [ln for ln in lines if ln.startswith("INFO operating_state")] == [
        "INFO operating_state: operating state stopped -> running (speed 889 rpm)"], p.stderr


def _without_raw_frames(data: bytes, every_blocks: int) -> bytes:
    """``data`` (a capture of one channel, block 250) less the RAW frame of every
    ``every_blocks``-th block, from block 7 on: a link that loses a frame now and then, for good."""
    out = bytearray()
    pos = 0
    while pos < len(data):
        n = int.from_bytes(data[pos + 12:pos + 14], "little")
        block = int.from_bytes(data[pos + 6:pos + 10], "little") // 250
        if not (data[pos + 3] == 3 and block % every_blocks == 7):     # type 3: RAW
            out += data[pos:pos + 18 + n]
        pos += 18 + n
    return bytes(out)


def test_a_link_losing_a_frame_in_every_record_for_good_still_reads_the_machine_running(tmp_path):
    # one RAW frame of 500 lost (a 10-ms block, a third of a turn at 1720 rpm) in every record (its
    # 2.6 s, the longest interval of RAW records): the tacho's speed is as without the gap; a state
    # that took no speed from such records never saw the machine start, and no alarm was evaluated
    # for as long as the link lost frames
    whole = tmp_path / "f.bin"
    p = run_module("firmware_sim", "--scenario", "faulty", "--mode", "raw", "--tacho", "--duration", "16",
                   "--out", str(whole))
    assert p.returncode == 0, p.stderr
    (tmp_path / "lossy.bin").write_bytes(_without_raw_frames(whole.read_bytes(), 250))
    # a record with lost samples has its waveform statistics (accel_rms), not the spectral ones
    config = CONFIG.replace("name: velocity", "name: accel").replace(
        "indicator: velocity_rms_mm_s\n      alert_zone: C\n      danger_zone: D",
        "indicator: accel_rms\n      alert: 1.5\n      danger: 3")
    (tmp_path / "op.yaml").write_text(config + "indicators:\n  interval_s: 2.62144\n")
    p = cmsensord("replay", "lossy.bin", "--config", "op.yaml", "--out", "o", "-v", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    lines = p.stderr.splitlines()
    assert sum(ln.startswith("WARNING frames_lost: ") for ln in lines) == 7, p.stderr
    assert [ln for ln in lines if ln.startswith(("INFO operating_state", "ERROR alarm_", "WARNING alarm_"))] == [
        "INFO operating_state: operating state stopped -> running (speed 1720 rpm)",
        "ERROR alarm_danger: accel/ch0: accel_rms 3.177 m/s² (acceleration RMS) reached the danger level 3 m/s²",
    ]
