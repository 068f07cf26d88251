"""Calibration of the acoustic estimator (Orimoto, Ikuta & Wang): learn what the paper assumes known.

The paper takes as known the orthonormal-polynomial coefficients lambda^(1),
lambda^(2) of the vibration x and the machine sound y (eqs. 4-5), the
expansion coefficients e, p (eq. 23), the background-noise moments <v>,
<v^2>, and the time-transition constants F, G of eq. (33).  This module learns
them (docs/acoustic.md §6) from

* a *paired* capture: the accelerometer (x_k = block mean square, (m/s^2)^2) and the
  microphone (z_k = block mean square, Pa^2) running together, and
* a stretch of *background noise alone* (the machine stopped): v_k.

Steps, per block of the board (10 ms by default):

1. lambda^(1) by Schmidt orthogonalisation of 1, x, x^2 under the sample
   moments of x (eq. 4);
2. the regression of z on theta_0, theta_1 of x (E[z|x] = E[y|x] + <v>: alpha0,
   a0 e11) and of its squared residual on theta_0..2 (var(z|x)); no deconvolution;
3. the observation noise: var v of the background stretch plus the variance of
   the per-block cross term of machine sound and background
   (:func:`cross_term_variance`, from waveforms: RAW captures; 0 when not given,
   and :func:`fit_captures` warns that it was not estimated from RMS captures);
4. the split var z = e11^2 + noise gives e11, a0 = (a0 e11)/e11, then e10, p of
   eq. (23) so that the model's <z|x,a0>, var(z|x,a0) are the fitted ones, and
   lambda^(2) from the moments of y they imply (docs §6);
5. F = the lag-1 autocorrelation coefficient of x (over consecutive blocks
   only), G = sqrt((1 - F^2) var x), <u> = (1 - F) <x> / G (eq. 33, docs §5);
6. <v> from the background stretch, <v^2> = <v>^2 + var v + cross term;
7. the initial prior: x* = <x>, Gamma_x = var x, a* = a0,
   Gamma_a = (``a_rel_std`` a0)^2.

The result is written to a JSON file (:func:`save_calibration`) that the
daemon's configuration points to (``acoustic.calibration``), read back by
:func:`load_calibration`, which raises :class:`~cmsensord.errors.ConfigError`
with a one-line message naming the file and the key for a bad file.  The file
format, :class:`Calibration`, :func:`save_calibration` and :func:`load_calibration`
live in :mod:`cmsensord.acoustic_model` (what the daemon needs at run time) and
are re-exported here.

Command line (captures as written by ``cmsensord record`` or firmware_sim)::

    python -m cmsensord.acoustic_calib --paired pair.bin --background bg.bin \\
        --accel 0 --mic 1 --out acoustic.json
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

import numpy as np

from cmsensord import __version__
from cmsensord.acoustic_model import FORMAT, VERSION, Calibration, load_calibration, save_calibration
from cmsensord.dsp.acoustic import AcousticModel
from cmsensord.importing.sidecar import channel_units, sidecar
from cmsensord.out_paths import overwritten_input, with_sidecars

__all__ = [
    "FORMAT",
    "VERSION",
    "Calibration",
    "schmidt",
    "fit_model",
    "cross_term_variance",
    "blocks_from_capture",
    "fit_captures",
    "save_calibration",
    "load_calibration",
    "main",
]

#: fewest blocks of each kind a calibration accepts (fourth moments need many)
MIN_BLOCKS = 500
#: |a0| is kept below this (a correlation coefficient; above it the model's var(y|x) < 0)
A_MAX = 0.98


def schmidt(moments) -> np.ndarray:
    """lambda (3x3, lower triangular) of theta_0..2 orthonormal under raw moments <x^j>, j = 0..4.

    Eqs. (4)-(5): theta_0 = 1, theta_1 = (x - mu)/sigma,
    theta_2 = (x^2 - <x^2> - <x^2 theta_1> theta_1) / norm.  Raises ValueError
    when the moments are not those of a distribution with at least 3 points.
    """
    m = [float(v) for v in moments]
    mu = m[1]
    var = m[2] - mu * mu
    if not var > 0:
        raise ValueError(f"variance {var:.3g} is not positive")
    s = math.sqrt(var)
    lam = np.zeros((3, 3))
    lam[0, 0] = 1.0
    lam[1, 0], lam[1, 1] = -mu / s, 1.0 / s
    c0 = m[2]                                    # <x^2 theta_0>
    c1 = lam[1, 0] * m[2] + lam[1, 1] * m[3]     # <x^2 theta_1>
    n2 = m[4] - c0 * c0 - c1 * c1
    if not n2 > 1e-12 * m[4]:
        raise ValueError("fourth moment too small for a second-order polynomial (kurtosis <= skewness^2 + 1)")
    N = math.sqrt(n2)
    lam[2, 2] = 1.0 / N
    lam[2, 1] = -c1 * lam[1, 1] / N
    lam[2, 0] = (-c0 - c1 * lam[1, 0]) / N
    return lam


def _consecutive_lag1(x: np.ndarray, t: np.ndarray | None) -> float:
    xc = x - x.mean()
    pairs = np.ones(x.size - 1, dtype=bool) if t is None else np.diff(t) == 1
    if pairs.sum() < 10:
        raise ValueError("fewer than 10 pairs of consecutive blocks: F of eq. (33) cannot be estimated")
    num = float(np.mean(xc[1:][pairs] * xc[:-1][pairs]))
    return num / float(np.mean(xc * xc))


def cross_term_variance(paired, background, *, max_blocks: int = 4000) -> float:
    """Variance of the per-block cross term 2<p_m p_b> between machine sound and background [Pa^4].

    z = y + v + 2<p_m p_b>_block: over one block the product of the machine's sound pressure
    p_m and the background's p_b does not average out (docs §6).  It is zero-mean and
    uncorrelated with x and y, but it is observation noise the background stretch cannot
    show.  From the waveforms (RAW mode), blocks of samples [Pa], shape (n, L): for
    independent blocks P of the paired capture (p_m + p_b) and Q, Q' of the background,
    E[(2<P Q>)^2] - E[(2<Q Q'>)^2] = (4/L^2) sum_ij R_m(i, j) R_b(i, j) = var of the cross term
    (the background's own autocorrelation cancels).  Pairs are formed between the captures
    (P with every Q) and between the two halves of the background capture.
    """
    P = np.asarray(paired, dtype=np.float64)
    Q = np.asarray(background, dtype=np.float64)
    if P.ndim != 2 or Q.ndim != 2 or P.shape[1] != Q.shape[1]:
        raise ValueError(f"cross term: expected sample blocks (n, L) of one length, got {P.shape} and {Q.shape}")
    if P.shape[0] < 100 or Q.shape[0] < 200:
        raise ValueError(f"cross term: need >= 100 paired and >= 200 background blocks of samples, "
                         f"got {P.shape[0]} and {Q.shape[0]}")
    if not (np.all(np.isfinite(P)) and np.all(np.isfinite(Q))):
        raise ValueError("cross term: samples must be finite")
    L = P.shape[1]
    P = P[np.linspace(0, P.shape[0] - 1, min(P.shape[0], max_blocks)).astype(np.int64)]
    Q = Q[np.linspace(0, Q.shape[0] - 1, min(Q.shape[0], max_blocks)).astype(np.int64)]
    h = Q.shape[0] // 2

    def msq(A, B):
        G = (2.0 / L) * (A @ B.T)
        return float(np.mean(G * G))

    return max(msq(P, Q) - msq(Q[:h], Q[h:2 * h]), 0.0)


def fit_model(x, z, v, *, t=None, block_s: float = 0.01, a_rel_std: float = 0.1,
              cross_var: float = 0.0) -> Calibration:
    """Fit the model of Orimoto, Ikuta & Wang from arrays (the steps of the module docstring, docs §6).

    x: vibration (accelerometer block mean square) and z: sound energy of the same
    blocks (paired capture); v: sound energy of blocks of background noise alone;
    t: optional block indices of the paired blocks (gaps are lost blocks, F uses
    consecutive blocks only); cross_var: variance of the per-block cross term of
    machine sound and background (:func:`cross_term_variance`, from RAW captures;
    0 when unknown).  Raises ValueError with a one-line reason.
    """
    x, z, v, t, cross_var = _checked_inputs(x, z, v, t, a_rel_std, cross_var)
    info: dict[str, Any] = {"blocks_paired": int(x.size), "blocks_background": int(v.size),
                            "method": "regression", "warnings": []}
    # 1. lambda^(1)
    mx = [float(np.mean(x ** j)) for j in range(5)]
    try:
        lam1 = schmidt(mx)
    except ValueError as exc:
        raise ValueError(f"vibration x: {exc}") from None
    # 2.-4. the machine sound and the observation noise
    snd = _fit_sound(x, z, v, lam1, cross_var, info)
    e10, e11, a0 = snd["e10"], snd["e11"], snd["a0"]
    # 5. F, G, <u> of eqs. (32)-(34)
    F = _consecutive_lag1(x, t)
    F = min(max(F, -0.999), 0.999)
    var_x = float(np.var(x))
    G = math.sqrt((1.0 - F * F) * var_x)
    u_mean = (1.0 - F) * float(np.mean(x)) / G
    info.update(x_mean=float(np.mean(x)), x_std=math.sqrt(var_x), y_mean=e10, y_std=e11,
                v_mean=snd["v1"], v_std=math.sqrt(snd["var_v"]), corr_xz=float(np.corrcoef(x, z)[0, 1]))
    model = AcousticModel(lam1=tuple(map(tuple, lam1.tolist())), lam2=snd["lam2"], e10=e10, e11=e11,
                          p20=snd["p20"], p21=snd["p21"], p22=snd["p22"], v1=snd["v1"],
                          v2=snd["v1"] * snd["v1"] + snd["noise"], F=F, G=G,
                          u_mean=u_mean, x0=float(np.mean(x)), gx0=var_x, a0=a0, ga0=(a_rel_std * a0) ** 2,
                          block_s=block_s)
    return Calibration(model=model, info=info)


def _checked_inputs(x, z, v, t, a_rel_std, cross_var):
    """The arguments of :func:`fit_model` as arrays (x, z, v float64, t int64 or None) and a float
    cross_var; ValueError with a one-line reason for a bad one."""
    x = np.asarray(x, dtype=np.float64).ravel()
    z = np.asarray(z, dtype=np.float64).ravel()
    v = np.asarray(v, dtype=np.float64).ravel()
    if x.shape != z.shape:
        raise ValueError(f"x and z must have the same length, got {x.size} and {z.size}")
    if t is not None:
        t = np.asarray(t, dtype=np.int64).ravel()
        if t.shape != x.shape or np.any(np.diff(t) <= 0):
            raise ValueError("t must be increasing block indices, one per paired block")
    for name, a in (("x", x), ("z", z), ("v", v)):
        if a.size < MIN_BLOCKS:
            raise ValueError(f"{name}: need at least {MIN_BLOCKS} blocks, got {a.size}")
        if not np.all(np.isfinite(a)) or np.any(a < 0):
            raise ValueError(f"{name}: blocks must be finite and >= 0")
    if not (a_rel_std > 0 and math.isfinite(a_rel_std)):
        raise ValueError(f"a_rel_std must be > 0, got {a_rel_std!r}")
    if isinstance(cross_var, bool) or not (math.isfinite(float(cross_var)) and float(cross_var) >= 0):
        raise ValueError(f"cross_var must be a finite number >= 0, got {cross_var!r}")
    return x, z, v, t, float(cross_var)


def _fit_sound(x, z, v, lam1, cross_var: float, info: dict) -> dict:
    """Steps 2-4 of the module docstring: the observation noise, the regression of z on theta(x),
    the split of var z between machine sound and noise, and p, lambda^(2) of eq. (23) (docs §6).

    Returns e10, e11, a0, p20, p21, p22, lam2, v1 (<v>), var_v (of the background stretch) and
    noise (the observation noise variance); adds the diagnostics and any warning to ``info``.
    """
    th1 = lam1[1, 0] + lam1[1, 1] * x
    th2 = lam1[2, 0] + lam1[2, 1] * x + lam1[2, 2] * x * x
    g1, g2 = float(np.mean(th1 ** 3)), float(np.mean(th1 * th1 * th2))   # theta1^2 = 1 + g1 theta1 + g2 theta2
    # 2. the observation noise: the background's moments plus the cross term
    v1 = float(np.mean(v))
    var_v = float(np.var(v))
    noise = var_v + cross_var
    # 3. the regression of z on theta(x): <z|x> = alpha0 + a e11 theta1(x) (least squares in an
    #    orthonormal basis = projection), and of the squared residual: var(z|x) = c0 + c1 theta1 + c2 theta2
    alpha0 = float(np.mean(z))
    b = float(np.mean(th1 * z))                     # a e11
    r2 = (z - alpha0 - b * th1) ** 2
    c0, c1, c2 = float(np.mean(r2)), float(np.mean(th1 * r2)), float(np.mean(th2 * r2))
    e10 = alpha0 - v1
    var_y = c0 + b * b - noise                      # var z = e11^2 + noise
    if not e10 > 0 or not var_y > 0:
        raise ValueError(f"the machine sound is not identifiable: mean {e10:.3g} and variance {var_y:.3g} "
                         "of z - v must be > 0 (the background stretch is louder or more variable than "
                         "the background during the paired capture)")
    e11 = math.sqrt(var_y)
    a0 = b / e11                                    # B_11 = corr(theta1(x), theta1(y))
    if abs(a0) > A_MAX:
        info["warnings"].append(f"a0 = {a0:.3f} clipped to {math.copysign(A_MAX, a0)}: the background "
                                "stretch does not represent the background of the paired capture")
        a0 = math.copysign(A_MAX, a0)
        e11 = abs(b) / A_MAX
        noise = max(c0 + b * b - e11 * e11, 0.0)
    if a0 == 0:
        raise ValueError("the sound does not follow the vibration: <theta1(x) z> = 0")
    # 4. p of eq. (23) from the model's <z^2|x, a0> = var(z|x) + <z|x>^2 (docs §6)
    p21 = (c1 + 2.0 * alpha0 * b + b * b * g1) / a0 - 2.0 * e11 * v1
    p22 = (c2 + b * b * g2) / (a0 * a0)
    if not p22 > 0:
        raise ValueError(f"the conditional variance of z given x has no admissible second-order part "
                         f"(a0^2 p22 = {c2 + b * b * g2:.3g} <= 0)")
    p20 = e10 * e10 + e11 * e11
    # the moments of y these imply (y = e10 + e11 theta1(y), y^2 = p20 + p21 theta1(y) + p22 theta2(y))
    my = [1.0, e10, p20, e11 * p21 + e10 * p20, p22 * p22 + p20 * p20 + p21 * p21]
    lam2 = schmidt(my)
    mu3 = my[3] - 3 * e10 * my[2] + 2 * e10 ** 3
    mu4 = my[4] - 4 * e10 * my[3] + 6 * e10 ** 2 * my[2] - 3 * e10 ** 4
    b22 = float(lam2[2, 2] * (np.mean(th2 * z * z) - 2.0 * v1 * np.mean(th2 * z)))
    info.update(B11=a0, B22=b22, a0_squared=a0 * a0, y_skew=mu3 / e11 ** 3, y_exkurt=mu4 / e11 ** 4 - 3.0,
                curvature=float(np.mean(th2 * z)), residual_var=c0, noise_var=noise, background_var=var_v,
                cross_var=cross_var)
    return {"e10": e10, "e11": e11, "a0": a0, "p20": p20, "p21": p21, "p22": p22, "lam2": lam2,
            "v1": v1, "var_v": var_v, "noise": noise}


# ---------------------------------------------------------------------------
# captures -> blocks
# ---------------------------------------------------------------------------


def blocks_from_capture(path, channels, *, chunk: int = 1 << 20, samples_of: int | None = None,
                        max_sample_blocks: int = 4000):
    """Per-block RMS of the given board channels from a capture file (RMS or RAW mode).

    Returns (block index int64 (n,), rms float64 (n, len(channels)), block_s):
    only blocks where every requested channel arrived; the RMS is the daemon's
    (docs/PROTOCOL.md RMS frames, or :func:`cmsensord.dsp.rms.rows_rms` of RAW
    blocks with the STATUS scale/offset), so z = rms^2 matches what the
    daemon computes.  Raises ValueError naming the file.

    samples_of: a channel (one of ``channels``) whose samples are wanted as well; a fourth
    item is then returned: float64 (m, block_len) physical samples ``(count - offset) * scale``
    (:func:`cmsensord.dsp.rms.rows_physical`) of at most ``max_sample_blocks`` of the returned
    blocks, evenly spread (as :func:`cross_term_variance` would pick them), or None when the
    capture carries no RAW blocks (RMS mode).
    """
    channels = [int(c) for c in channels]
    if samples_of is not None and int(samples_of) not in channels:
        raise ValueError(f"samples_of: channel {samples_of} is not one of {channels}")
    status, rms_rows, raw = _read_capture(path, channels, chunk)
    L = status.block_len
    samples = None
    if raw:
        t0, out, samples = _raw_block_rms(path, status, raw, channels, samples_of, max_sample_blocks)
    else:
        t0 = np.array(sorted(rms_rows), dtype=np.int64)
        out = np.array([rms_rows[t] for t in t0]) if t0.size else np.empty((0, len(channels)))
    if t0.size == 0:
        raise ValueError(f"{path}: no blocks of channel(s) {channels}")
    if samples_of is not None:
        return (t0 - t0[0]) // L, out, L / status.fs, samples
    return (t0 - t0[0]) // L, out, L / status.fs


def _read_capture(path, channels: list[int], chunk: int):
    """A capture's STATUS, the RMS rows of ``channels`` by t0 and the RAW payloads by t0 and
    channel; bad payloads are skipped.  ValueError for a capture that is not one board set-up
    (:class:`~cmsensord.one_setup.OneSetup`)."""
    from cmsensord.errors import LinkError
    from cmsensord.one_setup import OneSetup
    from cmsensord.protocol import FrameType, decode_rms
    from cmsensord.source import CaptureSource

    setup = OneSetup()
    rms_rows: dict[int, np.ndarray] = {}
    raw: dict[int, dict[int, bytes]] = {}
    try:
        source = CaptureSource(path, chunk=chunk)
    except LinkError as exc:
        raise ValueError(str(exc)) from None
    with source:
        for frames in source:
            for fr in frames:
                setup.see(fr)
                if fr.type == FrameType.RMS:
                    try:
                        vals = decode_rms(fr)
                    except ValueError:
                        continue
                    if max(channels) < vals.size:
                        rms_rows[fr.t0_unwrapped] = vals[channels].astype(np.float64)
                elif fr.type == FrameType.RAW and fr.chan in channels:
                    raw.setdefault(fr.t0_unwrapped, {})[fr.chan] = fr.payload
    if setup.status is None:
        raise ValueError(f"{path}: no STATUS frame (block length and scale unknown)")
    if setup.changed is not None:
        raise ValueError(f"{path}: the board {setup.changed}: the acoustic calibration needs one board "
                         "set-up for the whole capture (cut the capture at that byte)")
    return setup.status, rms_rows, raw


def _raw_block_rms(path, status, raw: dict[int, dict[int, bytes]], channels: list[int],
                   samples_of: int | None, max_sample_blocks: int):
    """(t0 of the RAW blocks where every channel arrived whole, their RMS (n, C), the physical
    samples of ``samples_of`` in at most ``max_sample_blocks`` of them or None)."""
    from cmsensord.dsp.rms import rows_physical, rows_rms

    L = status.block_len
    samples = None
    scale = np.asarray(status.scale, dtype=np.float32)
    offset = np.asarray(status.offset, dtype=np.float32)
    if max(channels) >= len(scale):
        raise ValueError(f"{path}: channel {max(channels)} not in the board's {len(scale)}")
    t0s = sorted(t for t, d in raw.items() if all(c in d and len(d[c]) == 2 * L for c in channels))
    out = np.empty((len(t0s), len(channels)))
    for j, c in enumerate(channels):
        counts = np.stack([np.frombuffer(raw[t][c], dtype="<u2") for t in t0s]) if t0s else \
            np.empty((0, L), dtype=np.uint16)
        out[:, j] = rows_rms(counts, np.full(len(t0s), scale[c]), np.full(len(t0s), offset[c]))
        if c == samples_of and t0s:
            pick = np.linspace(0, len(t0s) - 1, min(len(t0s), max_sample_blocks)).astype(np.int64)
            samples = rows_physical(counts[pick], np.full(pick.size, scale[c]), np.full(pick.size, offset[c]))
    return np.array(t0s, dtype=np.int64), out, samples


#: the warning of a calibration from captures without RAW blocks of the microphone (docs §6)
NO_CROSS_TERM = ("cross term not estimated ({why}): the noise variance is the background's alone and "
                 "the sound estimate is less accurate; {fix} to estimate it")
#: ... its fix: RMS captures, or RAW captures at two rates
IN_RAW, AT_ONE_RATE = "record the captures in RAW mode", "record (or import) both at one sampling rate"


def _units_fit(path, wanted: dict[int, tuple[str, str]]) -> None:
    """A ValueError when an imported capture's sidecar gives a channel of ``wanted`` (channel ->
    (its option, the unit it must be in)) another unit: a microphone imported as if in g would
    be calibrated 9.8 x too loud, without a word."""
    units = channel_units(sidecar(path))
    for c, (option, unit) in wanted.items():
        if c < len(units) and units[c] != unit:
            raise ValueError(f"{path}: channel {c} ({option}) is in {units[c]} by its import, not {unit}: "
                             f"{'a microphone' if unit == 'Pa' else 'an accelerometer'} is imported in {unit} "
                             "(cmsensord import --unit, one per channel: g,Pa)")


def fit_captures(paired, background, *, accel: int = 0, mic: int = 1, mic_background: int | None = None,
                 **kwargs) -> Calibration:
    """Fit from a paired capture (accelerometer ``accel``, microphone ``mic``) and a capture of
    background noise alone (microphone channel ``mic_background``, default ``mic``).

    When both captures carry RAW blocks of the microphone, the variance of the cross term of
    machine sound and background is estimated from them (:func:`cross_term_variance`, docs §6)
    and passed to :func:`fit_model`; otherwise (RMS mode) it is 0 and ``info["warnings"]`` says
    so in one line.  An explicit ``cross_var`` keyword overrides both.
    """
    mic_bg = mic if mic_background is None else mic_background
    _units_fit(paired, {accel: ("--accel", "m/s2"), mic: ("--mic", "Pa")})
    _units_fit(background, {mic_bg: ("--mic-background" if mic_background is not None else "--mic", "Pa")})
    t, rms, block_s, p_samples = blocks_from_capture(paired, [accel, mic], samples_of=mic)
    _, bg, block_bg, q_samples = blocks_from_capture(background, [mic_bg], samples_of=mic_bg)
    if abs(block_s - block_bg) > 1e-12:
        raise ValueError(f"the captures have different blocks: {block_s * 1e3:g} ms and {block_bg * 1e3:g} ms")
    warning = None
    if "cross_var" not in kwargs:
        if p_samples is None or q_samples is None:
            which = [name for name, s in (("paired", p_samples), ("background", q_samples)) if s is None]
            warning = NO_CROSS_TERM.format(why=f"no RAW blocks of the microphone in the {' and '.join(which)} "
                                               f"capture{'s' if len(which) > 1 else ''}", fix=IN_RAW)
            kwargs["cross_var"] = 0.0
        elif p_samples.shape[1] != q_samples.shape[1]:
            warning = NO_CROSS_TERM.format(why=f"the captures hold {p_samples.shape[1]} and {q_samples.shape[1]} "
                                               "samples a block: two sampling rates", fix=AT_ONE_RATE)
            kwargs["cross_var"] = 0.0
        else:
            try:
                kwargs["cross_var"] = cross_term_variance(p_samples, q_samples)
            except ValueError as exc:
                warning = NO_CROSS_TERM.format(why=str(exc), fix=IN_RAW)
                kwargs["cross_var"] = 0.0
    # x and z are block mean squares ((m/s²)², Pa²), as fit_model documents: the squared RMS
    cal = fit_model(rms[:, 0] ** 2, rms[:, 1] ** 2, bg[:, 0] ** 2, t=t, block_s=block_s, **kwargs)
    if warning is not None:
        cal.info["warnings"].insert(0, warning)
    cal.info.update(paired=str(paired), background=str(background), accel_channel=accel, mic_channel=mic,
                    cross_term_estimated=warning is None)
    return cal


# ---------------------------------------------------------------------------
# command line
# ---------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m cmsensord.acoustic_calib",
        description="Fit the acoustic estimator of Orimoto, Ikuta & Wang (vibration from microphone "
                    "sound) from a paired accelerometer + microphone capture and a capture of "
                    "background noise alone.")
    p.add_argument("--version", action="version", version=f"cmsensord.acoustic_calib (cmsensord {__version__})")
    p.add_argument("--paired", required=True, help="capture with the accelerometer and the microphone")
    p.add_argument("--background", required=True, help="capture of background noise alone (machine stopped)")
    p.add_argument("--accel", type=int, default=0, help="accelerometer channel of the paired capture (0)")
    p.add_argument("--mic", type=int, default=1, help="microphone channel of the paired capture (1)")
    p.add_argument("--mic-background", type=int, default=None,
                   help="microphone channel of the background capture (default: --mic)")
    p.add_argument("--a-rel-std", type=float, default=0.1,
                   help="initial uncertainty of a, relative to a0 (default 0.1)")
    p.add_argument("--out", required=True, help="calibration file to write (JSON)")
    args = p.parse_args(argv)
    same = overwritten_input(args.out, with_sidecars([args.paired, args.background]))
    if same:
        print(f"acoustic_calib: error: {same}", file=sys.stderr)
        return 2
    try:
        cal = fit_captures(args.paired, args.background, accel=args.accel, mic=args.mic,
                           mic_background=args.mic_background, a_rel_std=args.a_rel_std)
        save_calibration(cal, args.out)
    except ValueError as exc:
        print(f"acoustic_calib: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"acoustic_calib: error: cannot write {args.out}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    i = cal.info
    m = cal.model
    print(f"wrote {args.out}: {i['blocks_paired']} paired + {i['blocks_background']} background blocks of "
          f"{m.block_s * 1e3:g} ms; a0 = {m.a0:.3f} (B22 = {i['B22']:.3f} vs a0^2 = {i['a0_squared']:.3f}), "
          f"F = {m.F:.3f}, noise var {i['noise_var']:.3g} (background {i['background_var']:.3g} + cross term "
          f"{i['cross_var']:.3g}{'' if i.get('cross_term_estimated') else ', not estimated'})")
    for w in i["warnings"]:
        print(f"acoustic_calib: warning: {w}", file=sys.stderr)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
