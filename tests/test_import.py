"""`cmsensord import`: every format round-trips to the capture within one count, snapshot
files land on a continuous board clock with their gaps in the sidecar, clipping is never
silent, and a user's mistakes are one-line errors that leave nothing behind."""

from __future__ import annotations

import json
import os
import re
import stat
import subprocess
import sys
import wave
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from scipy.io import wavfile

from cmsensord.cli import main
from cmsensord.dsp.rms import block_rms
from cmsensord.importing.adc import nice_range
from cmsensord.protocol import FLAG_CLIPPED, FrameType, decode_raw, decode_rms, decode_status, decode_tacho, iter_frames
from cmsensord.sinks.mcap_sink import read_messages, summarize

G = 9.80665
REPO = Path(__file__).resolve().parents[1]


def decode(path: Path) -> dict:
    """The capture as the daemon's decoder sees it: STATUS, counts per channel, flags, tacho;
    ``x``: the values the counts stand for with the means the import took out (its sidecar's
    ``dc_removed``) added back, the recording's own values."""
    frames, counters = iter_frames(path.read_bytes())
    assert counters.crc_failures == 0 and counters.bytes_discarded == 0 and counters.frames_lost == 0
    status = decode_status(next(f for f in frames if f.type == FrameType.STATUS).payload)
    raw: dict[int, list] = {}
    flags: dict[int, list] = {}
    rms, edges, t0s = [], [], []
    dc: dict[int, list] = {}
    for f in frames:
        if f.type == FrameType.RAW:
            raw.setdefault(f.chan, []).append(decode_raw(f.payload))
            dc.setdefault(f.chan, []).append(f.t0_unwrapped)
            flags.setdefault(f.chan, []).append(f.flags)
            if f.chan == 0:
                t0s.append(f.t0_unwrapped)
        elif f.type == FrameType.RMS:
            rms.append(decode_rms(f))
            flags.setdefault(0, []).append(f.flags)
            t0s.append(f.t0_unwrapped)
        elif f.type == FrameType.TACHO:
            edges.extend(f.t0_unwrapped + decode_tacho(f.payload) / 256.0)
    out = {"status": status, "flags": {c: np.array(v) for c, v in flags.items()},
           "t0": np.array(t0s), "edges": np.array(edges), "rms": np.array(rms)}
    if raw:
        counts = np.stack([np.concatenate(raw[c]) for c in sorted(raw)])
        scale = np.array(status.scale)[:, None]
        offset = np.array(status.offset)[:, None]
        out["counts"] = counts
        out["x"] = (counts - offset) * scale + _removed(path, status.fs, raw, dc)
    return out


def _removed(path: Path, fs: int, raw: dict[int, list], t0s: dict[int, list]) -> np.ndarray | float:
    """Per channel and sample, the mean the import took out of it (0 without a sidecar, or
    with ``--keep-dc``)."""
    side = Path(f"{path}.json")
    meta = json.loads(side.read_text()) if side.is_file() else {}
    if not meta.get("dc_removed"):
        return 0.0
    snaps = meta["snapshots"]
    starts = np.array([round(s["start_s"] * fs) for s in snaps])
    means = np.array([s.get("dc_removed", meta["dc_removed"]) for s in snaps])
    rows = []
    for c in sorted(raw):
        k = np.searchsorted(starts, np.array(t0s[c]), side="right") - 1
        rows.append(np.repeat(means[k, c], [len(b) for b in raw[c]]))
    return np.stack(rows)


def run(*args: str | Path) -> int:
    return main(["import", *map(str, args)])


def sidecar(out: Path) -> dict:
    return json.loads(Path(f"{out}.json").read_text())


def assert_within_one_count(cap: dict, expected: np.ndarray) -> None:
    scale = np.array(cap["status"].scale)[:, None]
    assert cap["x"].shape == expected.shape
    assert np.all(np.abs(cap["x"] - expected) <= 0.5 * scale * (1 + 1e-6))


