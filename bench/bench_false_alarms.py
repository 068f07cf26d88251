"""False alarms on healthy machines never seen before, and how early a degrading one alarms.

For each simulated machine (seeds, speeds, sensor noise, channels, RAW or RMS frames, a short or
a long healthy period, a speed change or a slow benign drift after commissioning) this records a
capture of two parts with the simulator (``python -m firmware_sim ... --out``): the healthy
period calibrate learns from, then the machine's months ahead in miniature, healthy; and the
same first part followed by a degrading machine (healthy for a quarter of the second part, then
rising to faulty).  It runs the commands a user types: ``cmsensord calibrate`` on the first part
with the rules of a base configuration (the README's worked example, a severity-index rule, and
rules with short on-delays a user may write: the crest factor at 1.25 x baseline for 2 s, the
peak at 1.15 x for 3 s; in RMS mode the level at 1.1 x for 3 s), then ``cmsensord replay`` of
each whole capture with the site file, and reads the alarm events from the replays' MCAP logs.
Where calibrate advised a level (a thin margin), the healthy capture is calibrated and replayed
once more with the rules' levels as it advised.

Every alert or danger in the healthy capture after the healthy period is false.  The table gives
per machine the hours judged after commissioning, the false alerts and dangers, and the first
alert and danger of the degrading machine after its fault's onset; below it, each false alarm
with its rule, indicator, value and level, and what calibrate said of that rule (a thin margin
and the level it advised).  The rate per machine-month (730 h of running) is extrapolated from
the pooled hours, with the upper 95 % bound of a Poisson count (3 / hours when none is seen).

The captures are written once into ``--work`` and reused; the whole study takes about 5 minutes
on 2 cores.  ``python bench/bench_false_alarms.py [--work DIR] [--jobs 2]``
"""

from __future__ import annotations

import argparse
import math
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

FS = 25000
MONTH_H = 730.0

RAW_BASE = """\
indicators: {machine_group: 2, foundation: rigid}
bearings:
  - {name: de, channel: ch0, elements: 9, ball_diameter: 9.525, pitch_diameter: 46}
alarms:
  operating: {source: speed, running_above: 300, stopped_below: 200, startup_suppress_s: 60,
              coastdown_suppress_s: 30}
  rules:
    - {name: de_velocity, indicator: velocity_rms_mm_s, alert_zone: C, danger_zone: D, on_delay_s: 10,
       off_delay_s: 30}
    - {name: de_velocity_trend, indicator: velocity_rms_mm_s, alert_x_baseline: 2.0, on_delay_s: 60}
    - {name: de_envelope, indicator: envelope_rms, alert_x_baseline: 3.0, danger_x_baseline: 6.0,
       on_delay_s: 30}
    - {name: de_outer_race, indicator: de.bpfo_ratio, alert_x_baseline: 2.0, on_delay_s: 60, latch: true}
    - {name: de_inner_race, indicator: de.bpfi_ratio, alert_x_baseline: 2.0, on_delay_s: 60, latch: true}
    - {name: sev, indicator: severity_index, alert: 0.5, danger: 1.0, on_delay_s: 5}
    - {name: de_crest, indicator: crest_factor, alert_x_baseline: 1.25, on_delay_s: 2}
    - {name: de_peak, indicator: accel_peak, alert_x_baseline: 1.15, on_delay_s: 3}
"""

RMS_BASE = """\
alarms:
  rules:
    - {name: rms_trend, indicator: accel_rms, alert_x_baseline: 2.0, danger_x_baseline: 4.0, on_delay_s: 60}
    - {name: sev, indicator: severity_index, alert: 0.5, danger: 1.0, on_delay_s: 5}
    - {name: rms_step, indicator: accel_rms, alert_x_baseline: 1.1, on_delay_s: 3}
"""

#: calibrate's advice on a rule's level: ``alarm <rule>[/<channel>]: warning: thin margin: ...
#: (alert_x_baseline K or more)``
ADVICE = re.compile(r"^alarm ([^/:]+)\S*: warning: thin margin: .*\((alert|danger)_x_baseline ([0-9.]+) or more\)")


