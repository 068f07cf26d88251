"""The README's velocity RMS bias of a tone between the bins of 0.1-s records depends on the
tone's phase: a replay of 0.1-s snapshots of 25 and 27.5 Hz sines at four phases reads what an
independent Hann-window periodogram of each snapshot gives (numpy alone), and the biases against
the sine's true velocity RMS are the README's: at 25 Hz +4.8 % (a sine from 0) to +9.8 % (a
cosine), +7.3 % on average; at 27.5 Hz +6.8 % to +7.8 %, +7.3 % on average."""

from __future__ import annotations

import json

import numpy as np
from mcap.reader import make_reader

from processes import run_module

FS = 25600
N = FS // 10
PHASES = np.arange(4) * np.pi / 4            # 0, 45, 90 and 135 degrees (180 more: the same)
TONES = (25.0, 27.5)


def _hann_velocity_mm_s(x: np.ndarray, lo: float = 10.0, hi: float = 1000.0) -> float:
    """Velocity RMS of ``x`` over [lo, hi] Hz from its Hann-windowed one-sided power spectrum,
    each bin divided by (2 pi f)^2 (the standard's rectangular band, both edges in)."""
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(x.size) / x.size)
    X = np.fft.rfft((x - x.mean()) * w)
    f = np.fft.rfftfreq(x.size, 1 / FS)
    P = 2 * np.abs(X) ** 2 / (x.size * np.sum(w ** 2))
    m = (f >= lo) & (f <= hi)
    return 1000 * float(np.sqrt(np.sum(P[m] / (2 * np.pi * f[m]) ** 2)))


def test_the_bias_of_a_tone_between_bins_depends_on_its_phase(tmp_path):
    t = np.arange(N) / FS
    x = np.array([np.sin(2 * np.pi * f * t + p) for f in TONES for p in PHASES])[:, :, None]
    np.save(tmp_path / "tones.npy", x)
    p = run_module("cmsensord", "import", str(tmp_path / "tones.npy"), "--fs", str(FS), "--unit", "m/s2",
                   "--range", "1.2", "--out", str(tmp_path / "t.bin"))
    assert p.returncode == 0, p.stderr
    p = run_module("cmsensord", "replay", str(tmp_path / "t.bin"), "--out", str(tmp_path / "logs"))
    assert p.returncode == 0, p.stderr
    with open(next((tmp_path / "logs").glob("*.mcap")), "rb") as f:
        read = [json.loads(m.data)["velocity_rms_mm_s"] for _, c, m in make_reader(f).iter_messages()
                if c.topic == "/cm/ch/indicators"]
    assert len(read) == len(x)
    reference = [_hann_velocity_mm_s(s[:, 0]) for s in x]
    assert np.allclose(read, reference, rtol=1e-3), (read, reference)
    true = np.repeat([1000 / (2 * np.pi * f) / np.sqrt(2) for f in TONES], len(PHASES))
    bias = (100 * (np.array(reference) / true - 1)).reshape(len(TONES), len(PHASES))
    at25, at27 = bias
    assert (round(at25[0], 1), round(at25.max(), 1), round(at25.mean(), 1)) == (4.8, 9.8, 7.3), bias
    assert round(at25[2], 1) == 9.8 and at25.min() == at25[0], bias
    assert (round(at27.min(), 1), round(at27.max(), 1), round(at27.mean(), 1)) == (6.8, 7.8, 7.3), bias
