"""Orimoto, Ikuta & Wang on simulated data: the paper's Tables 1 and 2, severity from sound, throughput.

    python bench/bench_acoustic.py                         # tables, seeds 1-5, the project's motor
    python bench/bench_acoustic.py --machine broadband     # a machine with broadband vibration
    python bench/bench_acoustic.py --paper-model           # data drawn from the paper's own model
    python bench/bench_acoustic.py --severity 0 1 2 3      # degrading motor heard by the microphone

Tables (the paper's experiment, section 2 "Experiment"): 3000 observations of a
machine in normal condition split into 12 sets of 250; for each set the
estimator (eqs. 6-38, cmsensord.dsp.acoustic) and the EKF of the same model
start from the calibrated prior and run over the set's sound energy z_k.
Table 1: RMS error of the vibration, sqrt(x^_k) against the accelerometer's
block RMS [m/s^2]; Table 2: RMS error of the machine sound, 10 log10(y^_k / y_k)
[dB] against the true machine sound energy (the simulator's, without the
background).  The calibration (cmsensord.acoustic_calib) comes from another
seed: a paired capture of the accelerometer and the microphone and a capture of
the background alone (the machine stopped), through the board's block RMS.

--severity: the degrading motor (``degrading_mic``) through the daemon's
Processor, accelerometer on ch0 and microphone (kind: microphone) on ch1, the
microphone calibrated on another seed's degrading run; per seed the fraction of
1-s decisions whose severity levels agree within one level.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from cmsensord.acoustic_calib import cross_term_variance, fit_model, save_calibration  # noqa: E402
from cmsensord.dsp.acoustic import AcousticEKF, AcousticEstimator  # noqa: E402
from firmware_sim.board import Board, BoardConfig  # noqa: E402
from firmware_sim.scenarios import make_scenario  # noqa: E402

MACHINES = {
    "motor": {},                 # the project's motor (Kim et al. 2023) (tonal: 1x, 2x, 120 Hz)
    "broadband": dict(v1x=0.3, v2x=0.2, v_line=0.1, resonance_noise_rms=0.8),
}
CAL_SEED, BG_SEED = 1000, 1001
SETS, PER_SET = 12, 250


def board_blocks(name: str, seed: int, seconds: float, **params):
    """(accelerometer RMS, microphone RMS, scenario) per 10-ms block, as the daemon sees them."""
    sc = make_scenario(name, n_channels=2, seed=seed, duration_s=seconds, **params)
    board = Board(sc, BoardConfig(n_channels=2, scale=sc.board_scale))
    _, rms = board.observations(int(round(seconds * 100)))
    return rms[:, 0].astype(np.float64), rms[:, 1].astype(np.float64), sc


def mic_samples(name: str, seed: int, seconds: float, n_blocks: int = 2000, **params) -> np.ndarray:
    """Microphone samples [Pa] of ``n_blocks`` blocks spread over the capture, as RAW frames carry
    them (the board's counts, scale and offset): for the cross-term variance of the calibration."""
    sc = make_scenario(name, n_channels=2, seed=seed, duration_s=seconds, **params)
    board = Board(sc, BoardConfig(n_channels=2, scale=sc.board_scale))
    L, total = board.block_len, int(round(seconds * 100))
    out = []
    for start in np.linspace(0, total - 100, n_blocks // 100).astype(int):   # runs of 100 blocks
        counts = board.counts(int(start) * L, 100 * L)[1].astype(np.float64)
        out.append(((counts - board.offset[1]) * board.scale[1]).reshape(100, L))
    return np.concatenate(out)


def calibrate(name: str, seconds: float, bg_seconds: float, cross_term: bool = True, **params):
    """The calibration from a paired capture (seed CAL_SEED) and a background stretch (BG_SEED);
    cross_term: also the cross-term variance from their waveforms (a RAW-mode calibration)."""
    acc, mic, _ = board_blocks(name, CAL_SEED, seconds, **params)
    _, bg, _ = board_blocks(name, BG_SEED, bg_seconds, machine_off=True, **params)
    cross = 0.0
    if cross_term:
        cross = cross_term_variance(mic_samples(name, CAL_SEED, seconds, **params),
                                    mic_samples(name, BG_SEED, bg_seconds, machine_off=True, **params))
    return fit_model(acc ** 2, mic ** 2, bg ** 2, cross_var=cross)


def run_sets(model, x_rms, y, z):
    """Per set: (vibration RMS error, sound dB error) for the estimator, the EKF (y^ its posterior
    mean, y in the state) and the EKF with y^ by eq. (21) from its x^, a^; seconds spent."""
    err = {"est": ([], []), "ekf": ([], []), "ekf21": ([], [])}
    spent = {"est": 0.0, "ekf": 0.0}
    runs = (("est", lambda m: AcousticEstimator(m)), ("ekf", lambda m: AcousticEKF(m)),
            ("ekf21", lambda m: AcousticEKF(m, sound="eq21")))
    for i in range(SETS):
        sl = slice(PER_SET * i, PER_SET * (i + 1))
        for key, make in runs:
            t = time.perf_counter()
            out = make(model).process(z[sl])
            if key in spent:
                spent[key] += time.perf_counter() - t
            xh = np.sqrt(np.maximum(out.x_hat[:, 0], 0.0))
            yh = np.maximum(out.y_hat[:, 0], 1e-12)          # dB of a non-positive estimate: -120 dB
            err[key][0].append(float(np.sqrt(np.mean((xh - x_rms[sl]) ** 2))))
            err[key][1].append(float(np.sqrt(np.mean((10 * np.log10(yh / y[sl])) ** 2))))
    return err, spent


def rms(a) -> float:
    return math.sqrt(float(np.mean(np.square(a))))


def criteria(err) -> tuple:
    """(vibration wins, sound wins, sound wins over the eq.-21 EKF, overall errors, PASS?)."""
    (ex, ey), (kx, ky), (_, k21) = err["est"], err["ekf"], err["ekf21"]
    wx = sum(a < b for a, b in zip(ex, kx))
    wy = sum(a < b for a, b in zip(ey, ky))
    w21 = sum(a < b for a, b in zip(ey, k21))
    ok = wx >= 8 and wy >= 10 and rms(ex) < rms(kx) and rms(ey) < rms(ky)
    return wx, wy, w21, rms(ex), rms(kx), rms(ey), rms(ky), ok


def print_summary(rows) -> bool:
    print("\nSummary: sets where the proposed method has the lower error (of 12), and the RMS over all sets")
    print("| seed | vibration wins | sound wins | (sound wins vs EKF eq. 21) | vibration est / EKF (m/s^2) "
          "| sound est / EKF (dB) | criteria |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: | :---: |")
    for seed, (wx, wy, w21, a, b, c, d, ok) in rows:
        print(f"| {seed} | {wx}/12 | {wy}/12 | {w21}/12 | {a:.4f} / {b:.4f} | {c:.3f} / {d:.3f} | "
              f"{'PASS' if ok else 'FAIL'} |")
    n = len(rows)
    passed = sum(r[-1] for _, r in rows)
    allok = passed == n
    print(f"criteria (vibration >= 8/12 wins, sound >= 10/12 wins, lower overall in both): met for "
          f"{passed}/{n} seeds -> {'PASS' if allok else 'FAIL'}")
    return allok


def print_table(title: str, unit: str, est, ekf, fmt: str, ekf21=None) -> None:
    print(f"\n{title} ({unit})")
    for row in range(3):
        sets = range(4 * row, 4 * row + 4)
        head = " | ".join(f"{PER_SET * s + 1:>4}-{PER_SET * (s + 1):<4}" for s in sets)
        print(f"| {'':<15} | {head} |")
        print(f"| {'Proposed method':<15} | " + " | ".join(f"{est[s]:{fmt}}" for s in sets) + " |")
        print(f"| {'EKF':<15} | " + " | ".join(f"{ekf[s]:{fmt}}" for s in sets) + " |")
        if ekf21 is not None:
            print(f"| {'(EKF, eq. 21)':<15} | " + " | ".join(f"{ekf21[s]:{fmt}}" for s in sets) + " |")


def tables(args) -> bool:
    params = MACHINES[args.machine]
    t = time.perf_counter()
    cal = calibrate("healthy_mic", args.cal_seconds, args.bg_seconds, not args.no_cross_term, **params)
    m, info = cal.model, cal.info
    print(f"machine: {args.machine}; calibration ({time.perf_counter() - t:.1f} s): "
          f"{info['blocks_paired']} paired + {info['blocks_background']} background blocks, a0 = {m.a0:.3f}, "
          f"B22 = {info['B22']:.3f} (model: a0^2 = {m.a0 ** 2:.3f}), F = {m.F:.3f}, "
          f"noise var = {info['noise_var']:.3g} (background {info['background_var']:.3g} + cross term "
          f"{info['cross_var']:.3g}), implied y skewness {info['y_skew']:.2f}, excess kurtosis {info['y_exkurt']:.2f}")
    summary = []
    blocks = 0
    spent = {"est": 0.0, "ekf": 0.0}
    for seed in args.seeds:
        acc, mic, sc = board_blocks("healthy_mic", seed, SETS * PER_SET / 100.0, **params)
        y = sc.sound_energy(SETS * PER_SET)["y"]
        err, sp = run_sets(m, acc, y, mic ** 2)
        for k in spent:
            spent[k] += sp[k]
        blocks += SETS * PER_SET
        (ex, ey), (kx, ky), (_, k21) = err["est"], err["ekf"], err["ekf21"]
        if not args.quiet:
            print(f"\n=== seed {seed}")
            print_table("Table 1: RMS error of vibration", "m/s^2", ex, kx, "9.4f")
            print_table("Table 2: RMS error of sound", "dB", ey, ky, "9.4f", k21)
        summary.append((seed, criteria(err)))
    ok = print_summary(summary)
    print(f"\nthroughput (one channel, 10-ms blocks): estimator {blocks / spent['est']:,.0f} blocks/s "
          f"({blocks / spent['est'] / 100:,.0f}x real time), EKF {blocks / spent['ekf']:,.0f} blocks/s "
          f"({blocks / spent['ekf'] / 100:,.0f}x real time)")
    return ok


def paper_model(args) -> bool:
    """Data drawn from the paper's model: Kibble bivariate-gamma energies (B_rr = a^r), AR(1)."""
    def draw(N, seed, n=4, rho2=0.8, phi2=0.9):
        rng = np.random.default_rng(seed)
        X = np.empty((N, n))
        X[0] = rng.standard_normal(n)
        e = rng.standard_normal((N, n)) * math.sqrt(1 - phi2)
        for k in range(1, N):
            X[k] = math.sqrt(phi2) * X[k - 1] + e[k]
        Y = math.sqrt(rho2) * X + math.sqrt(1 - rho2) * rng.standard_normal((N, n))
        return np.sum(X ** 2, 1) / n, np.sum(Y ** 2, 1) / n, rng.gamma(2.0, 0.25, N)

    x, y, v = draw(100_000, 1)
    _, _, vb = draw(50_000, 2)
    m = fit_model(x, y + v, vb).model
    print("\npaper-model data (x, y energies of 4 correlated Gaussian components, a = 0.8, F = 0.9, "
          "gamma background); vibration in the unit of x")
    rows = []
    for seed in args.seeds:
        x, y, v = draw(SETS * PER_SET, 100 + seed)
        err, _ = run_sets(m, np.sqrt(x), y, y + v)
        rows.append((seed, criteria(err)))
    return print_summary(rows)


def severity(args) -> None:
    from cmsensord.config import config_from_dict
    from cmsensord.monitor.processor import Processor
    from cmsensord.sinks.memory import ListSink
    from cmsensord.source import ByteStreamSource

    dur = args.severity_seconds
    cal = calibrate("degrading_mic", dur, 60.0, not args.no_cross_term)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "mic.json")
        save_calibration(cal, path)
        cfg = config_from_dict({"channels": [{"name": "acc"}, {"name": "mic", "kind": "microphone"}],
                                "acoustic": {"calibration": path}})
        print(f"\ndegrading_mic, {dur:g} s: severity level of the microphone channel (estimator -> AKF "
              "bank) against the accelerometer's, per 1-s decision")
        print("| seed | within one level | equal | accelerometer levels (medians of tenths) | microphone |")
        print("| ---: | ---: | ---: | --- | --- |")
        fr = []
        for seed in args.severity:
            sc = make_scenario("degrading_mic", n_channels=2, seed=seed, duration_s=dur)
            board = Board(sc, BoardConfig(n_channels=2, scale=sc.board_scale))
            sink = ListSink()
            proc = Processor(cfg, sink)
            for frames in ByteStreamSource(board.iter_block_bytes(int(dur * 100))):
                proc.handle(frames)
            proc.finish()
            la = np.array([m["level"] for m in sink.topic("/cm/acc/severity")])
            lm = np.array([m["level"] for m in sink.topic("/cm/mic/severity")])
            tenths = np.array_split(np.arange(la.size), 10)
            w1 = float(np.mean(np.abs(la - lm) <= 1))
            fr.append(w1)
            print(f"| {seed} | {w1:.3f} | {np.mean(la == lm):.3f} | "
                  f"{[int(np.median(la[s])) for s in tenths]} | {[int(np.median(lm[s])) for s in tenths]} |")
        print(f"mean fraction within one level: {np.mean(fr):.3f} over {len(fr)} seeds")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    p.add_argument("--machine", choices=tuple(MACHINES), default="motor")
    p.add_argument("--cal-seconds", type=float, default=600.0)
    p.add_argument("--bg-seconds", type=float, default=300.0)
    p.add_argument("--quiet", action="store_true", help="summary only, no per-seed tables")
    p.add_argument("--paper-model", action="store_true", help="also data drawn from the paper's model")
    p.add_argument("--severity", type=int, nargs="*", default=None, metavar="SEED",
                   help="degrading motor heard by the microphone: severity agreement for these seeds")
    p.add_argument("--severity-seconds", type=float, default=300.0)
    p.add_argument("--no-cross-term", action="store_true",
                   help="calibrate without the cross-term variance (an RMS-mode calibration)")
    args = p.parse_args(argv)
    if args.severity is not None:
        severity(args)
        return 0
    ok = tables(args)
    if args.paper_model:
        ok = paper_model(args) and ok
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
