"""``cmsensord calibrate``: commission the monitor from a machine's healthy period.

Reads a capture through the daemon's own path (``cmsensord.observations``),
learns per channel what the monitor needs (``dsp.commissioning``), prints a table
of what it measured and chose, and writes SITE.yaml: a commented overlay that
``--config SITE.yaml`` loads on top of the defaults (or of ``--config BASE``).
The same input gives the same file.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from cmsensord.alarm_margins import thin_margins
from cmsensord.alarms import Judged
from cmsensord.argtypes import board_time, positive
from cmsensord.base_changes import replaced_baselines, unlisted_channels
from cmsensord.calibrate_bounds import FEW_DECISIONS, every_channels_bound, level_warning, rise_warning
from cmsensord.capture_print import capture_print
from cmsensord.config import Config, ConfigError, load_config
from cmsensord.config.alarm_indicators import indicator_names
from cmsensord.config.channel_refs import channel_refs_error
from cmsensord.config.settings import MAX_DECISION_PERIOD_S, decision_period_for
from cmsensord.dsp.commissioning import MARGIN, SPAN, STOPPED_SHARE, HealthyModel, learn_healthy
from cmsensord.errors import CmsensordError
from cmsensord.importing.capture_settings import capture_settings
from cmsensord.monitor.alarms import order_rules
from cmsensord.observations import Observations, alarm_events, read_observations, sidecar
from cmsensord.out_paths import not_a_file, overwritten_input, with_sidecars
from cmsensord.service.origin import delay_lines, origin_lines, span_line

__all__ = ["ChannelResult", "add_calibrate_parser", "alarm_lines", "calibrate", "format_table", "run_calibrate",
           "site_yaml"]


@dataclass(frozen=True)
class ChannelResult:
    """One channel's commissioning: the learned model and where f_r came from."""

    name: str
    index: int
    f_r: float
    f_r_source: str
    model: HealthyModel
    decision_s: float = 1.0      # seconds of board time a decision period
    level_alert: float | None = None  # the combined severity's level / baseline alert (None: paper)


def _f_r(obs: Observations, c: int, cfg: Config, rpm: float | None) -> tuple[float, str]:
    """f_r of channel c: --rpm, else the tacho's mean speed, else the configuration's
    indicators.rpm (the indicators' speed too), else the capture's rpm, else the configuration's
    monitor.f_r."""
    if rpm is not None:
        return rpm / 60.0, f"--rpm {rpm:g}"
    if obs.shaft_hz is not None and np.isfinite(obs.shaft_hz):
        return float(obs.shaft_hz), "tacho"
    if cfg.indicators.rpm is not None:
        return cfg.indicators.rpm / 60.0, f"indicators.rpm {cfg.indicators.rpm:g}"
    if obs.rpm is not None:
        return obs.rpm / 60.0, f"capture rpm {obs.rpm:g}"
    return float(_monitor(cfg, obs.names[c]).f_r), "config"


def _monitor(cfg: Config, name: str):
    try:
        return cfg.channel(name).monitor
    except KeyError:
        return cfg.monitor


