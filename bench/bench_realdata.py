"""Detection on real degradation: the whole user path on ../shared/realdata.

For each recording: ``cmsensord import`` -> ``cmsensord calibrate`` on the healthy
period -> ``cmsensord replay --config SITE.yaml``, run as a user types them, then
the severity messages of the MCAP log are read back.

FEMTO-ST PRONOSTIA learning bearings (horizontal channel, or ``--axis vertical``, calibrated on the first
20 % of each life): decisions with S_idx > 0 between 20 % and 50 % of life, the
life fraction at which S_idx first reaches 0.1, 0.5 and 1.0, and the analysts'
level rule beside it (one RMS per snapshot, baseline = median of the first 20 %,
alarm at the third consecutive snapshot above 2 x baseline).  Life fraction =
board time / (snapshots x 0.1 s): the import puts the 0.1-s snapshots end to end.

The vibration indicators of the same replays (the site file calibrate wrote:
``indicators.interval_s`` 0.1, one record per FEMTO snapshot, and ``indicators.rpm``, the
speed the import read from the archive): velocity RMS, kurtosis and envelope RMS over
life -- the median of the first 20 % (baseline), around 50 % and of the last 5 %, and the
life fraction at which each first stays above 2 x its baseline for 3 snapshots.

IMS (NASA/Cincinnati): calibrated on the first half of the healthy segment; the
severity of its second half, and the mean severity of each fault segment.

    python bench/bench_realdata.py [--data ../shared/realdata] [--bearings 1_1 2_2]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cmsensord.sinks.mcap_sink import read_messages  # noqa: E402

BEARINGS = ("1_1", "1_2", "2_1", "2_2", "3_1", "3_2")
SNAPSHOT_S = 0.1            # FEMTO: 2560 samples at 25.6 kHz
HEALTHY = 0.2               # calibrated on the first 20 % of life


def cmsensord(*args: str) -> float:
    """Run ``python -m cmsensord ARGS``; CPU seconds of the child. Exit on failure."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    p = subprocess.run([sys.executable, "-m", "cmsensord", *args], capture_output=True, text=True,
                       env=dict(os.environ, PYTHONPATH=str(ROOT)))
    if p.returncode != 0:
        sys.exit(f"bench_realdata: cmsensord {' '.join(args)} failed:\n{p.stderr}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def severity_timeline(out_dir: Path, channel: str, field: str = "severity_index") -> tuple[np.ndarray, np.ndarray]:
    """(board seconds at the end of each decision, the severity ``field``) from the replay's MCAP log."""
    msgs = read_messages(next(out_dir.glob("*.mcap")))
    sev = [(t, m.get(field, 0.0)) for topic, t, m in msgs if topic == f"/cm/{channel}/severity"]
    t = np.array([s[0] for s in sev], dtype=np.float64)
    period = np.median(np.diff(t)) if t.size > 1 else 1e9
    return (t - t[0] + period) / 1e9, np.array([s[1] for s in sev])


def level_rule(snapshot_rms: np.ndarray, healthy: float = HEALTHY) -> float:
    """% of life of the third consecutive snapshot above 2 x the healthy median (NaN: never)."""
    base = np.median(snapshot_rms[: int(healthy * snapshot_rms.size)])
    run = np.convolve((snapshot_rms > 2 * base).astype(int), np.ones(3, int), "valid") == 3
    idx = np.flatnonzero(run)
    return float((idx[0] + 3) / snapshot_rms.size * 100) if idx.size else float("nan")


def first_reached(life: np.ndarray, sev: np.ndarray, level: float) -> float:
    idx = np.flatnonzero(sev >= level - 1e-9)
    return float(life[idx[0]]) if idx.size else float("nan")


#: FEMTO's accelerometers: index in the archive's last axis
AXES = {"horizontal": 0, "vertical": 1}


def femto(data: Path, work: Path, bearing: str, axis: str = "horizontal") -> dict:
    src = data / "femto" / f"Bearing{bearing}.npz"
    d = np.load(src)
    snaps = d["acc_mg"].shape[0]
    rms = np.sqrt(((d["acc_mg"][..., AXES[axis]] / 1000.0) ** 2).mean(axis=1))
    cap, site, out = work / f"B{bearing}.bin", work / f"B{bearing}.yaml", work / f"B{bearing}"
    cpu = cmsensord("import", str(src), "--array", "acc_mg", "--channels", str(AXES[axis]), "--names", axis,
                    "--unit", "mg", "--out", str(cap))
    cpu += cmsensord("calibrate", str(cap), "--to", f"{HEALTHY * snaps * SNAPSHOT_S:g}",
                     "--out", str(site))          # f_r from the rpm the import read from the archive
    text = site.read_text(encoding="utf-8")     # the rpm the import read; the 0.1-s records come from
    assert "  interval_s:" not in text and f"  rpm: {float(d['rpm'])!r}" in text, text  # the capture's sidecar
    cpu += cmsensord("replay", str(cap), "--config", str(site), "--out", str(out))
    t, sev = severity_timeline(out, axis)
    akf = severity_timeline(out, axis, "severity_akf")[1]
    life = t / (snaps * SNAPSHOT_S) * 100
    mid = (life > 20) & (life <= 50)
    rule = level_rule(rms)
    s05 = first_reached(life, sev, 0.5)
    return {"bearing": f"Bearing{bearing}", "snapshots": snaps, "quiet": int(np.count_nonzero(sev[mid] > 0)),
            "s01": first_reached(life, sev, 0.1), "s05": s05, "s10": first_reached(life, sev, 1.0),
            "akf01": first_reached(life, akf, 0.1), "akf05": first_reached(life, akf, 0.5),
            "rule": rule, "diff": s05 - rule, "decision": 100.0 / (snaps * SNAPSHOT_S), "cpu": cpu,
            "trends": indicator_trends(out, axis)}


TRENDS = (("velocity_rms_mm_s", "velocity RMS mm/s"), ("kurtosis", "kurtosis"), ("envelope_rms", "envelope RMS m/s^2"))


def indicator_trends(out_dir: Path, channel: str) -> dict[str, tuple[float, float, float, float]]:
    """Per indicator: (baseline = median of the first 20 % of the records, median of 45-55 %,
    median of the last 5 %, % of life of the 3rd consecutive record above 2 x baseline)."""
    recs = [m for topic, _, m in read_messages(next(out_dir.glob("*.mcap")))
            if topic == f"/cm/{channel}/indicators" and m.get("missing_fraction", 0) == 0]
    out = {}
    for key, _ in TRENDS:
        v = np.array([m.get(key, np.nan) for m in recs], dtype=np.float64)
        n = v.size
        out[key] = (float(np.nanmedian(v[: max(1, n // 5)])), float(np.nanmedian(v[int(0.45 * n):int(0.55 * n) + 1])),
                    float(np.nanmedian(v[int(0.95 * n):])), level_rule(v))
    return out


def ims(data: Path, work: Path) -> list[dict]:
    imp = ("--variable", "data", "--fs", "20480", "--unit", "g", "--names", "bearing")
    caps = {}
    cpu = 0.0
    for name in ("NA", "IF", "OF", "BF"):
        caps[name] = work / f"ims_{name}.bin"
        cpu += cmsensord("import", str(data / "ims" / f"{name}.mat"), *imp, "--out", str(caps[name]))
    site = work / "ims.yaml"
    cpu += cmsensord("calibrate", str(caps["NA"]), "--to", "3", "--rpm", "2000", "--out", str(site))
    rows = []
    for name, cap in caps.items():
        out = work / f"ims_{name}"
        cpu += cmsensord("replay", str(cap), "--config", str(site), "--out", str(out))
        t, sev = severity_timeline(out, "bearing")
        part = sev[t > 3.0 + 1e-6] if name == "NA" else sev
        rows.append({"segment": name + (" (2nd half)" if name == "NA" else ""), "decisions": part.size,
                     "max": float(part.max()), "mean": float(part.mean())})
    rows[0]["cpu"] = cpu
    return rows


def _pct(x: float) -> str:
    return "never" if np.isnan(x) else f"{x:.1f}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "realdata")
    ap.add_argument("--bearings", nargs="*", default=list(BEARINGS))
    ap.add_argument("--no-ims", action="store_true")
    ap.add_argument("--axis", choices=tuple(AXES), default="horizontal",
                    help="the FEMTO accelerometer (the rules were developed on the horizontal one)")
    args = ap.parse_args()
    need = [args.data / "femto" / f"Bearing{b}.npz" for b in args.bearings]
    need += [] if args.no_ims else [args.data / "ims"]
    missing = [p for p in need if not p.exists()]
    if missing:
        print(f"bench_realdata: {missing[0]}: no such file or directory: give --data DIR holding femto/Bearing<n>.npz "
              "and ims/*.mat (the development tree's realdata; docs/references.md says where the sets come from)",
              file=sys.stderr)
        return 2
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="bench_realdata_") as tmp:
        work = Path(tmp)
        print(f"FEMTO learning bearings, {args.axis}, calibrated on the first 20 % of life "
              "(% of life; 'quiet' = decisions with S_idx > 0 in 20-50 %)")
        print("| bearing | snapshots | S>0 in 20-50 % | S>=0.1 | S>=0.5 | S>=1.0 | AKF part >=0.1 | "
              "AKF part >=0.5 | 2x rule | S>=0.5 - rule | 1 decision | CPU s |")
        print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
        femto_rows = []
        for b in args.bearings:
            r = femto(args.data, work, b, args.axis)
            femto_rows.append(r)
            print(f"| {r['bearing']} | {r['snapshots']} | {r['quiet']} | {_pct(r['s01'])} | {_pct(r['s05'])} | "
                  f"{_pct(r['s10'])} | {_pct(r['akf01'])} | {_pct(r['akf05'])} | {_pct(r['rule'])} | "
                  f"{r['diff']:+.1f} | {r['decision']:.2f} | "
                  f"{r['cpu']:.1f} |", flush=True)
        print("\nIndicator trends over life (one record per snapshot): baseline (first 20 %) -> 50 % -> "
              "last 5 %, and the % of life where it first stays above 2 x baseline (3 snapshots)")
        print("| bearing | " + " | ".join(name for _, name in TRENDS) + " |")
        print("| --- |" + " ---: |" * len(TRENDS))
        for r in femto_rows:
            cells = [f"{a:.3g} -> {b:.3g} -> {c:.3g} ({_pct(p)})" for a, b, c, p in
                     (r["trends"][k] for k, _ in TRENDS)]
            print(f"| {r['bearing']} | " + " | ".join(cells) + " |")
        if not args.no_ims:
            print("\nIMS, calibrated on the first half (3 s) of the healthy segment NA")
            print("| segment | decisions | max S_idx | mean S_idx |")
            print("| --- | ---: | ---: | ---: |")
            rows = ims(args.data, work)
            for r in rows:
                print(f"| {r['segment']} | {r['decisions']} | {r['max']:.1f} | {r['mean']:.2f} |")
            print(f"(IMS import + calibrate + replay: {rows[0]['cpu']:.1f} CPU s)")
    print(f"\ntotal wall time {time.monotonic() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
