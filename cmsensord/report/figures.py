"""The report's figures, drawn with matplotlib (the ``report`` extra; the daemon never imports this).

Each ``*_figure`` function returns a :class:`Figure`: the PNG bytes and its
metadata (id, title, kind, channel and, per axes, the labels and the limits;
time axes also as ISO 8601 local times), which the HTML carries beside the
image and ``--png`` writes into the PNG's text chunk, so a test or a tool can
check what a figure shows without reading pixels.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.colors as mcolors  # noqa: E402
import matplotlib.dates as mdates  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker as mticker  # noqa: E402
import numpy as np  # noqa: E402

from cmsensord.dsp.indicators.iso_zones import BOUNDARIES_MM_S  # noqa: E402
from cmsensord.report.log_data import SPEED_BIN_RPM, Capture, ChannelData, LogData  # noqa: E402
from cmsensord.report.marks import alarm_levels, event_lines, healthy_span  # noqa: E402
from cmsensord.report.time_axis import TimeAxis  # noqa: E402
from cmsensord.sinks.indicator_schema import DEFECT_LINES  # noqa: E402

__all__ = ["Figure", "severity_figure", "indicators_figure", "iso_text", "orders_figure", "campbell_figure",
           "capture_figure"]

#: PNG resolution [dots per inch]
SAVE_DPI = 100
#: fewer 10-rpm speed bins than this: the order figure shows bars, not curves over speed
MIN_SPEED_BINS = 5
_ZONE_COLOURS = ("#cfeccf", "#f4f1c0", "#f8d9b0", "#f4b8b8")
#: colours of the marked lines, by kind (the shaft's 1x, the bearing defects)
MARK_COLOURS = {"shaft": "#424242", "ftf": "#2e7d32", "bpfo": "#c62828", "bpfi": "#ef6c00", "bsf": "#6a1b9a"}


@dataclass
class Figure:
    """A drawn figure: ``png`` bytes and ``meta`` (see the module docstring)."""

    meta: dict[str, Any]
    png: bytes


def _times(t_ns: np.ndarray, axis: TimeAxis) -> np.ndarray:
    """Shown times (:class:`TimeAxis`) -> x: matplotlib date numbers of the local wall-clock
    reading, or :meth:`TimeAxis.numbers`."""
    if not axis.is_dates():
        return axis.numbers(t_ns)
    return np.asarray(mdates.date2num([axis.reading(int(t)) for t in t_ns]))


def _axes_meta(ax: Any, time_axis: TimeAxis | None = None) -> dict[str, Any]:
    """An axes' labels, limits and labelled lines (``styles``: each one's colour and line style);
    its legend's entries (``legend``: lines, bands and all) and box in axes fractions (left,
    bottom, right, top: outside the axes when right of 1), laid out as saved."""
    xlim, ylim = [float(x) for x in ax.get_xlim()], [float(y) for y in ax.get_ylim()]
    lines = [ln for ln in ax.get_lines() if not ln.get_label().startswith("_")]
    out: dict[str, Any] = {"title": ax.get_title(), "xlabel": ax.get_xlabel(), "ylabel": ax.get_ylabel(),
                           "xlim": xlim, "ylim": ylim, "xscale": ax.get_xscale(),
                           "lines": [ln.get_label() for ln in lines],
                           "styles": {ln.get_label(): [mcolors.to_hex(ln.get_color()), ln.get_linestyle()]
                                      for ln in lines}}
    if ax.get_legend() is not None:
        out["legend"] = [text.get_text() for text in ax.get_legend().get_texts()]
        box = ax.get_legend().get_window_extent().transformed(ax.transAxes.inverted())
        out["legend_box"] = [round(float(v), 3) for v in (box.x0, box.y0, box.x1, box.y1)]
    if time_axis is not None and time_axis.is_dates():
        out["xlim_local"] = [mdates.num2date(x).replace(tzinfo=None).isoformat(timespec="seconds") for x in xlim]
    return out


def _finish(fig: Any, meta: dict[str, Any], axes: list[Any], time_axis: TimeAxis | None = None,
            boxes: bool = False) -> Figure:
    """The PNG and its metadata; with ``boxes`` each axes' box in the PNG too (``box_px``: left,
    top, right, bottom pixels, laid out as saved), so a test can find a line's pixel column."""
    if time_axis is not None:
        axes[-1].set_xlabel(time_axis.label())
        for ax in axes if time_axis.is_dates() else ():
            locator = mdates.AutoDateLocator()
            ax.xaxis.set_major_locator(locator)
            ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(locator))
    fig.draw_without_rendering()                # the constrained layout as savefig makes it
    meta["axes"] = [_axes_meta(ax, time_axis) for ax in axes]
    if boxes:
        w, h = fig.get_size_inches() * SAVE_DPI
        for ax, m in zip(axes, meta["axes"]):
            x0, y0, x1, y1 = ax.get_position().extents
            m["box_px"] = [round(x0 * w, 1), round((1 - y1) * h, 1), round(x1 * w, 1), round((1 - y0) * h, 1)]
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=SAVE_DPI, metadata={"Title": meta["title"],
                                                      "Description": json.dumps(meta)})
    plt.close(fig)
    return Figure(meta, buf.getvalue())