def calibrate(obs: Observations, cfg: Config, *, faulty: Observations | None = None,
              rpm: float | None = None) -> list[ChannelResult]:
    """Learn every channel of ``obs`` (already cut to the healthy period)."""
    results = []
    for c, name in enumerate(obs.names):
        mon = _monitor(cfg, name)
        period = obs.period(mon.decision_period_s)
        f_r, source = _f_r(obs, c, cfg, rpm)
        if f_r >= period:
            longer = decision_period_for(f_r, obs.rate_hz)
            advice = (f"for a machine this fast give a longer decision: monitor: {{decision_period_s: {longer:g}}} "
                      "in --config BASE.yaml") if longer is not None else (
                f"no decision_period_s up to {MAX_DECISION_PERIOD_S:g} fits a machine this fast (f_r below "
                f"{MAX_DECISION_PERIOD_S * obs.rate_hz:g} Hz, {MAX_DECISION_PERIOD_S * obs.rate_hz * 60:g} rpm)")
            raise ConfigError(
                "calibrate", f"{name}.f_r",
                f"{f_r:.4g} Hz must be below the {period} observations per decision "
                f"({obs.rate_hz:.4g} blocks/s x decision_period_s {mon.decision_period_s:g}); {advice}")
        if name in obs.no_signal:
            raise CmsensordError(
                f"calibrate: channel {name}: no signal in the healthy period: {obs.no_signal[name]}: nothing to "
                "learn; choose a period where it works, or leave it out (import --channels, or a --config "
                "BASE.yaml listing the channels to learn)")
        _long_enough(obs, c, period)
        fy = faulty.y[:, faulty.names.index(name)] if faulty is not None and name in faulty.names else None
        alert = None if mon.severity == "paper" else mon.level_alert
        try:
            model = learn_healthy(obs.y[:, c], f_r=f_r, period=period, n=mon.n, window=mon.window,
                                  z_c=mon.z_c, p0=mon.p0, q0=mon.q0, faulty=fy, level_alert=alert, c=mon.c)
        except ValueError as exc:
            raise CmsensordError(f"calibrate: channel {name}: {exc}") from None
        results.append(ChannelResult(name, obs.indices[c], f_r, source, model, period / obs.rate_hz, alert))
    return results


def _long_enough(obs: Observations, c: int, period: int) -> None:
    """A one-line error, with the period that would do, when channel ``c`` holds fewer than the
    two decision periods learning needs (the first is the filters' transient)."""
    n = int(np.count_nonzero(np.isfinite(obs.y[:, c])))
    if n < 2 * period:
        need = 2 * period / obs.rate_hz
        end = obs.capture_s
        if end is None or round(obs.start_s + need, 6) <= round(end, 6):
            fix = f"give a longer one (--to {obs.start_s + need:g} or later)"
        elif end >= need:
            fix = f"give a longer one (--from {math.floor(round(10 * (end - need), 6)) / 10:g} or earlier)"
        else:
            fix = f"the capture holds only {end:.1f} s: record a longer one"
        raise CmsensordError(
            f"calibrate: channel {obs.names[c]}: the healthy period holds {n} observation(s) ({n / obs.rate_hz:.3g} "
            f"s), fewer than the 2 decision periods learning needs ({2 * period}, {need:g} s: the first is the "
            f"filters' transient); {fix}")


def _from_word(source: str) -> str:
    """The table's word for where f_r came from: --rpm, tacho, indicators, capture, config."""
    return source.split()[0].split(".")[0]


def _g(x: float) -> str:
    return f"{x:.4g}"


def _r1_why(m: HealthyModel) -> str:
    """Where the bank's R_1 (eq. 16 of R_min, R_max, n) comes from."""
    wanted = MARGIN * m.healthy_r
    if math.isclose(m.r_1, wanted, rel_tol=1e-9):
        return f"R_1 = {_g(m.r_1)} = {MARGIN:g} x healthy critical R {_g(m.healthy_r)}"
    return f"R_1 = {_g(m.r_1)}: eq. 16 cannot reach R_max with R_1 = {MARGIN:g} x H = {_g(wanted)}"


