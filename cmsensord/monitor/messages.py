"""Every message the monitoring chain writes, built in one place from the schema helpers.

A :class:`Message` is what a sink's ``write(topic, schema, stamp_ns, msg)`` takes.
The field names and their meaning are the output contract of
:mod:`cmsensord.sinks.schemas`; a value that is not finite becomes ``None``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from cmsensord.sinks.event_schema import LOG_LEVELS
from cmsensord.sinks.schemas import (
    TOPIC_ALARMS,
    TOPIC_DIAGNOSTICS,
    TOPIC_EVENTS,
    TOPIC_LOG,
    akf_topic,
    indicators_topic,
    orders_topic,
    severity_topic,
    vibration_estimate_topic,
)


class Message(NamedTuple):
    topic: str
    schema: str
    stamp_ns: int
    msg: dict


class MessageGroup(NamedTuple):
    """Messages written whole or not at all, even by a crash (a capture): a sink's
    ``write_group`` takes them in one call. ``written`` and ``dropped`` are the events
    (:class:`cmsensord.monitor.events.Event`) to log after it: the first when the sink took
    the group, the second when it went to no file (a disk outage)."""
    messages: tuple[Message, ...]
    written: Any = None
    dropped: Any = None


def num(x: float):
    """A float for JSON: None when it is NaN."""
    return None if x != x else x


def event(stamp_ns: int, kind: str, channel: str | None, message: str, extra: dict[str, Any]) -> Message:
    """An event record with its ``extra`` fields (count, filter, details ...)."""
    return Message(TOPIC_EVENTS, "event", stamp_ns,
                   {"kind": kind, "channel": channel, "message": message, **extra})


def log(stamp_ns: int, level: int, kind: str, channel: str | None, message: str) -> Message:
    """The event again as a ``foxglove.Log`` record: ``level`` (a logging level) as the
    foxglove.LogLevel, ``name`` the channel or "cmsensord", the message as in the journal."""
    name = "ERROR" if level >= 40 else "WARNING" if level >= 30 else "INFO" if level >= 20 else "DEBUG"
    return Message(TOPIC_LOG, "log", stamp_ns, {
        "level": LOG_LEVELS[name], "message": f"{kind}: {message}", "name": channel or "cmsensord",
        "file": "", "line": 0})


def severity(stamp_ns: int, channel: str, d, c: int, R: np.ndarray, **extra: Any) -> Message:
    """The decision ``d`` (:class:`~cmsensord.dsp.severity.Decision`) of channel column ``c``
    whose bank has the noise variances ``R``; ``extra``: further optional fields."""
    sev = float(d.severity[c])
    anomaly = d.anomaly[c].tolist()
    return Message(severity_topic(channel), "severity", stamp_ns, {
        "channel": channel, "severity_index": sev, "level": int(round(sev * len(R))),
        "anomaly": anomaly, "outliers": d.cnt[c].tolist(), "f_r": float(d.f_r[c]),
        "r": R.tolist(), "failure": bool(anomaly[-1]) or sev >= 1.0, "missing": int(d.missing[c]),
        "transient": d.transient, **_no_data(d, c), **extra,
    })


def _no_data(d, c: int) -> dict[str, Any]:
    """``{"no_data": True}`` when the decision ``d`` held channel column ``c`` for want of
    observations (:attr:`~cmsensord.dsp.severity.Decision.no_data`), else {}."""
    return {"no_data": True} if d.no_data is not None and d.no_data[c] else {}


def severities(stamp_ns: int, channels: Sequence[str], d, R: np.ndarray | Sequence[list[float]],
               extras: Sequence[dict[str, Any]], topics: Sequence[str] | None = None) -> list[Message]:
    """:func:`severity` of every channel column of the decision ``d`` (channel ``c``'s name
    ``channels[c]``, its bank's noise variances ``R[c]`` (a row of ``R``, or a list), its further
    fields ``extras[c]``, its topic ``topics[c]``, by default made from the name),
    with the decision's arrays converted to Python values once for all channels."""
    # tolist(): Python floats and ints already (what float() and int() of each would give)
    sev, anomaly = np.asarray(d.severity, dtype=np.float64).tolist(), d.anomaly.tolist()
    cnt, missing, transient = d.cnt.tolist(), np.asarray(d.missing, dtype=np.int64).tolist(), d.transient
    f_r = np.asarray(d.f_r, dtype=np.float64).tolist()
    if topics is None:
        topics = [severity_topic(ch) for ch in channels]
    out = []
    for c, channel in enumerate(channels):
        s, a, r = sev[c], anomaly[c], R[c]
        n = len(r)
        msg = {"channel": channel, "severity_index": s, "level": round(s * n), "anomaly": a,
               "outliers": cnt[c], "f_r": f_r[c], "r": r.tolist() if isinstance(r, np.ndarray) else list(r),
               "failure": bool(a[-1]) or s >= 1.0, "missing": missing[c], "transient": transient}
        msg.update(_no_data(d, c))
        if extras[c]:
            msg.update(extras[c])
        out.append(Message(topics[c], "severity", stamp_ns, msg))
    return out


