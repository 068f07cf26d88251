"""`cmsensord import` of channels in different units: an accelerometer beside a microphone in
one recording (a field recorder's WAV: each channel its own full scale), as the acoustic
calibration needs them, each in its own physical unit (m/s², Pa); the unit an array's or a
variable's name ends with (FEMTO's ``acc_mg``)."""

from __future__ import annotations

import re

import numpy as np
import scipy.io
from scipy.io import wavfile

from cmsensord.acoustic_calib import blocks_from_capture
from cmsensord.sinks.mcap_read import read_messages
from processes import cmsensord as cmsensord_run
from processes import run_module
from tests.test_import import G, cmd, sidecar

FS = 48000
#: the recorder's full scale of each channel: the accelerometer's 50 g, the microphone's 20 Pa
ACC_FS_G, MIC_FS_PA = 50.0, 20.0


def recorder_wav(path, seconds: float, machine: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A 2-channel 16-bit WAV: ch0 an accelerometer (1x at 29.7 Hz and noise, ``machine`` x its
    running level), ch1 a microphone hearing the machine and a background; its two signals in
    m/s2 and Pa as the file holds them."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * FS)) / FS
    acc = machine * (3.0 * np.sin(2 * np.pi * 29.7 * t) + 1.5 * rng.standard_normal(t.size)) \
        + 0.05 * rng.standard_normal(t.size)
    mic = machine * 0.8 * np.sin(2 * np.pi * 29.7 * t + 0.3) + 0.3 * rng.standard_normal(t.size)
    pcm = np.round(np.stack([acc / (ACC_FS_G * G), mic / MIC_FS_PA], axis=1) * 32767).astype(np.int16)
    wavfile.write(path, FS, pcm)
    held = pcm.astype(np.float64) / 32768
    return held[:, 0] * ACC_FS_G * G, held[:, 1] * MIC_FS_PA


def test_an_accelerometer_and_a_microphone_in_one_wav_each_in_its_own_unit(tmp_path):
    acc, mic = recorder_wav(tmp_path / "pair.wav", 6.0, 1.0, 1)
    r = cmd("import", "pair.wav", "--unit", "g,Pa", "--scale-factor", f"{ACC_FS_G:g},{MIC_FS_PA:g}",
            "--names", "acc,mic", "--out", "pair.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "  acc: full scale +-" in r.stderr and " m/s2 a count), peak " in r.stderr
    mic_line = next(line for line in r.stderr.splitlines() if line.startswith("  mic: "))
    assert mic_line.startswith("  mic: full scale +-") and mic_line.count(" Pa") == 3, mic_line
    meta = sidecar(tmp_path / "pair.bin")
    assert (meta["unit"], meta["source_unit"], meta["scale_factor"]) == (["m/s2", "Pa"], ["g", "Pa"], [50.0, 20.0])
    # the block RMS the daemon and the acoustic calibration see: m/s2 and Pa, each its own
    _, rms, _ = blocks_from_capture(tmp_path / "pair.bin", [0, 1])
    L = meta["block_len"]
    n = rms.shape[0]
    want = np.sqrt(np.stack([(x[:n * L].reshape(n, L) ** 2).mean(axis=1) for x in (acc, mic)], axis=1))
    np.testing.assert_allclose(rms, want, rtol=0.02, atol=2e-3)
    # one unit for both scales the microphone as if in g: 9.8 x too large
    r = cmd("import", "pair.wav", "--unit", "g", "--scale-factor", f"{ACC_FS_G:g},{MIC_FS_PA:g}", "--out", "g.bin",
            cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    _, rms_g, _ = blocks_from_capture(tmp_path / "g.bin", [0, 1])
    assert 9.5 < np.median(rms_g[:, 1] / rms[:, 1]) < 10.1


def test_the_acoustic_calibration_from_an_imported_paired_recording(tmp_path):
    """The README's acoustic calibration, from a recorder's files instead of the simulator's."""
    recorder_wav(tmp_path / "pair.wav", 20.0, 1.0, 2)
    recorder_wav(tmp_path / "bg.wav", 10.0, 0.0, 3)                # the machine stopped: background alone
    for name in ("pair", "bg"):
        r = cmd("import", f"{name}.wav", "--unit", "g,Pa", "--scale-factor", f"{ACC_FS_G:g},{MIC_FS_PA:g}",
                "--out", f"{name}.bin", cwd=tmp_path)
        assert r.returncode == 0, r.stderr
    r = run_module("cmsensord.acoustic_calib", "--paired", str(tmp_path / "pair.bin"), "--background",
                   str(tmp_path / "bg.bin"), "--accel", "0", "--mic", "1", "--out", str(tmp_path / "mic.json"))
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(f"wrote {tmp_path / 'mic.json'}: 2000 paired + 1000 background blocks of 10 ms")


def test_units_and_values_per_channel_that_do_not_fit_are_one_line(tmp_path):
    recorder_wav(tmp_path / "pair.wav", 1.0, 1.0, 4)
    cases = {
        ("--unit", "g,Pa,g"): "--unit gives 3 units for 2 channel(s); give one unit, or one per imported channel",
        ("--unit", "g,Pa", "--scale-factor", "1,2,3"): "--scale-factor gives 3 values for 2 channel(s); give one, "
                                                       "or one per imported channel",
        ("--unit", "g,Pa", "--sensitivity", "100"): "--sensitivity applies to --unit V only (got --unit g); drop "
                                                    "--sensitivity or use --unit V",
    }
    for args, message in cases.items():
        r = cmd("import", "pair.wav", *args, "--out", "o.bin", cwd=tmp_path)
        assert (r.returncode, r.stderr) == (2, f"cmsensord import: {message}\n"), args
        assert not list(tmp_path.glob("o.bin*"))
    r = cmd("import", "pair.wav", "--unit", "g,Pa", "--range", "50g,5g", "--out", "o.bin", cwd=tmp_path)
    assert (r.returncode, r.stderr) == (2, "cmsensord import: --range: ch1 is a microphone's channel, in Pa: give its "
                                           "range in Pa, not in g (one per channel: --range 50g,20)\n")
    r = cmd("import", "pair.wav", "--unit", "g,Pa", "--range", "50g,20", "--out", "o.bin", cwd=tmp_path)
    assert r.returncode == 0 and sidecar(tmp_path / "o.bin")["full_scale"] == [50 * G, 20.0], r.stderr
    r = cmd("import", "pair.wav", "--unit", "g,psi", "--out", "o.bin", cwd=tmp_path)
    assert r.returncode == 2 and "unknown unit 'psi'; choose from g, mg, m/s2, mm/s2, V, Pa" in r.stderr


def test_a_file_that_gives_its_columns_different_units_is_read_in_each_ones(tmp_path):
    """`Acc (g)` beside `Mic (Pa)`: each column in its own unit (not both taken as m/s2)."""
    rng = np.random.default_rng(5)
    x = np.round(rng.normal(0.0, 0.5, (2000, 2)), 4)
    (tmp_path / "d.csv").write_text("Acc (g),Mic (Pa)\n" + "".join(f"{a},{b}\n" for a, b in x))
    r = cmd("import", "d.csv", "--fs", "1000", "--block-len", "10", "--out", "d.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert ("  note: units from the file (Acc (g): g, Mic (Pa): Pa); --unit sets others (one, or one per "
            "channel)\n") in r.stderr
    assert sidecar(tmp_path / "d.bin")["unit"] == ["m/s2", "Pa"]
    _, rms, _ = blocks_from_capture(tmp_path / "d.bin", [0, 1])
    ac = x - x.mean(axis=0)                 # each channel's mean taken out, the microphone's too
    want = np.sqrt((ac[:rms.shape[0] * 10].reshape(-1, 10, 2) ** 2).mean(axis=1)) * [G, 1.0]
    np.testing.assert_allclose(rms, want, rtol=0.02, atol=2e-3)


def test_a_microphone_in_the_wrong_unit_is_refused_where_it_would_estimate_nothing(tmp_path):
    """A microphone calibrated in Pa and fed a channel imported in m/s2 gave severity 0 for a whole
    run without a word; its unit is now checked against the channel's kind, and the calibration's
    channels against theirs. A microphone no configuration lists is said to be monitored as a level."""
    recorder_wav(tmp_path / "pair.wav", 20.0, 1.0, 2)
    recorder_wav(tmp_path / "bg.wav", 10.0, 0.0, 3)
    both = ("--unit", "g,Pa", "--scale-factor", f"{ACC_FS_G:g},{MIC_FS_PA:g}", "--names", "acc,mic")
    for name, args in (("pair", both), ("bg", both), ("as_g", ("--unit", "g", "--scale-factor", "50,20",
                                                               "--names", "acc,mic", "--rpm", "1782"))):
        r = cmd("import", "pair.wav" if name == "as_g" else f"{name}.wav", *args, "--out", f"{name}.bin", cwd=tmp_path)
        assert r.returncode == 0, r.stderr
    calib = ("--paired", str(tmp_path / "pair.bin"), "--background", str(tmp_path / "bg.bin"))
    r = run_module("cmsensord.acoustic_calib", *calib, "--accel", "1", "--mic", "0", "--out", str(tmp_path / "x.json"))
    assert (r.returncode, r.stderr.strip()) == (2, f"acoustic_calib: error: {tmp_path / 'pair.bin'}: channel 1 "
                                                   "(--accel) is in Pa by its import, not m/s2: an accelerometer is "
                                                   "imported in m/s2 (cmsensord import --unit, one per channel: g,Pa)")
    r = run_module("cmsensord.acoustic_calib", *calib, "--out", str(tmp_path / "mic.json"))
    assert r.returncode == 0, r.stderr
    site = tmp_path / "mic.yaml"
    site.write_text(f"channels:\n  - {{name: acc, index: 0}}\n  - {{name: mic, index: 1, kind: microphone, "
                    f"calibration: {tmp_path / 'mic.json'}}}\n")
    r = cmsensord_run("replay", "as_g.bin", "--config", "mic.yaml", "--out", "logs", cwd=tmp_path)
    assert (r.returncode, r.stderr.strip()) == (78, (
        "cmsensord: configuration error: mic.yaml: channels[1].kind: microphone, but the capture holds mic in "
        "m/s2 (its import's --unit): a microphone's channel is imported in Pa, an accelerometer's in an "
        "acceleration; re-import it, or set kind (got 'microphone')"))
    r = cmsensord_run("replay", "pair.bin", "--config", "mic.yaml", "--out", "logs", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    said = ("mic: the capture holds it in Pa (a microphone's), monitored here as an accelerometer's level: list it "
            "in --config as kind: microphone with its calibration (python -m cmsensord.acoustic_calib)")
    r = cmsensord_run("replay", "pair.bin", "--out", "auto", cwd=tmp_path)
    assert r.returncode == 0 and r.stderr.splitlines()[0] == f"WARNING {said}", r.stderr
    r = cmsensord_run("calibrate", "pair.bin", "--out", "s.yaml", cwd=tmp_path)
    assert (r.returncode, r.stderr.strip()) == (2, f"cmsensord: calibrate: {said}; calibrate learns it from such a "
                                                   "--config BASE.yaml")
    # the batch orders are the vibration channels', as the daemon's: none for the microphone
    recorder_wav(tmp_path / "pair.wav", 6.0, 1.0, 5)
    r = cmd("import", "pair.wav", *both, "--rpm", "1782", "--out", "run.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = cmsensord_run("vkf", "run.bin", "--config", "mic.yaml", "--out", "vkf", cwd=tmp_path, timeout=300)
    assert r.returncode == 0, r.stderr
    topics = {t for p in (tmp_path / "vkf").glob("*.mcap") for t, _, m in read_messages(p)
              if t.endswith("/orders") and m["method"] == "batch"}
    assert topics == {"/cm/acc/orders"}


def test_a_background_at_another_rate_says_so_not_raw_mode(tmp_path):
    recorder_wav(tmp_path / "pair.wav", 20.0, 1.0, 2)
    recorder_wav(tmp_path / "bg.wav", 10.0, 0.0, 3)
    rate, pcm = wavfile.read(tmp_path / "bg.wav")
    wavfile.write(tmp_path / "bg44.wav", 44100, pcm[:44100 * 10])
    for name in ("pair", "bg44"):
        r = cmd("import", f"{name}.wav", "--unit", "g,Pa", "--scale-factor", "50,20", "--out", f"{name}.bin",
                cwd=tmp_path)
        assert r.returncode == 0, r.stderr
    r = run_module("cmsensord.acoustic_calib", "--paired", str(tmp_path / "pair.bin"), "--background",
                   str(tmp_path / "bg44.bin"), "--out", str(tmp_path / "mic.json"))
    assert r.returncode == 0, r.stderr
    assert ("acoustic_calib: warning: cross term not estimated (the captures hold 480 and 441 samples a block: two "
            "sampling rates): the noise variance is the background's alone and the sound estimate is less accurate; "
            "record (or import) both at one sampling rate to estimate it") in r.stderr


def test_a_unit_as_files_spell_it_and_a_peak_no_sensor_sees(tmp_path):
    """``--unit m/s^2`` (as configurations write it) is m/s2; values of milli-g given as g
    (FEMTO's ~50,000 'g' peaks) get a warning: it went through in silence."""
    x = 50_000.0 * np.sin(np.arange(20000) / 7.0)
    np.save(tmp_path / "x.npy", x)
    p = run_module("cmsensord", "import", str(tmp_path / "x.npy"), "--fs", "2000", "--unit", "g",
                   "--out", str(tmp_path / "g.bin"))
    assert p.returncode == 0, p.stderr
    peak = np.abs(x - x.mean()).max() * G
    assert (f"  WARNING ch: peak {peak:.4g} m/s2 ({peak / G:,.0f} g), more than an accelerometer on a machine "
            "measures: is --unit right (values in mg given as g read 1000 x)?\n") in p.stderr, p.stderr
    p = run_module("cmsensord", "import", str(tmp_path / "x.npy"), "--fs", "2000", "--unit", "mg",
                   "--out", str(tmp_path / "mg.bin"))
    assert p.returncode == 0 and "WARNING" not in p.stderr, p.stderr
    p = run_module("cmsensord", "import", str(tmp_path / "x.npy"), "--fs", "2000", "--unit", "m/s^2",
                   "--out", str(tmp_path / "ms2.bin"))
    assert p.returncode == 0, p.stderr
    assert sidecar(tmp_path / "ms2.bin")["source_unit"] == "m/s2"


def _femto_like(path) -> None:
    """FEMTO's archive layout: ``acc_mg`` int32 (snapshots, 2560, 2) in milli-g, peak 800 mg."""
    t = np.arange(2560) / 25600
    x = np.round(800 * np.sin(2 * np.pi * 160 * t)).astype(np.int32)
    np.savez(path, acc_mg=np.stack([np.stack([x, x // 2], axis=1)] * 3), fs_hz=np.array(25600),
             t_s=np.arange(3) * 10.0)


def test_the_unit_an_array_name_ends_with_is_taken_and_said_and_a_given_unit_wins(tmp_path):
    """``acc_mg`` holds milli-g: without --unit it is read as mg (not m/s², ~100 x off), with a
    note naming the array; a --unit given is taken, with the note that the name says otherwise."""
    _femto_like(tmp_path / "b.npz")
    r = cmd("import", "b.npz", "--channels", "0", "--out", "b.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "  note: unit mg taken from the array name acc_mg; --unit sets another\n" in r.stderr
    assert "assumed" not in r.stderr and "WARNING" not in r.stderr
    meta = sidecar(tmp_path / "b.bin")
    assert meta["source_unit"] == "mg" and meta["channel_names"] == ["acc_mg_0"]
    assert re.search(r"acc_mg_0: full scale \+-\S+ m/s2 \(\S+ m/s2 a count\), peak 7\.84\d+ m/s2", r.stderr)
    r = cmd("import", "b.npz", "--channels", "0", "--unit", "g", "--out", "g.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert sidecar(tmp_path / "g.bin")["source_unit"] == "g"
    assert ("  note: --unit g given, but the array name says mg (acc_mg_0): the values are taken as g; "
            "check --unit\n") in r.stderr


def test_a_variable_name_ending_in_a_unit_gives_it_and_a_velocity_or_an_axis_does_not(tmp_path):
    x = np.sin(np.arange(4096) / 3.0)
    scipy.io.savemat(tmp_path / "v.mat", {"de_ms2": x[:, None], "fe_mm_s": x[:, None], "acc_v": x[:, None]})
    r = cmd("import", "v.mat", "--variable", "de_ms2", "--fs", "4096", "--out", "a.bin", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "  note: unit m/s2 taken from the variable name de_ms2; --unit sets another\n" in r.stderr
    for var in ("fe_mm_s", "acc_v"):
        r = cmd("import", "v.mat", "--variable", var, "--fs", "4096", "--out", f"{var}.bin", cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        assert "  note: unit m/s2 assumed: the file does not say its unit; give --unit" in r.stderr