def signal(n: int, c: int, amp: float = 1.0, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(n)
    return np.stack([amp * (0.6 * np.sin(2 * np.pi * (k + 1) * t / 97) + 0.3 * rng.standard_normal(n).clip(-1.3, 1.3))
                     for k in range(c)])


# --------------------------------------------------------------------------- formats
@pytest.mark.parametrize("kind", ["int16", "int24", "int32", "float32"])
def test_wav_round_trip(tmp_path, kind):
    fs, n = 8000, 8000
    x = signal(n, 2, amp=0.5)  # fractions of full scale
    path = tmp_path / "rec.wav"
    if kind == "int16":
        wavfile.write(path, fs, np.round(x.T * 32767).astype(np.int16))
        frac = np.round(x * 32767) / 32768
    elif kind == "int32":
        wavfile.write(path, fs, np.round(x.T * 2**31).astype(np.int32))
        frac = np.round(x * 2**31) / 2**31
    elif kind == "float32":
        wavfile.write(path, fs, x.T.astype(np.float32))
        frac = x.astype(np.float32).astype(np.float64)
    else:  # 24-bit PCM, written by hand (scipy writes no 24-bit files)
        v = np.round(x.T * (2**23 - 1)).astype(np.int32)
        b = np.ascontiguousarray(v, dtype="<i4").view(np.uint8).reshape(-1, 4)[:, :3].tobytes()
        with wave.open(str(path), "wb") as w:
            w.setnchannels(2)
            w.setsampwidth(3)
            w.setframerate(fs)
            w.writeframes(b)
        frac = np.round(x * (2**23 - 1)) / 2**23
    out = tmp_path / "rec.bin"
    assert run(path, "--unit", "g", "--scale-factor", "2", "--out", out) == 0
    cap = decode(out)
    assert (cap["status"].fs, cap["status"].block_len, cap["status"].n_channels) == (8000, 80, 2)
    assert_within_one_count(cap, frac * 2 * G)
    assert sidecar(out)["channel_names"] == ["ch0", "ch1"]


def test_csv_header_names_and_columns(tmp_path):
    x = signal(1000, 3, amp=3.0)
    path = tmp_path / "log.csv"
    rows = "\n".join(",".join(f"{v:.6f}" for v in r) for r in x.T)
    path.write_text("time,acc_x,acc_y\n" + rows + "\n")
    out = tmp_path / "log.bin"
    assert run(path, "--fs", "1000", "--channels", "acc_y,1", "--unit", "m/s2", "--out", out) == 0
    cap = decode(out)
    assert_within_one_count(cap, np.round(x[[2, 1]], 6))
    meta = sidecar(out)
    assert meta["channel_names"] == ["acc_y", "acc_x"] and meta["block_len"] == 10


def test_tsv_without_header_and_semicolon_decimal_comma(tmp_path):
    x = signal(600, 2)
    tsv = tmp_path / "a.tsv"
    tsv.write_text("\n".join("\t".join(f"{v:.5f}" for v in r) for r in x.T) + "\n")
    semi = tmp_path / "b.csv"
    semi.write_text("\n".join(";".join(f"{v:.5f}".replace(".", ",") for v in r) for r in x.T) + "\n")
    for src in (tsv, semi):
        out = tmp_path / f"{src.stem}.bin"
        assert run(src, "--fs", "600", "--unit", "mm/s2", "--names", "h,v", "--out", out) == 0
        assert_within_one_count(decode(out), np.round(x, 5) * 1e-3)


def test_npy_and_npz_with_rate_times_and_speed_in_the_file(tmp_path):
    x = signal(5120, 2, amp=30)
    np.save(tmp_path / "a.npy", x.T)  # (samples, channels)
    out = tmp_path / "a.bin"
    assert run(tmp_path / "a.npy", "--fs", "5120", "--block-len", "64", "--channels", "1", "--out", out) == 0
    assert_within_one_count(decode(out), x[[1]])
    snaps = np.round(x.T.reshape(4, 1280, 2) * 1000).astype(np.int32)  # (snapshots, samples, ch), mg
    np.savez(tmp_path / "b.npz", acc_mg=snaps, t_s=np.array([0.0, 10.0, 20.0, 40.0]), fs_hz=12800.0,
             rpm=1800.0, other=np.arange(3))
    out = tmp_path / "b.bin"
    assert run(tmp_path / "b.npz", "--array", "acc_mg", "--unit", "mg", "--out", out) == 0
    cap = decode(out)
    assert cap["status"].fs == 12800
    assert_within_one_count(cap, snaps.transpose(2, 0, 1).reshape(2, -1) * 1e-3 * G)
    meta = sidecar(out)
    assert meta["rpm"] == 1800.0 and meta["rpm_source"] == "b.npz"
    assert [s["source"] for s in meta["snapshots"]] == [f"b.npz[{k}]" for k in range(4)]
    assert [s["gap_before_s"] for s in meta["snapshots"]] == [None, 9.9, 9.9, 19.9]


def test_mat_variable_and_snapshot_len(tmp_path):
    x = signal(3 * 2048 + 100, 1, amp=0.5)  # g; three whole snapshots and a short one
    scipy.io.savemat(tmp_path / "m.mat", {"data": x.T, "fs": 20480.0, "label": "bearing"})
    out = tmp_path / "m.bin"
    assert run(tmp_path / "m.mat", "--variable", "data", "--unit", "g", "--snapshot-len", "2048",
               "--block-len", "256", "--out", out) == 0
    meta = sidecar(out)
    assert meta["fs"] == 20480 and meta["block_len"] == 256
    assert [s["length"] for s in meta["snapshots"]] == [2048, 2048, 2048, 0]
    assert [s["dropped"] for s in meta["snapshots"]] == [0, 0, 0, 100]
    assert_within_one_count(decode(out), x[:, :3 * 2048] * G)


# --------------------------------------------------------------------------- snapshots
def test_glob_of_snapshot_files_in_natural_order_with_gaps_and_remainders(tmp_path, capsys):
    d = tmp_path / "snaps"
    d.mkdir()
    x = signal(5 * 1000, 1, amp=2.0)
    for k in range(5):  # acc_2 must come before acc_10
        (d / f"acc_{[1, 2, 3, 10, 11][k]}.csv").write_text(
            "\n".join(f"9,39,{k},{v:.5f}" for v in x[0, k * 1000:(k + 1) * 1000]) + "\n")
    out = tmp_path / "g.bin"
    assert run(str(d / "acc_*.csv"), "--fs", "10000", "--channels", "3", "--snapshot-interval", "10",
               "--out", out) == 0  # block 100: every 1000-sample snapshot is 10 blocks
    cap = decode(out)
    assert_within_one_count(cap, np.round(x, 5))
    assert np.array_equal(cap["t0"], np.arange(50) * 100)  # one continuous board clock
    meta = sidecar(out)
    snaps = meta["snapshots"]
    assert [s["source"] for s in snaps] == ["acc_1.csv", "acc_2.csv", "acc_3.csv", "acc_10.csv", "acc_11.csv"]
    assert [s["start_s"] for s in snaps] == [0.0, 0.1, 0.2, 0.3, 0.4]
    assert [s["pct_of_record"] for s in snaps] == [0.0, 20.0, 40.0, 60.0, 80.0]
    assert [s["gap_before_s"] for s in snaps] == [None, 9.9, 9.9, 9.9, 9.9]
    assert meta["dropped_samples"] == 0
    # a block length that does not divide the snapshots: the remainder is dropped, and said so
    assert run(str(d), "--fs", "10000", "--channels", "3", "--block-len", "300", "--out", out) == 0
    err = capsys.readouterr().err
    assert ("each 1000-sample snapshot ends with 100 sample(s) that do not fill a 300-sample block: "
            "dropped (500 samples in all, 10.00 %); --block-len 100 (a divisor of 1000) keeps them") in err
    meta = sidecar(out)
    assert [s["dropped"] for s in meta["snapshots"]] == [100] * 5 and meta["blocks"] == 15
    # the divisor that keeps them gives another block rate than 100 a second: said beside it
    assert run(str(d), "--fs", "12800", "--channels", "3", "--out", tmp_path / "rate.bin") == 0
    assert ("each 1000-sample snapshot ends with 104 sample(s) that do not fill a 128-sample block: dropped "
            "(520 samples in all, 10.40 %); --block-len 125 (a divisor of 1000) keeps them (102.4 blocks a second, "
            "not 100: a replay's decision_rule warning says what that changes)") in capsys.readouterr().err
    keep = np.concatenate([x[0, k * 1000:k * 1000 + 900] for k in range(5)])
    assert_within_one_count(decode(out), np.round(keep[None], 5))


def test_default_block_len_when_fs_over_100_is_not_whole(tmp_path, capsys):
    np.save(tmp_path / "a.npy", signal(20480 * 2, 1)[0])
    out = tmp_path / "a.bin"
    assert run(tmp_path / "a.npy", "--fs", "20480", "--snapshot-len", "20480", "--out", out) == 0
    err = capsys.readouterr().err
    assert "block_len 205 (fs/100 = 204.8 is not whole): 99.902 blocks per second" in err
    assert "185 sample(s) that do not fill a 205-sample block: dropped (370 samples in all" in err
    assert sidecar(out)["dropped_samples"] == 370


# --------------------------------------------------------------------------- range, clipping, modes
def test_default_range_has_headroom_and_never_clips():
    assert [nice_range(v) for v in (0.0, 0.79, 0.81, 4.0, 472.2, 1e-5)] == [1.0, 1.0, 1.2, 5.0, 600.0, 1.5e-05]


def test_clipping_is_flagged_per_block_and_reported(tmp_path, capsys):
    x = signal(1000, 1, amp=1.0)
    x[0, 345] = 9.0   # block 3 (block_len 100)
    x[0, 702] = -9.0  # block 7
    np.save(tmp_path / "a.npy", x[0])
    out = tmp_path / "a.bin"
    assert run(tmp_path / "a.npy", "--fs", "10000", "--range", "5", "--out", out) == 0
    cap = decode(out)
    assert list(np.flatnonzero(cap["flags"][0] & FLAG_CLIPPED)) == [3, 7]
    meta = sidecar(out)
    assert meta["clipped_blocks"] == [2] and meta["clipped_samples"] == [2]
    err = capsys.readouterr().err
    assert ("WARNING ch: 2 sample(s) in 2 block(s) clipped at +-5 m/s2 (counts 0/4095); those blocks "
            "carry the clipped flag; --range 12 avoids it") in err
    assert run(tmp_path / "a.npy", "--fs", "10000", "--out", out) == 0  # the default range: none
    assert not (decode(out)["flags"][0] & FLAG_CLIPPED).any() and sidecar(out)["full_scale"] == [12.0]


def test_rms_mode_sends_the_rms_of_the_raw_blocks(tmp_path):
    x = signal(4000, 2, amp=5.0)
    np.save(tmp_path / "a.npy", x.T)
    raw, rms = tmp_path / "raw.bin", tmp_path / "rms.bin"
    assert run(tmp_path / "a.npy", "--fs", "4000", "--out", raw) == 0
    assert run(tmp_path / "a.npy", "--fs", "4000", "--mode", "rms", "--out", rms) == 0
    r, m = decode(raw), decode(rms)
    assert m["status"].mode == 1 and m["rms"].shape == (100, 2)
    expected = block_rms(r["counts"], r["status"].scale, r["status"].offset, 40).T
    assert np.array_equal(m["rms"], expected)


def test_tacho_from_a_pulse_column_and_from_a_constant_speed(tmp_path):
    fs, n = 10000, 10000
    t = np.arange(n)
    pulses = ((t % 400) < 40).astype(float) * 5.0  # rising edges at 0 (none: starts high), 400, 800 ...
    data = np.stack([signal(n, 1)[0], pulses], axis=1)
    np.save(tmp_path / "a.npy", data)
    out = tmp_path / "a.bin"
    assert run(tmp_path / "a.npy", "--fs", fs, "--tacho-column", "1", "--out", out) == 0
    cap = decode(out)
    assert cap["status"].tacho_inputs == 1 and cap["status"].n_channels == 1
    assert np.allclose(cap["edges"], np.arange(400, n, 400) - 0.5, atol=1 / 256)
    assert run(tmp_path / "a.npy", "--fs", fs, "--channels", "0", "--rpm", "1500", "--ppr", "2",
               "--out", out) == 0
    cap = decode(out)
    assert cap["status"].tacho_ppr == 2
    assert np.allclose(cap["edges"], np.arange(0, n, 200), atol=1 / 256)  # 50 Hz x 2 = every 200 samples
    assert sidecar(out)["rpm"] == 1500.0


def test_tacho_from_a_column_of_shaft_speed_in_rpm(tmp_path):
    """A run-up logged as a speed column (600 -> 1500 rpm over 3 s at 5 kHz): --speed-column
    gives ppr edges a revolution where the integrated speed passes each 1/ppr revolution."""
    fs, n, ppr = 5000, 15000, 2
    rpm = 600.0 + 300.0 * np.arange(n) / fs
    np.save(tmp_path / "s.npy", np.stack([signal(n, 1)[0], rpm], axis=1))
    out = tmp_path / "s.bin"
    assert run(tmp_path / "s.npy", "--fs", fs, "--speed-column", "1", "--ppr", ppr, "--out", out) == 0
    cap = decode(out)
    assert cap["status"].tacho_inputs == 1 and cap["status"].n_channels == 1 and cap["status"].tacho_ppr == ppr
    # a plain re-statement: the revolutions at sample i are the trapezoid sum of rpm / 60 / fs
    revs = np.concatenate([[0.0], np.cumsum(0.5 * (rpm[1:] + rpm[:-1]) / 60 / fs)])
    expected = np.array([np.interp(k / ppr, revs, np.arange(n)) for k in range(int(revs[-1] * ppr) + 1)])
    assert cap["edges"].size == expected.size == 105       # 52.5 revolutions, from the first sample
    assert np.allclose(cap["edges"], expected, atol=1 / 256)
    meta = sidecar(out)
    assert (meta["tacho"], meta["tacho_from"], meta["rpm"], meta["rpm_source"]) == (
        "ch_1", "speed", float(np.median(rpm)), "column ch_1 (median)")


def test_a_run_up_with_a_speed_column_is_order_tracked_on_replay(tmp_path):
    """`import --speed-column` then `replay`: the orders follow the logged speed, and the 1x
    and 2x amplitudes are the recording's (0.5 g and 0.2 g)."""
    fs, n = 10000, 100000
    rpm = 600.0 + 120.0 * np.arange(n) / fs
    phase = np.cumsum(rpm / 60 / fs)
    x = 0.5 * np.sin(2 * np.pi * phase) + 0.2 * np.sin(4 * np.pi * phase)
    np.save(tmp_path / "r.npy", np.stack([x, rpm], axis=1))
    r = cmd("import", "r.npy", "--fs", str(fs), "--unit", "g", "--names", "motor", "--speed-column", "1",
            "--out", "r.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "  tacho: speed column ch_1 (median 1199.99 rpm), 200 edge(s), 1 a revolution\n" in r.stderr
    r = cmd("replay", "r.bin", "--out", "logs", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    (log,) = (tmp_path / "logs").glob("*.mcap")
    orders = [m for topic, _, m in read_messages(log) if topic == "/cm/motor/orders"]
    assert len(orders) == 100                            # one /orders block every 100 ms
    for m in orders[30:]:                                # the tracker settled (3 s)
        t = m["timestamp"]["sec"] + m["timestamp"]["nsec"] / 1e9 - (orders[0]["timestamp"]["sec"]
                                                                    + orders[0]["timestamp"]["nsec"] / 1e9)
        assert m["speed_rpm"] == pytest.approx(600 + 120 * (t + 0.1), rel=0.02)
        amp = {o["name"]: o["amplitude"] for o in m["orders"]}
        assert amp["1x"] == pytest.approx(0.5 * G, rel=0.05) and amp["2x"] == pytest.approx(0.2 * G, rel=0.05)


# --------------------------------------------------------------------------- the real command
def cmd(*args, cwd, env=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cmsensord", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=60, env=env)


def test_errors_are_one_line_and_leave_nothing_behind(tmp_path):
    (tmp_path / "x.csv").write_text("a,b,c\n1,2,3\n4,5,6\n")
    (tmp_path / "bad.csv").write_text("1;2\n3;oops\n")
    scipy.io.savemat(tmp_path / "m.mat", {"data": np.zeros((10, 1))})
    np.save(tmp_path / "p.npy", np.stack([np.zeros(4096), np.tile([0.0, 1.0], 2048)], axis=1))
    (tmp_path / "cut.wav").write_bytes(b"RIFF\x24\x00\x00\x00WAVEfmt ")    # a header cut short
    cases = {
        ("cut.wav",): "cut.wav: not a readable WAV file (it ends inside its header); export it as PCM or float WAV",
        ("x.csv", "--fs", "100", "--columns", "acc"):
            "x.csv: no column 'acc' (columns: a, b, c); use --columns",
        ("x.csv",): "x.csv: the file does not say its sampling rate; give --fs HZ",
        ("bad.csv", "--fs", "10"):
            "bad.csv: line 2, column 1: 'oops' is not a number (separator ';', no header); "
            "fix the file, or set --separator / --header / --no-header",
        ("m.mat", "--variable", "x", "--fs", "10"): "m.mat: no variable 'x' (variables: data); use --variable",
        ("x.csv", "--fs", "100", "--unit", "V"):
            "--unit V needs the sensor's sensitivity; add --sensitivity MV_PER_G (e.g. 100 for a 100 mV/g "
            "accelerometer)",
        # found while writing: a TACHO frame holds at most 1023 edges
        ("p.npy", "--fs", "204800", "--tacho-column", "1", "--block-len", "2048"):
            "p.npy: tacho column 'ch_1': 1024 edges in one 2048-sample block, a TACHO frame holds at most 1023; "
            "check --tacho-threshold, --ppr or --rpm",
        # found by trying hostile speeds: a traceback allocating 32 GB of edge times
        ("p.npy", "--fs", "20000", "--channels", "0", "--rpm", "1e12"):
            "--rpm 1e+12: more than one tacho edge a sample at 1 a revolution (at most 1.2e+06 rpm at 20000 Hz); "
            "check --rpm and --ppr",
    }
    for args, message in cases.items():
        r = cmd("import", *args, "--out", "o.bin", cwd=tmp_path)
        assert (r.returncode, r.stdout, r.stderr) == (2, "", f"cmsensord import: {message}\n"), args
        assert not list(tmp_path.glob("o.bin*")), args


def test_a_wav_file_cut_short_is_imported_as_far_as_it_goes_and_says_so(tmp_path):
    """A WAV file whose data stops before its header says (a copy cut short): the samples there
    are imported, and a note on stderr and in the sidecar says the file ends early."""
    x = np.round(signal(8000, 1, amp=0.5)[0] * 32767).astype(np.int16)
    wavfile.write(tmp_path / "whole.wav", 8000, x)
    data = (tmp_path / "whole.wav").read_bytes()
    (tmp_path / "cut.wav").write_bytes(data[: 44 + 2 * 5000])            # 5,000 of 8,000 samples
    r = cmd("import", "cut.wav", "--out", "o.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    [note] = [line for line in r.stderr.splitlines() if "cut.wav" in line]
    assert re.fullmatch(r"  note: cut\.wav: the file ends before the data its header declares \(.+\); "
                        r"the 5,000 sample\(s\) there are imported", note), note
    assert note[len("  note: "):] in sidecar(tmp_path / "o.bin")["notes"]
    cap = decode(tmp_path / "o.bin")
    n = 5000 - 5000 % cap["status"].block_len              # whole blocks of what is there
    assert_within_one_count(cap, x[None, :n] / 32768)


def test_import_then_replay_end_to_end(tmp_path):
    fs = 25600
    x = signal(fs * 4, 1, amp=3.0)[0]
    x[3 * fs:] *= 8  # the last second: a machine far from its healthy level
    wavfile.write(tmp_path / "rec.wav", fs, (x / 40).astype(np.float32))
    r = cmd("import", "rec.wav", "--scale-factor", "40", "--names", "bearing", "--out", "rec.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "RAW, 1 channel(s), fs 25600 Hz, block 256 (100 blocks/s), 4.00 s of board time" in r.stderr
    r = cmd("replay", "rec.bin", "--out", "mcap", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "4.0 s of ADC time" in r.stderr and "400 observations, 0 missing, 0 frames lost" in r.stderr
    assert "bearing: final severity" in r.stderr and "4 decisions" in r.stderr    # named as imported
    (log,) = (tmp_path / "mcap").glob("*.mcap")
    info = summarize(log)
    assert info["topics"]["/cm/bearing/severity"] == 4  # one severity message per 1-s decision
    assert info["events"][0]["message"] == "board firmware 1.0: RAW mode, 1 channel(s), fs 25600 Hz, block 256"


def test_progress_bar_only_on_a_terminal():
    import io

    from cmsensord.terminal_bar import Bar

    class Tty(io.StringIO):
        def isatty(self):
            return True

    tty, pipe = Tty(), io.StringIO()
    for stream in (tty, pipe):
        bar = Bar(10, "import: writing x.bin", stream=stream)
        bar(10)
        bar.close()
    assert tty.getvalue().startswith("\rimport: writing x.bin [" + "#" * 30 + "] 100.0%")
    assert pipe.getvalue() == ""


def test_a_snapshot_time_that_is_not_a_number_is_no_time_in_a_sidecar_of_strict_json(tmp_path):
    snaps = np.round(signal(4 * 1280, 1).T.reshape(4, 1280, 1) * 1000).astype(np.int32)
    np.savez(tmp_path / "t.npz", acc_mg=snaps, t_s=np.array([0.0, 10.0, np.nan, 30.0]), fs_hz=12800.0)
    assert run(tmp_path / "t.npz", "--array", "acc_mg", "--unit", "mg", "--out", tmp_path / "t.bin") == 0

    def refuse(word):
        raise ValueError(f"{word} in the sidecar")

    meta = json.loads((tmp_path / "t.bin.json").read_text(), parse_constant=refuse)
    assert [s["source_time_s"] for s in meta["snapshots"]] == [0.0, 10.0, None, 30.0]


def test_a_rate_or_speed_in_the_file_that_is_not_a_number(tmp_path):
    """Found by feeding the import random archives: an fs of NaN was a traceback, an rpm of inf
    went into the sidecar as Infinity (not JSON)."""
    np.savez(tmp_path / "nan.npz", data=np.zeros((1000, 1)), fs=np.nan)
    r = cmd("import", "nan.npz", "--out", "o.bin", cwd=tmp_path)
    assert (r.returncode, r.stderr) == (2, "cmsensord import: nan.npz: the sampling rate the file gives, nan Hz, "
                                           "is not a rate; give --fs HZ\n")
    np.savez(tmp_path / "inf.npz", data=signal(1000, 1).T, fs=1000.0, rpm=np.inf)
    assert run(tmp_path / "inf.npz", "--out", tmp_path / "o.bin") == 0
    meta = json.loads((tmp_path / "o.bin.json").read_text(), parse_constant=lambda word: word + " in the sidecar")
    assert (meta["rpm"], meta["rpm_source"]) == (None, None)


def test_an_out_that_is_a_fifo_is_left_and_said_in_one_line(tmp_path):
    """--out naming a FIFO (or a device: /dev/full, as root) is refused before the recording is read:
    the capture written beside it and renamed over it replaced it with a regular file."""
    wav = tmp_path / "a.wav"
    wavfile.write(wav, 25_000, (signal(25_000, 1)[0] * 1000).astype(np.int16))
    out = tmp_path / "cap.bin"
    os.mkfifo(out)
    p = cmd("import", str(wav), "--out", str(out), cwd=tmp_path)
    assert (p.returncode, p.stderr) == (2, f"cmsensord import: {out}: is a FIFO, not a regular file: the capture "
                                           "would replace it; give --out a file name\n")
    assert stat.S_ISFIFO(os.lstat(out).st_mode) and not (tmp_path / "cap.bin.json").exists()