def format_table(results: list[ChannelResult], obs: Observations) -> str:
    """What calibrate measured and chose, one row per channel (the names' column as wide as the
    longest), and the margins."""
    w = max([12, *(len(r.name) for r in results)])
    head = (f"{'channel':<{w}} {'f_r Hz':>7} {'from':<10} {'baseline':>9} {'spread':>7} {'run-in s':>8} "
            f"{'learned s':>9} {'H':>9} {'R_1':>9} {'R_min':>9} {'R_max':>9} {'max cnt':>7} {'flagged':>7}")
    lines = [f"healthy period: {obs.start_s:.1f}-{obs.end_s:.1f} board s, {obs.rate_hz:.4g} blocks/s", head]
    for r in results:
        m = r.model
        per = obs.period(1.0) / obs.rate_hz
        lines.append(
            f"{r.name:<{w}} {r.f_r:>7.3f} {_from_word(r.f_r_source):<10} {_g(m.baseline):>9} {m.spread:>7.3f} "
            f"{m.runin_periods * per:>8.0f} {m.learned * per:>9.0f} {_g(m.healthy_r):>9} {_g(m.r_1):>9} "
            f"{_g(m.r_min):>9} {_g(m.r_max):>9} {m.max_cnt:>7d} {m.any_flagged:>7d}")
    lines.append(f"R in units of baseline^2 (the bank watches block RMS / baseline); R_1 = {MARGIN:g} x H "
                 f"(twice the healthy fluctuation amplitude), R_n = {SPAN:g} x R_1 unless --faulty.")
    lines += [f"{r.name}: {_r1_why(r.model)}" for r in results if not math.isclose(
        r.model.r_1, MARGIN * r.model.healthy_r, rel_tol=1e-9)]
    lines += [f"{r.name}: R_n = {_g(r.model.r_max / r.model.r_1)} x R_1: with monitor.n <= {SPAN:g} AKFs, eq. 16 "
              f"cannot reach {SPAN:g} x R_1 with R_min > 0 (R_min = R_1 / {SPAN:g})" for r in results
              if r.model.r_max_rule == "span" and r.model.r_max < SPAN * r.model.r_1 * (1 - 1e-9)]
    for r in results:
        m = r.model
        margin = f"margin {r.f_r / m.max_cnt:.2f}x" if m.max_cnt else "no outlier at all"
        if m.max_cnt > m.max_cnt_after and m.runin_periods:
            after = f"{m.max_cnt_after}, margin {r.f_r / m.max_cnt_after:.2f}x" if m.max_cnt_after else "no outlier"
            margin += f", in the run-in (graded, not learned from); after it {after}"
        lines.append(f"{r.name}: highest outlier count per decision on the healthy period at R_1: "
                     f"{m.max_cnt} against f_r {r.f_r:.3g} ({margin}); "
                     f"{m.any_flagged} healthy decision(s) would be flagged" + _by_what(r))
        if m.flagged:
            lines.append(_r1_line(r, obs))
        if m.learned < FEW_DECISIONS:
            lines.append(f"{r.name}: warning: learned from {m.learned} decision(s) only: the healthy fluctuation "
                         "of so few is a guess; a longer healthy period (an hour of normal running) learns it better")
        if m.idle_periods:
            lines.append(f"{r.name}: {m.idle_periods} decision(s) with the machine stopped (level below "
                         f"{100 * STOPPED_SHARE:g} % of its running level), starting or stopping: not learned from")
        if m.level_flagged:
            lines.append(level_warning(r, obs))
        if m.rise_at >= 0:
            lines.append(rise_warning(r, obs))
        if r.f_r_source == "config":
            lines.append(f"{r.name}: f_r {r.f_r:.4g} Hz is the configuration's monitor.f_r: nothing gave this "
                         "machine's shaft speed (no tacho, no --rpm, no indicators.rpm, no rpm in the capture); "
                         "if it turns at another speed, give --rpm RPM")
        elif r.f_r_source.startswith("indicators.rpm"):
            lines.append(f"{r.name}: f_r {r.f_r:.4g} Hz from the configuration's {r.f_r_source} (no tacho, no "
                         "--rpm): the decisions at the speed of the indicators' bearing lines and bands")
    every = every_channels_bound(results, obs)
    return "\n".join(lines + ([every] if every else []))


def _by_what(r: ChannelResult) -> str:
    """`` (A by R_1, L by their level >= K x baseline)`` when the level check ran and any was flagged."""
    if r.level_alert is None or not r.model.any_flagged:
        return ""
    return f" ({r.model.flagged} by R_1, {r.model.level_flagged} by their level >= {r.level_alert:g} x baseline)"