def diagnostics(stamp_ns: int, link: dict, observations: int, uptime_s: float,
                extra: dict | None = None) -> Message:
    msg: dict[str, Any] = {"link": link, "queue_depth": 0, "queue_drops": 0, "lag_s": 0.0,
                           "observations": observations, "uptime_s": uptime_s}
    if extra:
        msg.update(extra)
    return Message(TOPIC_DIAGNOSTICS, "diagnostics", stamp_ns, msg)


def akf_trace(channel: str, stamps: Sequence[int], i: int, y: np.ndarray, valid: np.ndarray,
              x_prior: np.ndarray, x_hat: np.ndarray, Y: np.ndarray, z: np.ndarray,
              outlier: np.ndarray, Q: np.ndarray, z_c: float) -> list[Message]:
    """Per observation of one channel, the AKF ``i`` (0-based) of its bank (arrays (T,))."""
    sd = np.sqrt(Y)
    lo = (x_prior - z_c * sd).tolist()
    hi = (x_prior + z_c * sd).tolist()
    yl, zl, xpl, xhl = y.tolist(), z.tolist(), x_prior.tolist(), x_hat.tolist()
    ol, ql = outlier.tolist(), Q.tolist()
    topic = akf_topic(channel)
    out = []
    for k, stamp in enumerate(stamps):
        if valid[k]:
            msg = {"channel": channel, "filter": i + 1, "y": yl[k], "x_hat": xhl[k],
                   "x_prior": xpl[k], "lower": lo[k], "upper": hi[k], "z": zl[k],
                   "outlier": bool(ol[k]), "q_hat": ql[k], "missing": False}
        else:
            msg = {"channel": channel, "filter": i + 1, "y": None, "x_hat": num(xhl[k]),
                   "x_prior": num(xpl[k]), "lower": num(lo[k]), "upper": num(hi[k]),
                   "z": None, "outlier": False, "q_hat": num(ql[k]), "missing": True}
        out.append(Message(topic, "akf", stamp, msg))
    return out


def vibration_estimate(channel: str, stamps: Sequence[int], rms, z, ok, est, j: int) -> list[Message]:
    """Per block of microphone column ``j``: the acoustic estimator's output ``est`` (arrays
    (T, M)), the vibration RMS sqrt(x^) ``rms``, the observed z and whether it was there."""
    xr, xh, px, ah, pa, yh, py, zp = (a[:, j].tolist() for a in (
        rms, est.x_hat, est.P_x, est.a_hat, est.P_a, est.y_hat, est.P_y, est.z_pred))
    zl, okl = z[:, j].tolist(), ok[:, j].tolist()
    topic = vibration_estimate_topic(channel)
    return [Message(topic, "vibration_estimate", stamp, {
        "channel": channel, "x_hat": num(xr[k]), "x_ms": num(xh[k]), "x_ms_var": num(px[k]),
        "a_hat": num(ah[k]), "a_var": num(pa[k]), "y_hat": num(yh[k]),
        "y_var": num(py[k]), "z": zl[k] if okl[k] else None, "z_pred": num(zp[k]),
        "missing": not okl[k]}) for k, stamp in enumerate(stamps)]


def order_entries(components, freqs: Sequence[float], rms: Sequence[float], amplitude: Sequence[float],
                  ok: bool) -> list[dict]:
    """The ``orders`` array of one /orders message: per tracked component, its frequency, and
    RMS and amplitude where the block is valid and they are finite."""
    return [{"name": c.name, "order": c.order, "freq_hz": f,
             "rms": r if ok and r == r else None, "amplitude": a if ok and a == a else None}
            for c, f, r, a in zip(components, freqs, rms, amplitude)]


def orders(stamp_ns: int, channel: str, speed_rpm: float, valid: bool, method: str,
           entries: list[dict], missing_fraction: float) -> Message:
    return Message(orders_topic(channel), "orders", stamp_ns, {
        "channel": channel, "speed_rpm": num(speed_rpm), "valid": valid, "method": method,
        "orders": entries, "missing_fraction": missing_fraction})


def indicators(stamp_ns: int, channel: str, fields: dict) -> Message:
    """One /cm/<channel>/indicators record (:mod:`cmsensord.monitor.indicators` builds the fields)."""
    return Message(indicators_topic(channel), "indicators", stamp_ns, {"channel": channel, **fields})


def alarms(stamp_ns: int, table: dict) -> Message:
    """The alarm table on /cm/alarms (:mod:`cmsensord.monitor.alarms` builds it)."""
    return Message(TOPIC_ALARMS, "alarms", stamp_ns, table)