def _who(of: ChannelData | Capture) -> str:
    """A channel as the titles name it: after its recording's name, among several recordings."""
    name = of.name if isinstance(of, ChannelData) else of.channel
    return f"{of.recording} {name}" if of.recording else name


def _ident(of: ChannelData | Capture) -> str:
    """The start of a figure's id (and its PNG's name): the channel, after its recording's
    (its :attr:`.runs.Recording.ident`) among several recordings."""
    name = of.name if isinstance(of, ChannelData) else of.channel
    return f"{of.recording_id}-{name}" if of.recording else name


def legend_outside(ax: Any, pad: float = 0.01) -> None:
    """The axes' legend to the right of it, clear of the data (the constrained layout makes room)."""
    ax.legend(loc="upper left", bbox_to_anchor=(1 + pad, 1.0), fontsize=8, borderaxespad=0.0)


def _event_lines(ax: Any, data: LogData, channel: str) -> None:
    """The events of ``channel`` and of the daemon marked on ``ax`` (:func:`.marks.event_lines`)."""
    mine = [(t, ev["kind"]) for t, ev in data.events if ev["channel"] in (channel, None)]
    x = _times(np.array([t for t, _ in mine], dtype=np.int64), data.axis) if mine else np.zeros(0)
    event_lines(ax, [(float(xi), kind) for xi, (_, kind) in zip(x, mine)])


def _healthy(axes: list[Any], healthy: tuple[int, int] | None, axis: TimeAxis) -> dict[str, Any]:
    """The healthy period (shown times, :mod:`.healthy`) shaded on each of ``axes``; its metadata
    (``healthy_period``: x from and to on the axes, as ``xlim``; ``healthy_period_shown``: as
    the page writes times), {} without one."""
    if healthy is None:
        return {}
    x0, x1 = (float(x) for x in _times(np.array(healthy, dtype=np.int64), axis))
    for ax in axes:
        healthy_span(ax, x0, x1)
    return {"healthy_period": [x0, x1], "healthy_period_shown": [axis.text(t) for t in healthy]}


