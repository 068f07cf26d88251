"""An imported capture of snapshots gets indicator records that each hold one snapshot: with
``indicators.interval_s`` at its default, replay and calibrate take the snapshots' common
length, and say so (the site file calibrate writes leaves it to the capture); an interval the
configuration sets is kept, with a line when its records straddle the snapshots."""

from __future__ import annotations

import numpy as np

from cmsensord.sinks.mcap_sink import read_messages
from processes import run_module

FS = 2000
N = 1900        # a snapshot: 95 blocks of 20, 0.95 s: a 1-s record would straddle two


def _run(*args) -> str:
    p = run_module("cmsensord", *map(str, args))
    assert p.returncode == 0, p.stderr
    return p.stderr + p.stdout


def _records(out) -> list[dict]:
    return [m for path in sorted(out.glob("*.mcap")) for t, _, m in read_messages(path) if t == "/cm/ch/indicators"]


def _capture(tmp_path):
    """Four snapshots, each a 100-Hz sine of amplitude 1, 2, 3, 4 (whole periods), imported."""
    t = np.arange(N) / FS
    np.save(tmp_path / "s.npy", np.stack([(k + 1) * np.sin(2 * np.pi * 100 * t)[:, None] for k in range(4)]))
    _run("import", tmp_path / "s.npy", "--fs", FS, "--unit", "m/s2", "--names", "ch", "--out", tmp_path / "s.bin")
    return tmp_path / "s.bin"


def test_each_record_holds_one_snapshot_in_replay_and_in_the_site_file(tmp_path):
    cap = _capture(tmp_path)
    said = ("indicators.interval_s 0.95 (1900 samples, one record a snapshot) from the capture's snapshots of "
            "1900 samples: a record of the default 1 s would straddle them")
    err = _run("replay", cap, "--out", tmp_path / "out")
    assert f"  {said}\n" in err, err
    recs = _records(tmp_path / "out")
    # not records of 2000 samples, each with the start of the next snapshot (peaks 2, 3, 4, 4)
    assert [(m["interval_s"], round(m["accel_peak"], 2), m["missing_fraction"]) for m in recs] == \
        [(0.95, 1.0, 0.0), (0.95, 2.0, 0.0), (0.95, 3.0, 0.0), (0.95, 4.0, 0.0)]
    site = tmp_path / "site.yaml"
    out = _run("calibrate", cap, "--out", site)
    assert f"note: {said}\n" in out, out
    assert ("# indicators.interval_s is not set: the 0.95-s records of the capture's snapshots are its own (a "
            "replay\n") in site.read_text()
    assert "\n  interval_s:" not in site.read_text()        # the live board's stream is not of snapshots
    err = _run("replay", cap, "--config", site, "--out", tmp_path / "site")
    assert f"  {said}\n" in err, err                        # the replay of the capture takes it again
    assert [(m["interval_s"], round(m["accel_peak"], 2)) for m in _records(tmp_path / "site")] == \
        [(0.95, 1.0), (0.95, 2.0), (0.95, 3.0), (0.95, 4.0)]


def test_an_interval_the_configuration_sets_is_kept_and_said_to_straddle(tmp_path):
    cap = _capture(tmp_path)
    (tmp_path / "half.yaml").write_text("indicators:\n  interval_s: 0.5\n")
    err = _run("replay", cap, "--config", tmp_path / "half.yaml", "--out", tmp_path / "out")
    assert ("  indicators: records of 1000 samples (0.5 s) straddle the capture's snapshots (their lengths are "
            "multiples of 1900 samples only; indicators.interval_s is set): a record may hold the end of one and "
            "the start of the next\n") in err, err
    assert {m["interval_s"] for m in _records(tmp_path / "out")} == {0.5}


def test_a_capture_longer_than_the_snapshots_is_said(tmp_path):
    """capture.pre_s + post_s of 2 s against snapshots of 0.95 s: one line says a capture joins
    snapshots of other times (its spectra would average across the joins); none with
    a capture within a snapshot."""
    cap = _capture(tmp_path)
    for span, said in ((1.0, True), (0.4, False)):
        cfg = tmp_path / "cap.yaml"
        cfg.write_text(f"capture:\n  every_s: 1.0\n  pre_s: {span}\n  post_s: {span}\n")
        err = _run("replay", cap, "--config", cfg, "--out", tmp_path / f"out{span}")
        line = (f"  capture: a capture of {2 * span:g} s (capture.pre_s + post_s) holds about 3 of the recording's "
                "snapshots of 0.95 s, laid end to end: its waveform and spectra join records of other times; "
                "pre_s + post_s <= 0.95 s keeps it within one or two\n")
        assert (line in err) == said and ("  capture: a capture of" in err) == said, err