def _r1_line(r: ChannelResult, obs: Observations) -> str:
    """Where the decisions R_1 flags lie in the healthy period, and how many of them are in its
    run-in: left out of the learning, but graded by the monitor (a replay flags them too)."""
    m, dec = r.model, r.decision_s
    first, last = obs.start_s + m.r1_first * dec, obs.start_s + (m.r1_last + 1) * dec
    line = f"{r.name}: R_1 flags {m.flagged} decision(s) of the healthy period, in {first:.1f}-{last:.1f} board s"
    if m.runin_flagged:
        a, b = obs.start_s + dec, obs.start_s + (m.runin_periods + 1) * dec
        line += (f"; {m.runin_flagged} of them in its run-in ({a:.1f}-{b:.1f} board s), which is not learned "
                 "from but is graded all the same")
    return line


def site_yaml(results: list[ChannelResult], obs: Observations, *, source: str,
              base: dict[str, Any] | None = None, base_path: str | None = None,
              rpm: float | None = None) -> str:
    """SITE.yaml text: BASE's settings (if any) with the learned channels, commented, learned from
    the capture at ``source`` (its real path, :func:`_commissioned_yaml`).  A speed given to
    calibrate (``rpm``, ``--rpm``) replaces the one the capture's import read."""
    base = dict(base or {})
    base.pop("commissioned", None)
    base_alarms = base.pop("alarms", None) or {}
    base_channels = {ch.get("name"): ch for ch in base.pop("channels", None) or [] if isinstance(ch, dict)}
    out = [
        "# cmsensord site configuration written by `cmsensord calibrate`; re-run it to regenerate.",
        f"# learned from {Path(source).name}, board seconds {obs.start_s:.1f}-{obs.end_s:.1f} (the healthy period)"
        + (f", on top of {base_path}" if base_path else ""),
        "# Per channel: baseline = median RMS of the healthy period's decisions; the AKF bank watches",
        "# block RMS / baseline, so r_min and r_max are in units of baseline^2; the severity also",
        "# grades the level against the baseline (monitor.severity: auto -> combined).",
    ]
    settings, why = dict(obs.settings), dict(_SETTING_WHY)
    if rpm is not None:
        settings["rpm"], why["rpm"] = rpm, "the machine's speed given to calibrate (--rpm)"
    out += _indicators_yaml(settings, base, why)
    if base:
        out.append(yaml.safe_dump(base, sort_keys=False, default_flow_style=False).rstrip())
    out.append("channels:")
    for r in results:
        m = r.model
        entry = {k: v for k, v in base_channels.get(r.name, {}).items()
                 if k not in ("name", "index", "baseline", "baseline_spread", "r_min", "r_max", "f_r")}
        rows = [("baseline", m.baseline, "median RMS of the healthy period's decisions"),
                ("baseline_spread", m.spread, "robust std of the per-decision level / baseline"),
                ("r_min", m.r_min, _r1_why(m)),
                ("r_max", m.r_max, f"R_n = {_g(m.r_max / m.r_1)} x R_1" if m.r_max_rule == "span" else
                 "R_n: the largest R that still flags the faulty capture"), ("f_r", r.f_r, r.f_r_source)]
        out += [f"  - name: {r.name}", f"    index: {r.index}"]
        out += [f"    {(k + ': ' + _g(v)):<28}# {why}" for k, v, why in rows]
        for k, v in entry.items():
            out.append(f"    {k}: {yaml.safe_dump(v, default_flow_style=True).strip().removesuffix('...').strip()}")
    return "\n".join(out + _alarms_yaml(obs, base_alarms) + _commissioned_yaml(obs, source)) + "\n"