def severity_figure(data: LogData, ch: ChannelData) -> Figure:
    """The severity index S_idx over time, anomaly periods shaded, the healthy period the
    baselines were learned from shaded (:func:`_healthy`), channel events as lines, the
    levels of alarm rules on ``severity_index``;
    under it, when the log has the combined severity's level, the level / healthy baseline
    with its alert and danger ratios (the analysts' 2 x baseline rule)."""
    levels = ch.level.count > 0
    fig, axes = plt.subplots(2 if levels else 1, 1, figsize=(11, 5.6 if levels else 3.2), sharex=True,
                             layout="constrained", squeeze=False, height_ratios=[1, 0.8] if levels else None)
    ax = axes[0, 0]
    shaded = _healthy(list(axes[:, 0]), data.healthy, data.axis)
    t, s = ch.severity.arrays()
    x = _times(t, data.axis)
    ax.step(x, s, where="post", color="#1f4e99", lw=1.4, label="severity index")
    ta, a = ch.anomaly.arrays()
    if a.size and a.max() > 0:
        ax.fill_between(_times(ta, data.axis), 0, 1, where=a > 0, step="post", color="#ff9800", alpha=0.25,
                        transform=ax.get_xaxis_transform(), label="anomaly flagged")
    _event_lines(ax, data, ch.name)
    drawn = alarm_levels(ax, ch, ("severity_index",))
    ax.set_ylim(0, 1.05)
    if x.size:
        ax.set_xlim(x[0], x[-1] if x[-1] > x[0] else x[0] + (1 / 86400 if data.axis.is_dates() else 1 / 3600))
    ax.set_ylabel("severity index")
    ax.set_title(f"{_who(ch)}: severity index (Kim et al. 2023)")
    ax.grid(alpha=0.3)
    legend_outside(ax)
    if levels:
        _level_axes(axes[1, 0], data, ch)
    meta = {"id": f"{_ident(ch)}-severity", "kind": "severity", "channel": ch.name,
            "title": f"{_who(ch)}: severity index", "points": int(ch.severity.count), "alarm_levels": drawn,
            **shaded}
    return _finish(fig, meta, list(axes[:, 0]), time_axis=data.axis)


def _level_axes(ax: Any, data: LogData, ch: ChannelData) -> None:
    """The decisions' level (RMS) / healthy baseline on a log scale, with the baseline (1) and
    the alert and danger ratios of the combined severity."""
    t, v = ch.level.arrays()
    ax.step(_times(t, data.axis), v, where="post", color="#37474f", lw=1.2, label="level / baseline")
    ax.axhline(1.0, color="#888", lw=0.8, ls=":")
    top = float(np.nanmax(v)) if v.size else 1.0
    if ch.level_limits is not None:
        alert, danger = ch.level_limits
        ax.axhline(alert, color="#e08a00", lw=1.2, ls="--", label=f"level_alert {alert:g} x (severity 0.5)")
        ax.axhline(danger, color="#b00020", lw=1.2, ls="--", label=f"level_danger {danger:g} x (severity 1)")
        top = max(top, danger)
    low = float(np.nanmin(v)) if v.size and np.nanmin(v) > 0 else 0.5
    lo, hi = min(0.5, low / 1.2), top * 1.3
    ax.set_yscale("log")
    ax.set_ylim(lo, hi)
    ax.yaxis.set_major_formatter(mticker.FuncFormatter(lambda y, _: f"{y:g}"))
    ax.yaxis.set_minor_formatter(mticker.NullFormatter())
    ax.set_yticks([y for y in (0.5, 1, 2, 4, 8, 16, 32, 64) if lo <= y <= hi])
    ax.set_ylabel("level / baseline")
    ax.set_title(f"{_who(ch)}: decision level / healthy baseline (the 2 x baseline rule)")
    ax.grid(alpha=0.3, which="both")
    legend_outside(ax)


def _zone_bands(ax: Any, bounds: list[float], top: float) -> None:
    edges = [0.0, *bounds, max(top, bounds[-1] * 1.3)]
    for i, zone in enumerate("ABCD"):
        ax.axhspan(edges[i], edges[i + 1], color=_ZONE_COLOURS[i], zorder=0)
        ax.text(1.003, (edges[i] + edges[i + 1]) / 2, zone, transform=ax.get_yaxis_transform(),
                va="center", fontsize=9, color="#444")


#: each bearing's defect lines drawn as trends (a line of theirs an alarm rule watches is drawn too)
BEARING_TRENDS = ("ftf", "bpfo", "bpfi", "bsf")
#: the machine groups of ISO 10816-3 as the standard names them
_GROUPS = {1: "large, > 300 kW", 2: "medium, 15-300 kW"}