@dataclass
class Machine:
    """One machine: its healthy period (``commission_s``), then ``after_s`` of it healthy (or
    degrading: its fault's onset a quarter into that part), in ``after_parts`` parts whose
    scenario parameters ``drift`` changes (a speed change, a slow benign drift)."""

    name: str
    seed: int
    commission_s: float = 600.0
    after_s: float = 1200.0
    mode: str = "raw"
    channels: int = 1
    params: dict = field(default_factory=dict)
    drift: list = field(default_factory=list)   # per later part: parameters over ``params``

    def parts(self, faulty: bool) -> list[tuple[str, float, dict, int]]:
        """(scenario, seconds, parameters, seed) of each part of the capture."""
        out = [("healthy", self.commission_s, dict(self.params), self.seed)]
        if faulty:
            return out + [("degrading", self.after_s, dict(self.params), self.seed + 1000)]
        steps = self.drift or [{}]
        for k, extra in enumerate(steps):
            out.append(("healthy", self.after_s / len(steps), {**self.params, **extra}, self.seed + 1 + k))
        return out


MACHINES = [
    Machine("raw seed 1", 1),
    Machine("raw seed 2", 2),
    Machine("raw 2-min healthy", 4, commission_s=120.0),
    Machine("raw noisy sensor", 5, params={"noise_rms": 1.0, "wander_amp": 0.2}),
    Machine("raw 1470 rpm", 6, params={"shaft_hz": 24.5}),
    Machine("raw 2940 rpm", 7, params={"shaft_hz": 49.0}),
    Machine("raw 2 channels", 8, channels=2),
    Machine("raw speed -9 % after", 9, drift=[{"shaft_hz": 26.0}]),
    Machine("raw drift +20 %", 10, drift=[{"v1x": 1.6, "noise_rms": 0.37}, {"v1x": 1.7, "noise_rms": 0.39},
                                           {"v1x": 1.8, "noise_rms": 0.42}]),
    Machine("rms 10-min healthy", 11, mode="rms", after_s=3000.0),
    Machine("rms 2-h healthy", 12, mode="rms", commission_s=7200.0, after_s=3600.0),
]


def _run(args: list[str]) -> subprocess.CompletedProcess:
    p = subprocess.run([sys.executable, *args], capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(args)}: exit {p.returncode}: {p.stderr.strip()[-500:]}")
    return p


def record(m: Machine, faulty: bool, work: Path) -> Path:
    """The machine's capture (written once): its parts end to end, the board's sample counter
    running on from one to the next."""
    cap = work / f"{_slug(m.name)}-{'faulty' if faulty else 'healthy'}-{m.seed}.bin"
    if cap.exists():
        return cap
    data, t0 = b"", 0
    for k, (scenario, seconds, params, seed) in enumerate(m.parts(faulty)):
        part = cap.with_suffix(f".part{k}")
        args = ["-m", "firmware_sim", "--scenario", scenario, "--mode", m.mode, "--channels", str(m.channels),
                "--seed", str(seed), "--duration", f"{seconds:g}", "--t0-start", str(t0), "--out", str(part)]
        args += ["--tacho"] if m.mode == "raw" else []
        for key, value in params.items():
            args += ["--param", f"{key}={value}"]
        _run(args)
        data += part.read_bytes()
        part.unlink()
        t0 += round(seconds * FS)
    cap.with_suffix(".tmp").write_bytes(data)
    cap.with_suffix(".tmp").rename(cap)
    return cap


