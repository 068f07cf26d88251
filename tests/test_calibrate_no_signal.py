"""Which decisions with no signal make `cmsensord calibrate` refuse a channel: only those whose
samples were flat (a dead sensor, monitor.flat_signal) and that lie in the healthy window. A
level under monitor.signal_floor of a BASE config's baseline is a machine that may have
stopped: its decisions are not learned from, as without a baseline; a flat stretch ending
where the window begins is outside it; fewer flat blocks than that are left out of what it
learns."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from cmsensord.protocol import COUNT_MAX
from processes import cmsensord
from test_flat_signal import _board, _pinned

FS, BLOCK = 5120, 64


def _imported(tmp_path: Path, x: np.ndarray, name: str, *options: str) -> Path:
    """The samples ``x`` (in g) of channel ``name`` at 5120 Hz, imported in blocks of 64."""
    npy, cap = tmp_path / f"{name}.npy", tmp_path / f"{name}.bin"
    np.save(npy, x.astype(np.float32))
    p = cmsensord("import", str(npy), "--fs", str(FS), "--block-len", str(BLOCK), "--unit", "g",
                  "--names", name, *options, "--out", str(cap))
    assert p.returncode == 0, p.stderr
    return cap


def _machine(seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """Board seconds and the vibration of a machine at 1500 rpm (1x and broadband)."""
    t = np.arange(int(seconds * FS)) / FS
    return t, np.sin(2 * np.pi * 25 * t) * 2 + np.random.default_rng(1).standard_normal(t.size)


def test_recalibrating_a_machine_that_stops_with_its_site_file_as_base(tmp_path):
    """A pump stopped for three stretches: calibrate learns it from its running time; again with
    that site file as --config BASE.yaml (its baseline then puts the stops under signal_floor:
    signal_lost) it does the same, not 'no signal in the healthy period'."""
    t, x = _machine(200)
    for a, b in ((10, 40), (50, 80), (90, 110)):
        x[(t >= a) & (t < b)] *= 0.01
    cap = _imported(tmp_path, x, "pump")
    runs = []
    for base in ((), ("--config", str(tmp_path / "site.yaml"))):
        out = tmp_path / f"site{len(runs)}.yaml"
        p = cmsensord("calibrate", str(cap), "--to", "120", "--rpm", "1500", *base, "--out", str(out))
        assert p.returncode == 0, p.stderr
        (tmp_path / "site.yaml").write_bytes(out.read_bytes())
        runs.append(p.stdout)
    for said in runs:
        assert "pump: 86 decision(s) with the machine stopped (level below 10 % of its running level), " \
               "starting or stopping: not learned from" in said, said


def test_a_flat_stretch_ending_where_the_window_begins_is_outside_it(tmp_path):
    """A sensor flat for the first 5 s, working after: calibrate --from 5 (and 5.01, floored to
    the same block) learns it; --from 4 takes in a flat decision and refuses it."""
    t, x = _machine(60)
    x[t < 5] = 0.0
    cap = _imported(tmp_path, x, "de", "--keep-dc")
    for start in ("5", "5.01"):
        p = cmsensord("calibrate", str(cap), "--from", start, "--to", "60", "--rpm", "1500",
                      "--out", str(tmp_path / "site.yaml"))
        assert p.returncode == 0, (start, p.stderr)
    p = cmsensord("calibrate", str(cap), "--from", "4", "--to", "60", "--rpm", "1500",
                  "--out", str(tmp_path / "site.yaml"))
    assert p.returncode == 2 and p.stderr.startswith(
        "cmsensord: calibrate: channel de: no signal in the healthy period: every sample at 2048 counts (no "
        "noise at all) for 1 s of the decision: nothing to learn"), p.stderr


def test_a_few_flat_blocks_in_the_healthy_period_are_not_learned_from(tmp_path):
    """One block in eight of ch1 pinned at 4095 all through the healthy period (fewer than make
    a decision of no signal): calibrate learns ch1 from the blocks that move, the baseline of the
    clean capture (the rail's blocks made it 115 x that), and says so."""
    clean = _board(tmp_path, seconds=30)
    loose = _pinned(clean, tmp_path / "loose.bin", 1, 0.0, 30.0, COUNT_MAX, every=8)
    learned = []
    for cap in (clean, loose):
        out = tmp_path / f"{cap.stem}.yaml"
        p = cmsensord("calibrate", str(cap), "--out", str(out))
        assert p.returncode == 0, p.stderr
        learned.append({ch["name"]: ch["baseline"] for ch in yaml.safe_load(out.read_text())["channels"]})
    assert "note: ch1: 375 flat block(s) in the healthy period (every sample one ADC count: a loose connector or " \
           "cable?): not learned from" in p.stdout and "misses" not in p.stdout, p.stdout
    assert learned[1]["ch0"] == learned[0]["ch0"]
    assert learned[1]["ch1"] == pytest.approx(learned[0]["ch1"], rel=0.02), learned


def test_flat_blocks_before_the_healthy_period_are_not_noted(tmp_path):
    """One block in eight of ch1 at 4095 from 1 s to 4 s, calibrate --from 6: no note of flat
    blocks (the replay's warning of them, before the window, was printed as a note)."""
    cap = _pinned(_board(tmp_path, seconds=20), tmp_path / "early.bin", 1, 1.0, 4.0, COUNT_MAX, every=8)
    p = cmsensord("calibrate", str(cap), "--from", "6", "--out", str(tmp_path / "site.yaml"))
    assert p.returncode == 0 and "flat" not in p.stdout, p.stdout + p.stderr