def iso_text(ch: ChannelData) -> str | None:
    """The ISO 10816-3 grading the channel's indicator records carry: the zone boundaries and
    the machine group and foundation they are the boundaries of (both, when two share them:
    the records carry the boundaries, not the configuration)."""
    if not ch.zone_boundaries:
        return None
    ab, bc, cd = ch.zone_boundaries
    which = [(g, f) for (g, f), v in BOUNDARIES_MM_S.items() if np.allclose(v, ch.zone_boundaries)]
    machine = ""
    if len(which) == 1:
        machine = f": machine group {which[0][0]} ({_GROUPS[which[0][0]]}), {which[0][1]} foundation"
    elif which:
        machine = (": " + " or ".join(f"group {g} on a {f}" for g, f in which)
                   + " foundation (the log does not say which)")
    return f"ISO 10816-3 zone boundaries A/B {ab:g}, B/C {bc:g}, C/D {cd:g} mm/s{machine}"


def _band_text(ch: ChannelData) -> str:
    """`` over 10-1000 Hz``: the velocity band(s) the records gave ('' without one)."""
    return " over " + " and ".join(f"{lo:g}-{hi:g} Hz" for lo, hi in ch.velocity_bands) if ch.velocity_bands else ""


def _panels(ch: ChannelData) -> list[tuple[str, tuple[str, ...]]]:
    """(kind, indicators) of each axes of the indicators figure, top to bottom: the velocity RMS,
    the acceleration RMS, the envelope RMS, each bearing's lines (BEARING_TRENDS and those a rule
    watches), the shape indicators; each one the log has."""
    panels: list[tuple[str, tuple[str, ...]]] = [
        (k, (k,)) for k in ("velocity_rms_mm_s", "accel_rms", "envelope_rms") if k in ch.indicators]
    watched = {indicator for indicator, _ in ch.alarm_levels.values()}
    for bearing in dict.fromkeys(k.rpartition(".")[0] for k in ch.indicators if "." in k):
        lines = tuple(f"{bearing}.{line}" for line in DEFECT_LINES if f"{bearing}.{line}" in ch.indicators
                      and (line in BEARING_TRENDS or f"{bearing}.{line}" in watched))
        if lines:
            panels.append(("bearing", lines))
    shape = tuple(k for k in ("kurtosis", "crest_factor") if k in ch.indicators)
    return panels + ([("shape", shape)] if shape else [])


def indicators_figure(ch: ChannelData, axis: TimeAxis | None = None,
                      healthy: tuple[int, int] | None = None) -> Figure | None:
    """The channel's indicator trends over ``axis`` (default: local time), each on axes of its
    own: velocity RMS with the ISO 10816-3 zones shaded and their boundaries, machine group and
    foundation in its title (:func:`iso_text`), acceleration RMS (the only one in RMS mode),
    envelope RMS, each bearing's defect lines (0-peak amplitudes in the envelope spectrum), and
    kurtosis and crest factor; on each, the alert and danger levels of the alarm rules watching
    an indicator drawn there (``alarm_levels`` in the metadata), and the ``healthy`` period the
    baselines were learned from shaded (:func:`_healthy`). None without a velocity or
    acceleration RMS."""
    axis = axis or TimeAxis()
    panels = _panels(ch)
    if not panels or panels[0][0] not in ("velocity_rms_mm_s", "accel_rms"):
        return None
    fig, axes = plt.subplots(len(panels), 1, figsize=(11, 0.4 + 2.5 * len(panels)), sharex=True,
                             layout="constrained", squeeze=False)
    used = [a[0] for a in axes]
    shaded = _healthy(used, healthy, axis)
    drawn: list[dict[str, Any]] = []
    for ax, (kind, names) in zip(used, panels):
        if kind == "velocity_rms_mm_s":
            drawn += _velocity_axes(ax, ch, axis)
        elif kind == "shape":
            for k, colour in zip(names, ("#6a1b9a", "#2e7d32")):
                tk, vk = ch.indicators[k].arrays()
                ax.plot(_times(tk, axis), vk, color=colour, lw=1, label=k)
            drawn += alarm_levels(ax, ch, names)
            ax.set_ylabel("kurtosis, crest factor")
            ax.set_title(f"{_who(ch)}: kurtosis and crest factor", fontsize=9.5)
        else:
            drawn += _trend_axes(ax, ch, axis, kind, names)
        legend_outside(ax, 0.03)                # right of the zones' letters
        ax.grid(alpha=0.3)
    iso = iso_text(ch)
    meta = {"id": f"{_ident(ch)}-indicators", "kind": "indicators", "channel": ch.name,
            "title": f"{_who(ch)}: indicators", "main": panels[0][0], "panels": [list(n) for _, n in panels],
            "zones": bool(ch.zone_boundaries), "iso": iso, "alarm_levels": drawn, **shaded}
    if iso:
        meta["caption"] = f"{_who(ch)}: indicators. Velocity RMS{_band_text(ch)}; {iso}."
    return _finish(fig, meta, used, time_axis=axis)