def _commissioned_yaml(obs: Observations, source: str) -> list[str]:
    """The ``commissioned`` section: the capture (``source``, its real path, as a replay's log
    names its ``source``; its size and the digest of its ends, by which a replay knows it moved or
    renamed: :mod:`cmsensord.capture_print`), its board's rate (a board at another is warned of)
    and the healthy period in its board seconds (a replay of that capture writes it into its log,
    where the report shades it)."""
    size, digest = capture_print(source)
    return ["# What the baselines were learned from: a board streaming at another rate is warned of; a replay",
            "# of this capture (here, or moved: the same size and ends) marks the healthy period (board seconds)",
            "# in its log and its report.",
            "commissioned:", f"  capture: {json.dumps(source)}", f"  capture_bytes: {size}",
            f"  capture_ends_sha256: {digest}", f"  fs_hz: {obs.fs:g}",
            f"  block_len: {round(obs.fs / obs.rate_hz)}",
            f"  from_s: {round(float(obs.start_s), 6)!r}", f"  to_s: {round(float(obs.end_s), 6)!r}"]


_SETTING_WHY = {"rpm": "the speed the import read from the recording (no tacho in the capture)"}


def _indicators_yaml(settings: dict[str, float], base: dict[str, Any], why: dict[str, str]) -> list[str]:
    """The ``indicators`` settings the capture's sidecar gave (``settings``) that are the
    machine's, with why; merged into BASE's own ``indicators`` section (``base``, changed) when
    it has one.  The record length of a capture of snapshots is the capture's, not the machine's:
    it is not written (the live board's stream is continuous; a replay of the capture takes it
    from the sidecar again), a comment says so."""
    kept = {k: v for k, v in settings.items() if k in why}
    out = []
    if "interval_s" in settings:
        out += [f"# indicators.interval_s is not set: the {settings['interval_s']:g}-s records of the capture's "
                "snapshots are its own (a replay", "# of it takes them from its sidecar); the live board's "
                "continuous stream keeps the configured length."]
    if not kept:
        return out
    if isinstance(base.get("indicators"), dict):
        base["indicators"] = {**base["indicators"], **kept}
        return out + [f"# indicators.{k}: {why[k]}" for k in kept]
    return out + ["indicators:"] + [f"  {(k + ': ' + repr(float(v))):<26} # {why[k]}" for k, v in kept.items()]


def _baseline_rows(obs: Observations) -> list[dict[str, Any]]:
    """The ``alarms.baselines`` rows: each channel's indicator medians over the healthy period."""
    return [{"channel": ch, "indicator": k, "value": float(_g(v))}
            for ch in obs.names for k, v in sorted(obs.indicators.get(ch, {}).items())]


def _alarms_yaml(obs: Observations, base_alarms: Any) -> list[str]:
    """The ``alarms`` section: BASE's, with ``baselines`` = each indicator's median over the
    healthy period (rules with ``alert_x_baseline`` / ``danger_x_baseline`` use them)."""
    rows = _baseline_rows(obs)
    if not rows and not base_alarms:
        return []
    rest = {k: v for k, v in (base_alarms if isinstance(base_alarms, dict) else {}).items() if k != "baselines"}
    out = ["# Indicator baselines: the median of each /cm/<ch>/indicators value over the healthy period",
           "# (alarm levels given as alert_x_baseline / danger_x_baseline are k x these)."]
    out += yaml.safe_dump({"alarms": {**rest, "baselines": rows}}, sort_keys=False,
                          default_flow_style=None, width=110).rstrip().splitlines()
    return out


def add_calibrate_parser(sub) -> argparse.ArgumentParser:
    """The ``calibrate`` subcommand's arguments."""
    p = sub.add_parser("calibrate", help="learn a machine's healthy model from a capture -> SITE.yaml",
                       description="Learn R_min, R_max, f_r and the healthy baseline per channel from the "
                                   "healthy period [--from, --to] of a capture and write a site configuration.")
    p.add_argument("capture", help="capture of the machine (cmsensord record / import)")
    p.add_argument("--from", dest="from_s", type=board_time, default=0.0, metavar="S|P%",
                   help="start of the healthy period, board seconds or a percentage of the capture "
                        "(default: 0)")
    p.add_argument("--to", dest="to_s", type=board_time, default=None, metavar="S|P%",
                   help="end of the healthy period, board seconds or a percentage of the capture "
                        "(e.g. 20%%: the first fifth of a run to failure; default: the end of the capture)")
    p.add_argument("--faulty", metavar="CAPTURE2", help="a faulty capture of the same machine: R_max "
                   "becomes the largest R that still flags it (Kim et al. 2023)")
    p.add_argument("--rpm", type=positive, default=None, help="the machine's shaft speed (before the "
                   "tacho's and the capture's)")
    p.add_argument("--config", metavar="BASE.yaml", help="base configuration the site file extends")
    p.add_argument("--out", required=True, metavar="SITE.yaml", help="site configuration to write")
    return p


