"""A decision period that lacks most of a channel's observations is not judged: a failing
channel whose frames are lost for 5 s (a seq and t0 gap, as when a self-powered board's USB is
pulled) keeps its severity and failure through the gap, its severity messages say
``no_data``, and no ``failure_clear`` comes of the gap (guards against each empty second read
as healthy: severity 1.00 -> 0.00 and a failure_clear, then FAILURE again after it).
A failure raised by the level says so when it clears. Through ``cmsensord replay`` of the
board's capture with the frames cut out."""

from __future__ import annotations

from pathlib import Path

import pytest

from cmsensord.protocol import OVERHEAD, iter_frames
from cmsensord.sinks.mcap_read import read_messages
from processes import cmsensord, run_module

FS = 25000
GAP = (85.0, 90.0)        # s of board time whose frames are lost


@pytest.fixture(scope="module")
def gapped(tmp_path_factory) -> Path:
    """A degrading 2-channel board's 120 s, its frames of GAP cut out."""
    d = tmp_path_factory.mktemp("gap")
    assert run_module("firmware_sim", "--scenario", "degrading", "--channels", "2", "--duration", "120",
                      "--out", str(d / "deg.bin")).returncode == 0
    data = (d / "deg.bin").read_bytes()
    frames, _ = iter_frames(data)
    keep = [data[f.offset:f.offset + OVERHEAD + len(f.payload)] for f in frames
            if not GAP[0] * FS <= f.t0_unwrapped < GAP[1] * FS]
    assert len(keep) < len(frames)
    (d / "gap.bin").write_bytes(b"".join(keep))
    return d / "gap.bin"


def test_a_failing_channel_keeps_its_severity_through_seconds_without_data(gapped, tmp_path):
    (tmp_path / "c.yaml").write_text("monitor:\n  baseline: 0.7\n")
    r = cmsensord("replay", str(gapped), "--config", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "o"))
    assert r.returncode == 0, r.stderr
    (log,) = (tmp_path / "o").glob("*.mcap")
    msgs = list(read_messages(log))
    sev = [m for t, _, m in msgs if t == "/cm/ch1/severity"]
    t0 = sev[0]["timestamp"]["sec"] + sev[0]["timestamp"]["nsec"] / 1e9 - 1.0   # the first decision: 1 s in
    at = {round(m["timestamp"]["sec"] + m["timestamp"]["nsec"] / 1e9 - t0): m for m in sev}
    before = at[int(GAP[0])]
    assert before["severity_index"] == 1.0 and before["failure"], before
    empty = [at[s] for s in range(int(GAP[0]) + 1, int(GAP[1]) + 1)]
    assert all(m["missing"] == 100 and m.get("no_data") for m in empty), empty
    assert all(m["severity_index"] == 1.0 and m["failure"] for m in empty), empty
    clears = [m for t, _, m in msgs if t == "/cm/events" and m["kind"] == "failure_clear" and m["channel"] == "ch1"
              and GAP[0] < m["timestamp"]["sec"] + m["timestamp"]["nsec"] / 1e9 - t0 <= GAP[1] + 1]
    assert clears == [], clears


def test_a_failure_by_level_clears_by_level(gapped, tmp_path):
    """A failure raised by the level (``level 4.02 x baseline >= level_danger``) says, when it
    clears, that the level fell (it said ``AKF_10 back below c*f_r``, a flag never set)."""
    (tmp_path / "c.yaml").write_text("monitor:\n  baseline: 0.7\n")
    r = cmsensord("replay", str(gapped), "--config", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "o"))
    assert r.returncode == 0, r.stderr
    (log,) = (tmp_path / "o").glob("*.mcap")
    ev = [m["message"] for t, _, m in read_messages(log) if t == "/cm/events" and m.get("channel") == "ch1"
          and m["kind"] in ("failure", "failure_clear")]
    by_level = [i for i, msg in enumerate(ev) if "FAILURE: level" in msg]
    assert by_level and by_level[0] + 1 < len(ev), ev
    assert ev[by_level[0] + 1].startswith("ch1: failure condition cleared (level "), ev
    assert ev[by_level[0] + 1].endswith(" x baseline below level_danger)"), ev