def _velocity_axes(ax: Any, ch: ChannelData, axis: TimeAxis) -> list[dict[str, Any]]:
    """The velocity RMS over its ISO zones with the alarm rules' levels on it; what
    :func:`.marks.alarm_levels` drew."""
    t, v = ch.indicators["velocity_rms_mm_s"].arrays()
    ax.plot(_times(t, axis), v, color="#1f4e99", lw=1.2, label="velocity_rms_mm_s")
    drawn = alarm_levels(ax, ch, ("velocity_rms_mm_s",))
    top = max([float(v.max()) * 1.1, 0.1] + [d["value"] * 1.1 for d in drawn])
    if ch.zone_boundaries:
        _zone_bands(ax, ch.zone_boundaries, top)
        top = max(top, ch.zone_boundaries[-1] * 1.3)
    if ch.velocity_alarm is not None:
        ax.axhline(ch.velocity_alarm, color="#b00020", ls="--", lw=1, label="alarm level")
    ax.set_ylim(0, top)
    ax.set_ylabel("velocity RMS [mm/s]")
    iso = iso_text(ch)
    ax.set_title(f"{_who(ch)}: velocity RMS{_band_text(ch)}, ISO 10816-3 zones A-D shaded"
                 + (f"\n{iso}" if iso else ""), fontsize=9.5)
    return drawn


#: (title, y label) of the trends of one unit in m/s², by the kind of axes
_TREND_TEXTS = {"accel_rms": ("acceleration RMS", "acceleration RMS [m/s²]"),
                "envelope_rms": ("envelope RMS (acceleration enveloping)", "envelope RMS [m/s²]"),
                "bearing": ("bearing {} defect lines in the envelope spectrum, 0-peak", "line, 0-peak [m/s²]")}


def _trend_axes(ax: Any, ch: ChannelData, axis: TimeAxis, kind: str, names: tuple[str, ...]) -> list[dict[str, Any]]:
    """The trends ``names`` with the levels of the alarm rules on them: the acceleration or the
    envelope RMS from 0, or one bearing's lines on a log scale (they span decades from healthy
    to failed; a line's 2nd harmonic dotted)."""
    top, low = 0.0, np.inf
    for name in names:
        t, v = ch.indicators[name].arrays()
        line = name.rpartition(".")[2]
        style = {"color": MARK_COLOURS.get(line.split("_")[0], "#1f4e99"), "ls": ":" if "_" in line else "-"} \
            if kind == "bearing" else {"color": "#1f4e99" if kind == "accel_rms" else "#e08a00"}
        ax.plot(_times(t, axis), v, lw=1.1, label=name, **style)
        top = max(top, float(np.nanmax(v)) if v.size else 0.0)
        low = min(low, float(np.nanmin(v[v > 0])) if np.any(v > 0) else np.inf)
    drawn = alarm_levels(ax, ch, names, say_indicator=kind == "bearing" and len(names) > 1)
    top = max([top, 1e-6] + [d["value"] for d in drawn])
    if kind == "bearing":
        ax.set_yscale("log")
        ax.set_ylim(min([low, top / 10] + [d["value"] for d in drawn]) / 1.5, top * 1.5)
    else:
        ax.set_ylim(0, top * 1.1)
    title, ylabel = _TREND_TEXTS[kind]
    ax.set_title(f"{_who(ch)}: {title.format(names[0].rpartition('.')[0])}", fontsize=9.5)
    ax.set_ylabel(ylabel)
    return drawn


