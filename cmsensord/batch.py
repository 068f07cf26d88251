"""Offline order tracking of a whole capture with the batch Vold-Kalman filter (Tůma).

``cmsensord vkf CAPTURE`` runs the capture through the daemon's own path (so
the file holds the recursive orders, severity and events as a replay would)
and, beside them, the zero-phase second-generation VKF of the whole record
(``dsp.vkf_batch.vkf2``, all components coupled) on ``/cm/<channel>/orders``
with ``method: "batch"``, in the same 0.1 s blocks and on the same time base. Of an import,
its log says the capture and the recording's timeline as a replay's does, board second 0 at
the run's start (:class:`~cmsensord.service.replay.RecordingHead`): a report draws it in that
recording, over its time.

Steps: RAW counts -> m/s² (STATUS scale/offset or the configuration), the
tacho's shaft angle at every sample (``dsp.tacho``, fed the whole record and
keeping all of it, so every value is final and known), zero-phase decimation to at least 5x the highest
tracked frequency (``scipy.signal.decimate``, FIR, forwards and backwards),
phases θ_k = 2π o_k turns (or 2π f t), one coupled banded solve per channel.
A lost RAW block is zeros in the record (the batch filter sees a short gap); each
/orders message says which fraction of its block's samples had none (``missing_fraction``).
Whatever it cannot handle (no RAW blocks or tacho, a board that changes its rate, channels,
calibration or tacho pulses, or restarts, mid-record, a bandwidth too narrow for double
precision or not below the tracked rate, a record too large for memory) is one
CmsensordError line, and the files of the run are deleted: nothing is left behind.
This is an offline tool: it holds the whole record in memory (about 11 bytes
per sample and channel at 25 kHz, plus ~1.6 kB per decimated sample for the
solve with 2 poles and 4 components); :func:`memory_need` estimates it from the
capture's size before the replay, and a record that cannot fit in the memory
available is refused then. On a terminal, progress bars show the replay and the solve.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from pathlib import Path

import numpy as np

from cmsensord.config import Config
from cmsensord.dsp.rms import rows_physical
from cmsensord.errors import CmsensordError, Interrupted
from cmsensord.monitor import messages
from cmsensord.one_setup import OneSetup
from cmsensord.protocol import (
    HEADER_LEN,
    MAX_FRAME,
    MODE_RAW,
    Decoder,
    FrameType,
    decode_raw,
    decode_status,
    decode_tacho,
)
from cmsensord.source import CaptureSource, require_frames
from cmsensord.terminal_bar import Bar, Progress


class _Collector:
    """RAW counts and TACHO edges of a whole capture, as decoded; its first STATUS, and what first
    broke its one board set-up (:class:`~cmsensord.one_setup.OneSetup`)."""

    def __init__(self) -> None:
        self.raw: list[tuple[int, int, bytes]] = []      # (t0, chan, payload)
        self.tacho_t0: list[int] = []
        self.tacho_edges: list[np.ndarray] = []
        self.setup = OneSetup()

    def add(self, frames, tacho_input: int) -> None:
        for f in frames:
            self.setup.see(f)
            if f.type == FrameType.RAW:
                self.raw.append((f.t0_unwrapped, f.chan, f.payload))
            elif f.type == FrameType.TACHO and f.chan == tacho_input:
                try:
                    edges = decode_tacho(f.payload)
                except ValueError:
                    continue
                self.tacho_t0.append(f.t0_unwrapped)
                self.tacho_edges.append(edges)


def batch_orders(capture: str, cfg: Config, *, bandwidth_hz: float = 1.0, poles: int = 2,
                 quiet: bool = False, auto_channels: bool = True, publish: bool = False
                 ) -> tuple[list[Path], dict]:
    """Replay ``capture`` and add the batch VKF orders; returns the MCAP paths and a summary.
    ``auto_channels``: ``cfg`` lists no channels: an imported capture's are named as its import
    named them (as ``cmsensord replay`` names them), else the board's. ``publish``: an
    ``mqtt`` section publishes the run (``--publish``); otherwise it is ignored.

    A capture or a bandwidth the batch filter cannot handle (no RAW blocks or no tacho, a
    bandwidth too narrow for double precision, a record too large for memory) raises
    CmsensordError with one line, and the files this run wrote are deleted: nothing is left
    behind. Ctrl-C before the log is complete does the same, raising
    :class:`~cmsensord.errors.Interrupted` that says how far the run got."""
    from cmsensord.service.replay import RecordingHead
    from cmsensord.service.sink import open_sink, publish_lines, send_queued

    t_start = time.monotonic()
    source = CaptureSource(capture, chunk=1 << 20)      # LinkError before any output file exists
    try:
        require_frames(capture, "vkf")
        _tacho_first(capture, cfg.tacho.input)
        cfg, auto_channels, meta = _capture_config(capture, cfg, auto_channels)
        _room_for(capture, cfg, poles, auto_channels)
    except KeyboardInterrupt:
        raise Interrupted(f"vkf: interrupted (Ctrl-C) reading {capture}, before its replay: nothing "
                          "written") from None
    out_dir = Path(cfg.output.dir)
    made_dir = not out_dir.exists()
    done = replayed = False
    head = RecordingHead(capture, meta, cfg.commissioned)     # an import's: on its recording's time, as its replays
    sink = open_sink(cfg, {**head.metadata, "batch_vkf": f"{poles} poles, {bandwidth_hz:g} Hz"},
                     publish=publish, command="vkf")
    try:
        sink.hold_all()     # the batch orders come after the whole run: held to write the file in log-time order
        proc, col = _replay(capture, cfg, source, sink, auto_channels, head)
        replayed = True
        bar = Bar(1 + sum(ch.kind != "microphone" for ch in proc.channels), f"vkf {Path(capture).name}: batch VKF")
        try:
            summary = _track(col, cfg, proc, sink, bandwidth_hz, poles, bar)
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise CmsensordError(f"{capture}: batch VKF at {bandwidth_hz:g} Hz, {poles} pole(s): "
                                 f"{exc}") from None
        except MemoryError:
            raise _no_memory(capture) from None
        finally:
            bar.close()
        done = True
        send_queued(sink)
    except KeyboardInterrupt:
        if done:
            raise
        where = ("in the batch VKF, after the replay" if replayed else
                 f"at {source.bytes_read / max(source.size, 1):.0%} of the replay")
        raise Interrupted(f"vkf: interrupted (Ctrl-C) {where} of {capture}: nothing written (the batch "
                          "orders need the whole record)") from None
    finally:
        sink.close()
        sink.release()                  # the directory's lock: a daemon may start now
        if not done:
            _remove(sink.paths, out_dir if made_dir else None)
    summary["wall_s"] = round(time.monotonic() - t_start, 3)
    summary["mqtt"] = publish_lines(sink)
    return sink.paths, summary


def _capture_config(capture: str, cfg: Config, auto_channels: bool) -> tuple[Config, bool, dict]:
    """``cfg`` with the capture's channels and settings (an import's sidecar, as ``cmsensord
    replay`` takes them), their warnings logged; whether the channels are the board's; the
    sidecar."""
    from cmsensord.importing.capture_settings import capture_settings
    from cmsensord.importing.channel_names import capture_channels
    from cmsensord.importing.sidecar import sidecar

    meta = sidecar(capture)
    cfg, auto_channels, warnings = capture_channels(cfg, meta, auto_channels)
    cfg, _, said = capture_settings(cfg, meta)
    for warning in warnings + said:
        logging.getLogger("cmsensord").warning("%s", warning)
    return cfg, auto_channels, meta


def _replay(capture: str, cfg: Config, source: CaptureSource, sink, auto_channels: bool, head):
    """The capture through the daemon's Processor, its RAW blocks and tacho edges collected,
    with a progress bar on a terminal: (the Processor, the :class:`_Collector`); a
    CmsensordError for a capture the batch VKF cannot take. ``head``: the log's
    :class:`~cmsensord.service.replay.RecordingHead`, whose board second 0 the Processor's clock
    is anchored at (an import's, as ``cmsensord replay`` does)."""
    from cmsensord.monitor.processor import Processor

    proc = Processor(cfg, sink, auto_channels=auto_channels, link_counters=source.counters.as_dict)
    head.anchor(proc)
    col = _Collector()
    progress = Progress(source.size, f"vkf {Path(capture).name}: replay")
    try:
        with source:
            for frames in source:
                col.add(frames, cfg.tacho.input)
                if col.setup.status is not None and col.setup.status.mode != MODE_RAW and not col.raw:
                    raise CmsensordError(f"{capture}: the board is in RMS mode (its first STATUS): the "
                                         "batch VKF needs a capture in RAW mode")
                proc.handle(frames)
                progress.update(source.bytes_read, f"{proc.adc_seconds:.0f} s")
        proc.finish()
    finally:
        progress.close()
    if not col.raw or col.setup.status is None:
        raise CmsensordError(f"{capture}: no RAW blocks with a STATUS: the batch VKF needs a "
                             "capture in RAW mode")
    if col.setup.changed:
        raise CmsensordError(f"{capture}: the board {col.setup.changed}: the batch VKF needs one "
                             "board set-up for the whole record (cut the capture at that byte)")
    if not col.tacho_t0:
        raise CmsensordError(f"{capture}: no TACHO frames: the batch VKF needs the shaft speed")
    return proc, col


def _no_memory(capture: str, need: int | None = None, room: int | None = None) -> CmsensordError:
    """The error of a record too large for the memory there is (``need``, ``room``: the bytes
    estimated and available, when known)."""
    known = f": it needs about {_mb(need)}, {_mb(room)} available" if need and room is not None else ""
    return CmsensordError(f"{capture}: batch VKF: not enough memory for the whole record{known} (shorten "
                          "the capture or track fewer components)")


def _mb(n: int) -> str:
    return f"{n / 1e9:.1f} GB" if n >= 1e10 else f"{n / 1e6:,.0f} MB"


def _room_for(capture: str, cfg: Config, poles: int, auto_channels: bool) -> None:
    """:func:`_no_memory`, before the replay, when the batch VKF of a RAW capture needs more memory
    than there is (:func:`memory_need` from its size and first STATUS, :func:`available_memory`)."""
    status = None
    with CaptureSource(capture) as scan:
        for frames in scan:
            status = next((decode_status(f.payload) for f in frames if f.type == FrameType.STATUS), None)
            if status is not None:
                break
    # the run imports these anyway: what they take is in use when the room is measured
    import scipy.signal  # noqa: F401

    import cmsensord.monitor.processor  # noqa: F401

    room = available_memory()
    if status is None or status.mode != MODE_RAW or room is None:
        return                          # the replay says what is wrong with such a capture
    channels = status.n_channels if auto_channels else min(len(cfg.channels), status.n_channels)
    need = memory_need(cfg, status, scan.size, channels, poles)
    if need > room:
        raise _no_memory(capture, need, room)


#: bytes :class:`_Collector` holds for a RAW frame beside its payload: the payload's bytes object
#: header, the (t0, chan, payload) tuple, t0's int and the list's pointer
_FRAME_HELD = 33 + 64 + 32 + 8
#: arrays of the shape of the unknowns (N, 2K) the solve holds beside the normal matrix (g, the
#: right-hand side and its transposed copy, z, and the refinement's residual, correction and
#: structural terms: :func:`cmsensord.dsp.vkf_normal.solve`)
_SOLVE_ARRAYS = 9
#: bytes of one message the sink holds to the end of the run (``hold_all``): the /orders
#: messages (recursive, smoothed and batch, each block of each channel) are most of them
_HELD_MESSAGE = 700


def memory_need(cfg: Config, status, size: int, channels: int, poles: int) -> int:
    """Bytes the batch VKF of a RAW capture of ``size`` bytes holds at its peak beside what the
    process holds before it, from its first STATUS (``status``: rate, block length, the board's
    channels) and the ``channels`` it tracks: its blocks from the size (a RAW frame per board
    channel and a TACHO frame a block), the RAW frames :class:`_Collector` keeps, the record
    :func:`_record` makes of them (float64 values, a bool per sample lost), the decimated
    arrays of :func:`_track` (sample indices, speed, turns, valid, phases, the channels) and one
    channel's solve: the banded normal matrix ((2Ks + 1) rows of 2K N doubles) and
    ``_SOLVE_ARRAYS`` arrays of the unknowns' shape."""
    L, board = status.block_len, status.n_channels
    blocks = size // (board * (HEADER_LEN + 4 + 2 * L) + HEADER_LEN + 4)
    n = blocks * L
    nd = -(-n // _decimation(cfg, status.fs))
    k = len(cfg.orders.components)
    unknowns = 2 * k
    held = blocks * board * (2 * L + _FRAME_HELD)
    record = n * channels * (8 + 1)
    track = nd * (8 * 3 + 1 + 8 * k + 8 * channels)
    solve = nd * 8 * unknowns * (unknowns * poles + 1 + _SOLVE_ARRAYS)
    messages = 3 * cfg.orders.output_rate_hz * (n / status.fs) * channels * _HELD_MESSAGE
    return int(held + record + track + solve + messages)


def available_memory() -> int | None:
    """Bytes this process may still take: the least of the system's available memory and free
    swap (``/proc/meminfo``), its cgroup's limit less its use (cgroup v2, each level up to the
    root) and its address-space limit (RLIMIT_AS) less its size; None where none is known."""
    import resource

    room: list[int] = []
    info = _kib_fields("/proc/meminfo")
    if "MemAvailable" in info:
        room.append(1024 * (info["MemAvailable"] + info.get("SwapFree", 0)))
    limit, _ = resource.getrlimit(resource.RLIMIT_AS)
    size = _kib_fields("/proc/self/status").get("VmSize")
    if limit != resource.RLIM_INFINITY and size is not None:
        room.append(limit - 1024 * size)
    with contextlib.suppress(OSError, ValueError, StopIteration):
        line = next(x for x in Path("/proc/self/cgroup").read_text().splitlines() if x.startswith("0::"))
        group = Path("/sys/fs/cgroup") / line[3:].strip("/")
        for d in (group, *group.parents):
            cap = (d / "memory.max").read_text().strip() if (d / "memory.max").exists() else "max"
            if cap != "max":
                room.append(int(cap) - int((d / "memory.current").read_text()))
            if d == Path("/sys/fs/cgroup"):
                break
    return max(0, min(room)) if room else None


def _kib_fields(path: str) -> dict[str, int]:
    """The ``Name: N kB`` lines of a /proc file, in KiB ({}: unreadable)."""
    out = {}
    with contextlib.suppress(OSError):
        for line in Path(path).read_text().splitlines():
            name, _, value = line.partition(":")
            parts = value.split()
            if len(parts) == 2 and parts[1] == "kB" and parts[0].isdigit():
                out[name] = int(parts[0])
    return out


def _tacho_first(capture: str, tacho_input: int) -> None:
    """CmsensordError, before the replay, when the capture holds RAW frames but no TACHO frame of
    ``tacho_input``, with how to give it the shaft speed; the frames are scanned as columns
    (decoded, not processed) up to the first such TACHO frame.  A capture without RAW frames is
    left to the replay's own check (an RMS-mode board is said at its first STATUS)."""
    from cmsensord.importing.sidecar import sidecar

    chunk = 1 << 20
    raw = False
    with CaptureSource(capture, chunk=chunk, decoder=Decoder(max_buffer=chunk + MAX_FRAME), batches=True) as scan:
        for batch in scan:
            code, chan = batch.cols.code, batch.cols.chan
            if np.any((code == FrameType.TACHO) & (chan == tacho_input)):
                return
            raw = raw or bool(np.any(code == FrameType.RAW))
    if raw:
        meta = sidecar(capture)
        rpm = meta.get("rpm") if not meta.get("rpm_differs") else None
        raise CmsensordError(
            f"{capture}: no TACHO frames: the batch VKF needs the shaft speed: re-import the recording with its "
            f"speed (cmsensord import SRC... --rpm {f'{rpm:g}' if rpm else 'RPM'} --out {capture}, which also "
            "sends TACHO frames) or record with a tacho")


def describe(info: dict, *, bandwidth_hz: float, poles: int) -> str:
    """One line of what ``batch_orders`` did, for the terminal (its summary dict, read aloud)."""
    ridge = [m for m in info["ridge"] if m]
    return (f"batch VKF: {len(info['components'])} component(s) ({', '.join(info['components'])}), "
            f"{poles} pole(s), {bandwidth_hz:g} Hz: {info['samples']:,} sample(s) a channel, decimated "
            f"{info['decimation']}x to {info['fs_tracked']:g} Hz; {info['blocks']:,} /orders message(s) "
            f"written in {info['wall_s']:.1f} s"
            + (f"; a ridge term was needed (mu up to {max(ridge):.3g})" if ridge else ""))


def _remove(paths: list[Path], made_dir: Path | None) -> None:
    """Delete the files of a failed run (they would hold the replay without the batch orders),
    and the output directory when this run made it and it is empty again."""
    for p in paths:
        with contextlib.suppress(FileNotFoundError):
            p.unlink()
    paths.clear()
    if made_dir is not None:
        with contextlib.suppress(OSError):
            made_dir.rmdir()


def _track(col, cfg, proc, sink, bandwidth_hz, poles, bar: Bar) -> dict:
    """The whole record -> speed and angle -> decimation -> coupled solve -> 0.1 s blocks; ``bar``
    (on a terminal) counts a step for the record and one for each channel solved."""
    from scipy.signal import decimate  # offline tool: scipy.signal is fine here

    from cmsensord.dsp.tacho import TachoTracker
    from cmsensord.dsp.vkf_batch import Hz, phases_for, r_for_bandwidth, vkf2

    st = col.setup.status
    fs, L = st.fs, st.block_len
    channels = proc.channels
    solved = [ci for ci, ch in enumerate(channels) if ch.kind != "microphone"]  # orders are the vibration
    bar(0)                                                                       # channels', as the daemon's
    s0, y, lost = _record(col, proc)
    n = len(y)
    # the whole record's speed and angle stay queryable (the daemon keeps 60 s of knots; behind
    # them the angle is unknown, which made every order's phase 0 there, all orders alike)
    tacho = TachoTracker(fs, cfg.tacho.ppr or st.tacho_ppr, block_len=L, timeout_s=cfg.tacho.timeout_s,
                         history_s=n / fs + 60.0, history_max=None)
    tacho.update(np.array(col.tacho_t0, dtype=np.int64), col.tacho_edges)
    comps = cfg.orders.components
    q = _decimation(cfg, fs)
    fs_d = fs / q
    idx = s0 + np.arange(0, n, q)
    hz, turns, valid = tacho.evaluate(idx)
    if not valid.any() and any(c.order is not None for c in cfg.orders.components):
        edges = sum(len(e) for e in col.tacho_edges)
        raise ValueError(f"the tacho gives no shaft speed anywhere in the record ({edges} edge(s) in "
                         f"{n / fs:.1f} s): the orders have no shaft angle to follow; give a record with the "
                         "shaft turning")
    yd = decimate(y, q, ftype="fir", axis=0, zero_phase=True) if q > 1 else y
    yd = yd[:len(idx)]
    spec = [c.order if c.order is not None else Hz(c.freq_hz) for c in comps]
    ph = phases_for(spec, turns=np.nan_to_num(turns), t=idx / fs)
    # the batch filter's own bandwidth: zero-phase over the whole record, it can be much
    # narrower than the causal tracker's (the components' r/bandwidth are for the tracker)
    r = [r_for_bandwidth(bandwidth_hz, fs_d, poles) for _ in comps]
    block = max(1, round(fs_d / cfg.orders.output_rate_hz))
    nb = len(idx) // block
    rpm_blocks = _seen_mean(60.0 * hz[:nb * block], np.asarray(lost[idx[:nb * block] - s0].all(axis=1)), nb, block)
    ok_blocks = valid[:nb * block].reshape(nb, block).all(axis=1) & (rpm_blocks >= cfg.orders.min_rpm)
    gone = lost[idx[:nb * block] - s0].reshape(nb, block, len(channels)).mean(axis=1)
    heads = _block_heads(comps, [proc.stamp_ns(int(idx[(b + 1) * block - 1])) for b in range(nb)],
                         rpm_blocks, ok_blocks)
    written, ridge = 0, []
    bar(1)
    for done, ci in enumerate(solved, start=2):
        ch = channels[ci]
        res = vkf2(yd[:, ci], ph, r, poles=poles)
        ridge.append(res.ridge)
        w = res.waveforms[:, :nb * block].reshape(len(comps), nb, block)
        rms = np.sqrt(np.mean(w * w, axis=2))
        amp = res.amplitude[:, :nb * block].reshape(len(comps), nb, block).mean(axis=2)
        del res, w                          # not held through the next channel's solve
        written += _write_blocks(sink, comps, ch.name, heads, rms, amp, gone[:, ci])
        bar(done)
    return {"samples": n, "decimation": q, "fs_tracked": fs_d, "blocks": written,
            "components": [c.name for c in comps], "r": [float(v) for v in r],
            "ridge": [float(f"{m:.3g}") for m in ridge]}


def _seen_mean(rpm: np.ndarray, unseen: np.ndarray, nb: int, block: int) -> np.ndarray:
    """Per block of ``block`` samples, the mean speed over the samples some channel holds
    (``unseen``: none does; the tacho's speed there spans a hole of lost frames, where it is
    no measurement), or over all of them when none holds one."""
    r, u = rpm.reshape(nb, block), unseen.reshape(nb, block)
    held = (~u).sum(axis=1)
    seen = np.where(u, 0.0, r).sum(axis=1) / np.maximum(held, 1)
    return np.where(held > 0, seen, r.mean(axis=1))


def _record(col, proc) -> tuple[int, np.ndarray, np.ndarray]:
    """The record's RAW blocks in m/s², from its first block's board sample s0 on: (s0, y (n, C),
    lost (n, C): True where no RAW block came, zeros in y)."""
    L = col.setup.status.block_len
    channels = proc.channels
    scale, offset = proc.raw_calibration()
    t0s = np.array([t for t, _, _ in col.raw], dtype=np.int64)
    s0 = int(t0s.min())
    n = int(t0s.max()) - s0 + L
    y = np.zeros((n, len(channels)))
    lost = np.ones((n, len(channels)), dtype=bool)
    pos = {ch.index: i for i, ch in enumerate(channels)}
    for t0, chan, payload in col.raw:
        if chan in pos and len(payload) == 2 * L:
            counts = decode_raw(payload)[None, :]
            y[t0 - s0:t0 - s0 + L, pos[chan]] = rows_physical(counts, scale[chan:chan + 1],
                                                              offset[chan:chan + 1])[0]
            lost[t0 - s0:t0 - s0 + L, pos[chan]] = False
    return s0, y, lost


def _decimation(cfg, fs: float) -> int:
    """The decimation factor: the largest that keeps 5 samples a period of the fastest
    component at ``orders.max_rpm`` and divides the board samples of an /orders block (so
    that the blocks line up with the tracker's)."""
    rpm_top = cfg.orders.max_rpm
    f_hi = max(c.freq_hz if c.freq_hz is not None else c.order * rpm_top / 60.0 for c in cfg.orders.components)
    q = max(1, math.floor(fs / (5.0 * f_hi)))
    per_block = round(fs / cfg.orders.output_rate_hz)
    return max(d for d in range(1, q + 1) if per_block % d == 0)


def _block_heads(comps, stamps: list[int], rpm_blocks: np.ndarray,
                 ok_blocks: np.ndarray) -> list[tuple[int, float, bool, list[float]]]:
    """Per block what every channel's message of it shares: (stamp, speed [rpm], valid, the
    components' frequencies [Hz])."""
    heads = []
    for stamp, rpm, ok in zip(stamps, rpm_blocks.tolist(), ok_blocks.tolist()):
        freqs = [c.freq_hz if c.freq_hz is not None else c.order * rpm / 60.0 for c in comps]
        heads.append((stamp, float(rpm), bool(ok), freqs))
    return heads


def _write_blocks(sink, comps, channel: str, heads: list[tuple[int, float, bool, list[float]]],
                  rms: np.ndarray, amp: np.ndarray, gone: np.ndarray) -> int:
    """The "batch" /orders messages of one channel's blocks (:func:`_block_heads`; rms and amp
    (K, blocks)); how many. A block of no sample (all lost) is not valid, as the daemon's."""
    for b, (stamp, rpm, ok, freqs) in enumerate(heads):
        seen = ok and gone[b] < 1.0
        entries = messages.order_entries(comps, freqs, rms[:, b].tolist(), amp[:, b].tolist(), seen)
        sink.write(*messages.orders(stamp, channel, rpm, seen, "batch", entries, float(gone[b])))
    return len(heads)