def _writable_out(out: Path) -> Path:
    """``--out`` checked before the capture is read: a file name in a directory that exists, not
    a special file (a device or FIFO there would be replaced by the site file)."""
    if out.is_dir():
        raise CmsensordError(f"calibrate: {out}: is a directory; give --out a file name, e.g. {out / 'site.yaml'}")
    special = not_a_file(out, "the site file")
    if special:
        raise CmsensordError(f"calibrate: {special}")
    if not out.parent.is_dir():
        raise CmsensordError(f"calibrate: {out}: cannot write the site file: no directory {out.parent}")
    return out


def _given_speed(cfg: Config, capture: str, rpm: float | None) -> tuple[Config, float | None]:
    """``cfg`` with ``indicators.rpm`` = ``rpm`` (``--rpm``) where the capture's import speed
    would otherwise be it (no tacho, none configured), and that speed, else (``cfg``, None):
    the indicators' baselines and the site file then follow the machine's speed as given."""
    if rpm is None or "rpm" not in capture_settings(cfg, sidecar(capture))[1]:
        return cfg, None
    return dataclasses.replace(cfg, indicators=dataclasses.replace(cfg.indicators, rpm=rpm)), rpm


def run_calibrate(args: argparse.Namespace) -> int:
    """Read, learn, print the table, write SITE.yaml atomically and check it loads."""
    out = _writable_out(Path(args.out))
    same = overwritten_input(out, with_sidecars([args.capture] + ([args.faulty] if args.faulty else [])))
    if same:
        raise CmsensordError(f"calibrate: {same}")
    cfg = load_config(args.config) if args.config else Config()
    base = yaml.safe_load(Path(args.config).read_text(encoding="utf-8")) if args.config else None
    auto = not (isinstance(base, dict) and base.get("channels"))
    cfg, speed = _given_speed(cfg, args.capture, args.rpm)
    obs = read_observations(args.capture, cfg, auto_channels=auto, from_s=args.from_s, to_s=args.to_s)
    absent = "" if auto else _absent_channels(cfg, obs, args.config, Path(args.capture).name, out.name)
    faulty = read_observations(args.faulty, cfg, auto_channels=auto) if args.faulty else None
    faulty, faulty_said = _faulty_matches(args.faulty, faulty, obs)
    results = calibrate(obs, cfg, faulty=faulty, rpm=args.rpm)
    print(format_table(results, obs))
    for line in faulty_said + _faulty_unused(args.faulty, faulty, results):
        print(line)
    if absent:
        print(absent)
    if not auto:
        listed = [(ch.name, ch.index) for ch in cfg.channels]
        for line in [unlisted_channels(listed, obs.board_channels, Path(args.capture).name, args.config, out.name),
                     *replaced_baselines(base, [(r.name, r.model.baseline) for r in results], _baseline_rows(obs),
                                         out.name)]:
            if line:
                print(line)
    for note in obs.notes:
        print(f"note: {note}")
    if "interval_s" in obs.settings:
        every = obs.settings["interval_s"]
        print(f"note: {out.name} does not carry indicators.interval_s {every:g} (the capture's snapshots'): the live "
              f"board's continuous stream keeps records of {cfg.indicators.interval_s:g} s; a replay of this capture "
              f"takes {every:g} s from its sidecar again")
    where = span_line(obs.meta, obs.start_s, obs.end_s)
    if where:
        print(f"healthy period {where}")
    text = site_yaml(results, obs, source=os.path.realpath(args.capture), base=base, base_path=args.config, rpm=speed)
    tmp = out.with_name(out.name + ".part")
    try:
        tmp.write_text(text)
        site = load_config(str(tmp))
        os.replace(tmp, out)
    except OSError as exc:
        raise CmsensordError(f"calibrate: {out}: cannot write the site file: {exc.strerror or exc}") from None
    finally:
        tmp.unlink(missing_ok=True)
    for line in alarm_lines(args.capture, site, obs):
        print(line)
    print(f"wrote {out}: run `cmsensord replay CAPTURE --config {out}` or `cmsensord --config {out}`",
          file=sys.stderr)
    return 0