def orders_figure(ch: ChannelData) -> Figure | None:
    """Order RMS versus shaft speed (mean per 10-rpm bin) of every tracked order; at an almost
    constant speed (fewer than ``MIN_SPEED_BINS`` bins) the mean order RMS as bars instead."""
    if not ch.orders:
        return None
    keys_all = sorted({k for bins in ch.orders.values() for k in bins})
    lo, hi = keys_all[0] * SPEED_BIN_RPM, (keys_all[-1] + 1) * SPEED_BIN_RPM
    fig, ax = plt.subplots(figsize=(11, 3.4), layout="constrained")
    if len(keys_all) < MIN_SPEED_BINS:
        names = list(ch.orders)
        means = [sum(v[0] for v in ch.orders[n].values()) / sum(v[1] for v in ch.orders[n].values()) for n in names]
        ax.bar(names, means, color="#1f4e99", label=f"{lo:.0f}-{hi:.0f} rpm")
        ax.set_xlabel("order")
        ax.set_title(f"{_who(ch)}: order RMS at {lo:.0f}-{hi:.0f} rpm (constant speed; Yeh, Pan & Le)")
    else:
        for name, bins in ch.orders.items():
            keys = sorted(bins)
            rpm = (np.array(keys) + 0.5) * SPEED_BIN_RPM
            rms = np.array([bins[k][0] / bins[k][1] for k in keys])
            ax.plot(rpm, rms, marker=".", ms=3, lw=1, label=f"order {name}")
        ax.set_xlabel("shaft speed [rpm]")
        ax.set_title(f"{_who(ch)}: order RMS versus speed (Yeh, Pan & Le)")
        ax.legend(loc="upper left", fontsize=8, ncols=4)
    ax.set_ylabel("order RMS [m/s²]")
    ax.grid(alpha=0.3)
    meta = {"id": f"{_ident(ch)}-orders", "kind": "orders", "channel": ch.name,
            "title": f"{_who(ch)}: order RMS versus speed", "speed_rpm": [lo, hi], "orders": list(ch.orders)}
    return _finish(fig, meta, [ax])


def campbell_figure(ch: ChannelData) -> Figure | None:
    """A Campbell diagram of the channel's tracked orders: each order's frequency over shaft speed
    (mean per 10-rpm bin), coloured by its mean order RMS. Only over a speed range of at least
    ``MIN_SPEED_BINS`` bins (a run-up or coast-down): at a constant speed it is one vertical line."""
    keys_all = sorted({k for bins in ch.campbell.values() for k in bins})
    if len(keys_all) < MIN_SPEED_BINS:
        return None
    rpm, freq, rms = [], [], []
    fig, ax = plt.subplots(figsize=(11, 4.2), layout="constrained")
    for name, bins in ch.campbell.items():
        keys = sorted(bins)
        f = [bins[k][0] / bins[k][2] for k in keys]
        rpm += [(k + 0.5) * SPEED_BIN_RPM for k in keys]
        freq += f
        rms += [bins[k][1] / bins[k][2] for k in keys]
        ax.annotate(f"{name}", ((keys[-1] + 0.5) * SPEED_BIN_RPM, f[-1]), xytext=(4, 0),
                    textcoords="offset points", fontsize=8, va="center")
    dots = ax.scatter(rpm, freq, c=rms, s=14, cmap="viridis", edgecolors="none")
    fig.colorbar(dots, ax=ax, label="order RMS [m/s²]")
    ax.set_xlabel("shaft speed [rpm]")
    ax.set_ylabel("frequency [Hz]")
    ax.set_ylim(0, max(freq) * 1.08 if freq else 1.0)
    ax.set_title(f"{_who(ch)}: Campbell diagram, order frequency over speed coloured by order RMS")
    ax.grid(alpha=0.3)
    lo, hi = keys_all[0] * SPEED_BIN_RPM, (keys_all[-1] + 1) * SPEED_BIN_RPM
    meta = {"id": f"{_ident(ch)}-campbell", "kind": "campbell", "channel": ch.name,
            "title": f"{_who(ch)}: Campbell diagram (order RMS over speed and frequency)",
            "speed_rpm": [lo, hi], "freq_hz": [min(freq), max(freq)], "rms": [min(rms), max(rms)],
            "orders": list(ch.campbell), "points": len(rpm)}
    return _finish(fig, meta, [ax])