def _slug(name: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-")


def advised(text: str, said: str) -> str:
    """The base configuration ``text`` with the level of each rule calibrate advised on (``said``)
    set as it advised."""
    for line in said.splitlines():
        found = ADVICE.match(line)
        if found:
            rule, which, k = found.groups()
            text = re.sub(rf"(name: {re.escape(rule)},[^\n]*?{which}_x_baseline: )[0-9.]+", rf"\g<1>{k}", text)
    return text


def calibrate(m: Machine, cap: Path, work: Path, said: str = "") -> tuple[Path, str]:
    """Site file and calibrate's printout, commissioned on the first part of ``cap``; with
    ``said`` (calibrate's printout of a first run), the rules' levels as it advised."""
    tag = "-advised" if said else ""
    base = work / f"{_slug(m.name)}-base{tag}.yaml"
    base.write_text(advised(RAW_BASE if m.mode == "raw" else RMS_BASE, said))
    site = work / f"{_slug(m.name)}-site{tag}.yaml"
    p = _run(["-m", "cmsensord", "calibrate", str(cap), "--config", str(base), "--to", f"{m.commission_s:g}",
              "--out", str(site)])
    return site, p.stdout


def alarms(cap: Path, site: Path, out: Path, values: dict | None = None) -> list[tuple[float, str, str, str]]:
    """(board s, kind, alarm, message) of every alarm_alert / alarm_danger of the replay; into
    ``values`` (channel -> list of (board s, indicator values)), its indicator records."""
    from cmsensord.monitor.alarms import indicator_values
    from cmsensord.sinks.mcap_sink import read_messages

    if out.exists():
        for f in out.glob("*"):
            f.unlink()
    _run(["-m", "cmsensord", "replay", str(cap), "--config", str(site), "--out", str(out)])
    t0, found = None, []
    for log in sorted(out.glob("*.mcap")):
        for topic, stamp, msg in read_messages(log):
            if topic == "/cm/events":
                t0 = stamp if t0 is None else t0
            if t0 is None:
                continue
            if values is not None and topic.endswith("/indicators"):
                values.setdefault(topic.split("/")[2], []).append(((stamp - t0) / 1e9, indicator_values(msg)))
            if topic == "/cm/events" and msg.get("kind") in ("alarm_alert", "alarm_danger"):
                found.append(((stamp - t0) / 1e9, msg["kind"][6:], str(msg.get("alarm")), msg.get("message", "")))
    return found


def extrapolated(site: Path, values: dict, after_s: float) -> list[tuple[str, float, int, float]]:
    """Per ``x baseline`` alert rule of ``site`` and channel: (rule/channel, the share p of the
    healthy records after ``after_s`` at its level, the k records in a row its on-delay needs, the
    false alerts a machine-month N p^k, N the records of 730 h, the records taken as independent)."""
    import yaml

    cfg = yaml.safe_load(site.read_text())
    base = {(b["channel"], b["indicator"]): b["value"] for b in cfg["alarms"].get("baselines", [])}
    out = []
    for rule in cfg["alarms"]["rules"]:
        k = rule.get("alert_x_baseline")
        for ch, recs in values.items():
            b = base.get((ch, rule["indicator"]))
            v = [x[rule["indicator"]] for t, x in recs if t > after_s and rule["indicator"] in x]
            if k is None or b is None or len(v) < 2:
                continue
            step = (recs[-1][0] - recs[0][0]) / (len(recs) - 1)
            need = max(1, math.ceil(rule.get("on_delay_s", 0.0) / step - 1e-9))
            share = sum(1 for x in v if x >= k * b) / len(v)
            out.append((f"{rule['name']}/{ch}", share, need, MONTH_H * 3600.0 / step * share ** need))
    return out


def study(m: Machine, work: Path) -> dict:
    """One machine: calibrate, the healthy replay's false alarms, the degrading replay's first."""
    healthy, faulty = record(m, False, work), record(m, True, work)
    site, said = calibrate(m, healthy, work)
    values: dict = {}
    false = [a for a in alarms(healthy, site, work / f"{_slug(m.name)}-h", values) if a[0] > m.commission_s]
    rates = extrapolated(site, values, m.commission_s)
    onset = m.commission_s + 0.25 * m.after_s
    rises = [a for a in alarms(faulty, site, work / f"{_slug(m.name)}-f") if a[0] > m.commission_s]
    first = {kind: next((t - onset for t, k, _, _ in rises if k == kind), None) for kind in ("alert", "danger")}
    again, rates2 = None, None
    if any(ADVICE.match(ln) for ln in said.splitlines()):
        site2, _ = calibrate(m, healthy, work, said)
        values = {}
        again = [a for a in alarms(healthy, site2, work / f"{_slug(m.name)}-a", values) if a[0] > m.commission_s]
        rates2 = extrapolated(site2, values, m.commission_s)
    return dict(machine=m, false=false, first=first, said=said, advised=again, rates=rates, rates2=rates2)


def _fmt_first(t: float | None) -> str:
    return "never" if t is None else f"{t:+.0f}"


def _rate(rates: list | None) -> str:
    """The extrapolated false alerts a machine-month, all rules together."""
    return "-" if rates is None else f"{sum(r[3] for r in rates):.2g}"


def _warned(said: str) -> str:
    """The rules calibrate warned of (thin margin, or shown in the healthy period)."""
    names = dict.fromkeys(ln.split()[1].split("/")[0].rstrip(":") for ln in said.splitlines()
                          if ln.startswith("alarm ") and ": warning:" in ln)
    return ", ".join(names) or "-"


def report(results: list[dict]) -> str:
    lines = ["| machine | healthy s | judged after h | false alerts | false dangers | /machine-month | "
             "extrapolated /machine-month | rules calibrate warned of | false, its advice applied | "
             "extrapolated, its advice applied | degrading: first alert s after onset | first danger s |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: |"]
    hours = n_false = 0.0
    details = []
    for r in results:
        m = r["machine"]
        h = m.after_s / 3600.0
        alerts = sum(1 for a in r["false"] if a[1] == "alert")
        dangers = sum(1 for a in r["false"] if a[1] == "danger")
        hours += h
        n_false += alerts + dangers
        lines.append(f"| {m.name} | {m.commission_s:g} | {h:.2f} | {alerts} | {dangers} | "
                     f"{(alerts + dangers) / h * MONTH_H:.0f} | {_rate(r['rates'])} | {_warned(r['said'])} | "
                     f"{'-' if r['advised'] is None else len(r['advised'])} | {_rate(r['rates2'])} | "
                     f"{_fmt_first(r['first']['alert'])} | "
                     f"{_fmt_first(r['first']['danger'])} |")
        for tag, rates in (("", r["rates"]), ("with calibrate's advice: ", r["rates2"] or [])):
            details += [f"{m.name}: {tag}{name}: {100 * share:.2g} % of the healthy records after commissioning at "
                        f"its level, {need} in a row needed: {month:.2g} false alert(s) a machine-month"
                        for name, share, need, month in rates if month >= 0.01]
        for t, kind, _alarm, message in r["advised"] or []:
            details.append(f"{m.name}: with calibrate's advice: {kind} at {t:.0f} board s: {message}")
        for t, kind, alarm, message in r["false"]:
            warned = [ln for ln in r["said"].splitlines() if ln.startswith(f"alarm {alarm}:")]
            details.append(f"{m.name}: {kind} at {t:.0f} board s: {message}" +
                           (f"\n    calibrate said: {warned[0]}" if warned else "\n    calibrate said nothing of it"))
    upper = (3.0 if n_false == 0 else n_false + 2.0 * math.sqrt(n_false) + 1.0) / hours * MONTH_H
    lines.append(f"\npooled: {n_false:.0f} false alarm(s) in {hours:.1f} h of healthy running after commissioning: "
                 f"{n_false / hours * MONTH_H:.0f} per machine-month (730 h), upper 95 % bound {upper:.0f}")
    return "\n".join(lines + [""] + details)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="/tmp/bench_false_alarms", help="captures and logs (kept, reused)")
    ap.add_argument("--jobs", type=int, default=2, help="machines studied at once")
    ap.add_argument("--only", default="", help="study the machines whose name holds this")
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    chosen = [m for m in MACHINES if args.only in m.name]
    with ThreadPoolExecutor(args.jobs) as pool:
        results = list(pool.map(lambda m: study(m, work), chosen))
    print(report(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