def _faulty_matches(path: str | None, faulty: Observations | None,
                    obs: Observations) -> tuple[Observations | None, list[str]]:
    """The ``--faulty`` capture to learn R_max from, or None when it is sampled otherwise than
    the healthy one (another fs or block rate: its outlier counts per decision mean another
    thing), with a line on what of it is not used (that, or the channels it lacks)."""
    if faulty is None or path is None:
        return None, []
    name, span = Path(path).name, f"R_max is R_n = {SPAN:g} x R_1"
    if (faulty.fs, faulty.rate_hz) != (obs.fs, obs.rate_hz):
        return None, [f"warning: --faulty {name} is not used: it is sampled at {faulty.fs:g} Hz, {faulty.rate_hz:.4g} "
                      f"blocks/s, the healthy capture at {obs.fs:g} Hz, {obs.rate_hz:.4g} blocks/s (another machine "
                      f"or set-up?): {span}"]
    lacking = [n for n in obs.names if n not in faulty.names]
    if lacking:
        return faulty, [f"warning: --faulty {name} has no channel {', '.join(lacking)} (its channels: "
                        f"{', '.join(faulty.names)}): their {span}"]
    return faulty, []


def _faulty_unused(path: str | None, faulty: Observations | None, results: list[ChannelResult]) -> list[str]:
    """A line per channel whose R_max the ``--faulty`` capture, which has it, did not change, with why."""
    if faulty is None or path is None:
        return []
    lines = []
    for r in results:
        m = r.model
        if r.name not in faulty.names or m.r_max_rule == "faulty":
            continue
        why = (f"no R flags half of its decisions (at f_r {r.f_r:.3g})" if not np.isfinite(m.faulty_r) else
               f"the largest R that flags half of its decisions, {_g(m.faulty_r)}, is not above R_1 {_g(m.r_1)}")
        lines.append(f"{r.name}: --faulty {Path(path).name} did not change R_max: {why}; R_n = {SPAN:g} x R_1")
    return lines


def _absent_channels(cfg: Config, obs: Observations, base_path: str, capture: str, out: str) -> str:
    """The warning line on the channels ``cfg`` (BASE.yaml at ``base_path``) lists that the
    capture does not hold ("" when it holds them all): not learned, so not in the site file.  A
    rule or bearing of BASE naming one of them (or a rule's vote that needs them) is a
    :class:`ConfigError` naming BASE: the site file could not monitor it."""
    absent = [ch for ch in cfg.channels if ch.name not in obs.names]
    if not absent:
        return ""
    held = f"its {len(obs.names)} channel(s): {', '.join(obs.names)}"
    found = channel_refs_error(cfg, [ch for ch in cfg.channels if ch.name in obs.names])
    if found is not None:
        path, reason, value = found
        names = ", ".join(ch.name for ch in absent)
        reason = (f"names {value}, a channel {capture} does not have ({held})" if value in names.split(", ") else
                  f"{reason}: {capture} does not have channel(s) {names} ({held})")
        raise ConfigError(base_path, path, f"{reason}; the site file holds the channels calibrate learns from the "
                          f"capture: calibrate a capture that holds {names}, or leave {names} out of this file")
    listed = ", ".join(f"{ch.name} (index {ch.index})" for ch in absent)
    return (f"warning: {base_path} lists channel(s) {listed} that {capture} does not have ({held}): not learned, "
            f"and left out of {out}: a daemon with it does not monitor them")