#: the zoomed envelope spectrum shows up to this many times its highest bearing line
ZOOM_LINES = 3.5


def _marks(ax: Any, marks: list[dict[str, Any]], fmax: float, text: bool, harmonics: bool) -> None:
    """The marked frequencies up to ``fmax`` as vertical dashed lines (legend: label and Hz);
    with ``text`` each also labelled at the top of the axes, with ``harmonics`` its 2x and 3x dotted."""
    for m in sorted(marks, key=lambda m: m["freq_hz"]):
        hz, colour = float(m["freq_hz"]), MARK_COLOURS.get(m.get("kind", ""), "#424242")
        if not 0 < hz <= fmax:
            continue
        ax.axvline(hz, color=colour, ls="--", lw=1.1, label=f"{m['label']} {hz:.1f} Hz")
        if text:
            ax.text(hz, 0.98, f"{m['label']} ", transform=ax.get_xaxis_transform(), rotation=90,
                    va="top", ha="right", fontsize=7.5, color=colour)
        for h in (2, 3) if harmonics else ():
            if h * hz <= fmax:
                ax.axvline(h * hz, color=colour, ls=":", lw=0.9, alpha=0.7)


def _spectrum(ax: Any, msg: dict[str, Any], label: str, fmax: float | None = None, *,
              log_f: bool = False, legend: bool = True) -> None:
    """An amplitude spectrum with its marks: up to ``fmax`` (a zoom: the lines labelled, their
    2x and 3x dotted), or whole, on a log frequency axis with ``log_f`` (the lines labelled).
    Its y label says RMS per bin, as the capture's spectra are (a sine of RMS a reads a; the
    indicators' bearing lines are 0-peak)."""
    amp = np.asarray(msg.get("amplitude", []), dtype=float)
    f = float(msg.get("freq_start_hz") or 0.0) + float(msg.get("freq_step_hz") or 1.0) * np.arange(amp.size)
    if fmax is not None:
        keep = f <= fmax
        f, amp = f[keep], amp[keep]
    if log_f:                                   # DC off the log axis
        f, amp = f[f > 0], amp[f > 0]
        ax.set_xscale("log")
    ax.plot(f, amp, lw=0.8, color="#1f4e99")
    marks = msg.get("marks") or []
    if f.size:
        ax.set_xlim(float(f[0]) if log_f else 0.0, float(f[-1]))
        _marks(ax, marks, float(f[-1]), text=fmax is not None or log_f, harmonics=fmax is not None)
    ax.set_xlabel("frequency [Hz]")
    speed = f", shaft {msg['shaft_speed_rpm']:.0f} rpm from the {msg.get('speed_source', '?')}" \
        if "shaft_speed_rpm" in msg else ""
    dotted = "; dotted: 2x and 3x of each line" if fmax is not None and marks else ""
    ax.set_title(f"{label} ({f[0] if log_f else 0:.0f}-{f[-1]:.0f} Hz{speed}{dotted})" if f.size else label,
                 fontsize=9, loc="left")
    ax.set_ylabel(f"{label.split(',')[0]}\nRMS per bin [{_unit(msg)}]")     # two lines: fits 2.6 in
    ax.grid(alpha=0.3, which="both" if log_f else "major")
    if marks and legend:
        ax.legend(loc="upper right", fontsize=7.5, ncols=3 if fmax is None else 2, framealpha=0.85)


def _unit(msg: dict[str, Any]) -> str:
    """A capture's unit as the figures write units: the messages' ``m/s^2`` as ``m/s²`` (the
    trends' spelling), another unit (a microphone's Pa) as it is."""
    return str(msg.get("unit") or "m/s^2").replace("^2", "²")


def _zoom_to(msg: dict[str, Any]) -> float | None:
    """The zoomed envelope spectrum's top frequency: ZOOM_LINES x its highest bearing line
    (None: no bearing line to zoom on)."""
    lines = [float(m["freq_hz"]) for m in msg.get("marks") or [] if m.get("kind") != "shaft"]
    if not lines:
        return None
    top = float(msg.get("freq_start_hz") or 0.0) + float(msg.get("freq_step_hz") or 1.0) * \
        (len(msg.get("amplitude", [])) - 1)
    return min(ZOOM_LINES * max(lines), top)


def capture_figure(cap: Capture, index: int, axis: TimeAxis | None = None) -> Figure:
    """A captured waveform (seconds from its trigger), its spectrum and its envelope spectrum,
    the marked lines on both; with bearing lines also the envelope spectrum zoomed on them; its
    time in the title (``heading`` in the metadata) as ``axis`` shows times (default: local time)."""
    parts: list[str] = [p for p in ("waveform", "spectrum", "envelope") if p in cap.parts]
    zoom = _zoom_to(cap.parts["envelope"]) if "envelope" in cap.parts else None
    if zoom is not None:
        parts.append("envelope_zoom")
    fig, axes = plt.subplots(len(parts), 1, figsize=(11, 2.6 * len(parts)), layout="constrained", squeeze=False)
    trigger = cap.parts.get("waveform", next(iter(cap.parts.values()))).get("trigger") or {}
    for ax, part in zip((a[0] for a in axes), parts):
        if part == "waveform":
            _waveform(ax, cap.parts[part])
        elif part == "envelope_zoom":
            _spectrum(ax, cap.parts["envelope"], "envelope spectrum, bearing lines", zoom)
        elif part == "spectrum":
            _spectrum(ax, cap.parts[part], "spectrum", log_f="envelope" in cap.parts, legend=False)  # RAW
        else:                                   # with a zoom below, its legend says what the lines are
            _spectrum(ax, cap.parts[part], "envelope spectrum", legend=zoom is None)
    heading = (f"{_who(cap)}: capture at {(axis or TimeAxis()).text(cap.time_ns)}"
               f" — trigger {trigger.get('kind', '?')}: {trigger.get('message', '')}")
    fig.suptitle(heading, fontsize=11)
    meta = {"id": f"{_ident(cap)}-capture-{index}", "kind": "capture", "channel": cap.channel,
            "title": f"{_who(cap)}: capture {index}, on {trigger.get('kind', '?')}", "heading": heading,
            "trigger": trigger.get("kind"),
            "parts": parts,
            "marks": [m["label"] for m in cap.parts.get("spectrum", {}).get("marks", [])]}
    return _finish(fig, meta, [a[0] for a in axes], boxes=True)


def _waveform(ax: Any, msg: dict[str, Any]) -> None:
    y = np.asarray(msg.get("samples", []), dtype=float)
    y[np.asarray(msg.get("lost", []), dtype=int)] = np.nan    # lost samples are gaps
    rate = float(msg.get("sample_rate_hz") or 1.0)
    x = -float(msg.get("pre_s") or 0.0) + np.arange(y.size) / rate
    ax.plot(x, y, lw=0.5, color="#1f4e99")
    ax.axvline(0.0, color="#b00020", lw=1, ls="--", label="trigger")
    ax.set_xlabel("time from trigger [s]")
    ax.set_title(f"waveform ({msg.get('source', 'raw').upper()}, {rate:g} samples/s, "
                 f"{msg.get('missing', 0)} lost)", fontsize=9, loc="left")
    ax.set_ylabel(f"waveform [{_unit(msg)}]")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