def alarm_lines(capture: str, site: Config, obs: Observations) -> list[str]:
    """A warning per alarm of ``site`` that a replay raises within the healthy period itself, or
    that stands all through it from before: its levels are within what the machine did then; and
    per alarm whose values there reach its level without raising it, held back by its on-delay
    alone (:func:`~cmsensord.alarm_margins.thin_margins`)."""
    if not (site.alarms.enabled and (site.alarms.rules or order_rules(site))):
        return []
    standing: dict[str, tuple[float, str, str]] = {}     # alarm -> (since, level, message) all through
    seen: dict[str, list[tuple[float, str, str]]] = {}   # alarm -> its rises within the period
    judged = Judged()
    for t, m in alarm_events(capture, site, obs.end_s, judged):
        alarm, level = str(m.get("alarm")), m["kind"].removeprefix("alarm_")
        said = (t, level, m["message"].removeprefix(alarm + ": "))
        if level == "clear":
            standing.pop(alarm, None)
        elif t <= obs.start_s + 1e-3:            # its record ended by the period's start: judged before it
            standing[alarm] = said
        else:
            seen.setdefault(alarm, []).append(said)
    lines = []
    for alarm in dict.fromkeys([*standing, *seen]):
        parts = []
        if alarm in standing:
            t, level, message = standing[alarm]
            parts.append(f"{level} since {t:.1f} board s, before the period, and all through it ({message})")
        firsts: dict[str, float] = {}
        for t, level, message in seen.get(alarm, []):
            if level not in firsts:
                firsts[level] = t
                parts.append(f"{level} at {t:.1f} board s ({message})")
        rises = f", raised {len(seen[alarm])} time(s)" if alarm in seen else ""
        lines.append(f"alarm {alarm}: warning: shown within the healthy period{rises}: {'; '.join(parts)}; "
                     "its levels are within what this machine did then: check the rule's levels, or whether "
                     "the period was healthy")
        lines += [ln.strip() for ln in origin_lines(obs.meta, [], {alarm: firsts})] if firsts else []
    unjudged = _unjudged_rules(site, obs)
    rules = len(site.alarms.rules) + len(order_rules(site)) - len(unjudged)
    if not lines and rules:
        lines = [f"alarms: none of the {rules}{' judged' if unjudged else ''} rule(s) shown within the healthy "
                 "period (replayed with the site file)"]
    lines += thin_margins(judged, {r.name: r for r in (*site.alarms.rules, *order_rules(site))}, obs.start_s,
                          obs.end_s, {*standing, *seen})
    lines += [f"note: {ln.strip()}" for ln in delay_lines(obs.meta, site)]
    if unjudged:
        raw = any(set(medians) - {"accel_rms"} for medians in obs.indicators.values())
        why = ("listed unavailable: a band past Nyquist, or one that holds no bin of the records' spectrum" if raw
               else "an RMS-mode board's carry accel_rms alone")
        lines.append(f"alarms: rule(s) {', '.join(r.name for r in unjudged)} not judged: the capture's indicator "
                     f"records carry no {', '.join(dict.fromkeys(r.indicator for r in unjudged))} ({why})")
    return lines


def _unjudged_rules(site: Config, obs: Observations) -> list[Any]:
    """The rules of ``site`` on an indicator record's value that no record of the healthy period
    carried (the zone counts as carried with the velocity RMS)."""
    carried = {k for values in obs.indicators.values() for k in values}
    if "velocity_rms_mm_s" in carried:
        carried.add("zone")
    records = set(indicator_names(site, records_only=True))
    return [r for r in site.alarms.rules if r.indicator in records and r.indicator not in carried]
