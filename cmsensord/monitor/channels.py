"""What the board says about itself (STATUS) and which channels are monitored.

A STATUS frame (docs/PROTOCOL.md type 1) that changes fs, block_len, the
channel count or the mode is news: the block clock takes the new rate (and
re-anchors its slots), and a ``config`` event says what the board sends.  The
channels come from the configuration, or from the board's first data frame's C
when the configuration lists none (``auto_channels``); configured channels the
board does not send are reported and left out.  With the first data, the
severity chain (and the microphone estimator) of the usable channels is made.
"""

from __future__ import annotations

from cmsensord.config import MAX_CHANNELS, ChannelConfig, Config, default_channels
from cmsensord.monitor.clock import BlockClock
from cmsensord.monitor.events import EventLog
from cmsensord.monitor.microphone import Microphones
from cmsensord.monitor.severity import SeverityChain
from cmsensord.protocol import Frame, Status, decode_status


class ChannelSetup:
    """The board's STATUS, the monitored channels and their severity chain (see module docstring)."""

    def __init__(self, cfg: Config, auto_channels: bool, clock: BlockClock, log: EventLog):
        self.cfg, self.auto_channels, self.clock, self.log = cfg, auto_channels, clock, log
        self.status: Status | None = None
        self.channels: tuple[ChannelConfig, ...] = cfg.channels
        self.severity: SeverityChain | None = None
        self.microphones: Microphones | None = None
        self._no_channels = False

    def decode(self, f: Frame) -> tuple[Status | None, bool]:
        """A STATUS frame -> (its Status or None if bad, whether it changes the time base or
        the channels)."""
        try:
            st = decode_status(f.payload)
        except ValueError as exc:
            self.log.emit("decode_error", None, f"bad STATUS payload at byte {f.offset}: {exc}")
            return None, False
        old = self.status
        return st, old is None or (st.fs, st.block_len, st.n_channels, st.mode) != (
            old.fs, old.block_len, old.n_channels, old.mode)

    def apply(self, f: Frame, st: Status) -> None:
        """News from the board: the clock's rate, and the config event."""
        if self.clock.set_rate(st.fs, st.block_len):
            self.log.emit("config", None, f"board changed fs/block_len to {st.fs}/{st.block_len}:"
                          " time base re-anchored")
        mode = {1: "RMS", 2: "RAW"}.get(st.mode, f"unknown({st.mode})")
        self.log.emit("config", None, f"board firmware {st.fw_version >> 8}.{st.fw_version & 0xFF}: "
                      f"{mode} mode, {st.n_channels} channel(s), fs {st.fs} Hz, block {st.block_len}",
                      self.clock.stamp_ns(f.t0_unwrapped))

    def ready(self, n_board: int) -> bool:
        """True when the severity chain exists (made now for a board sending ``n_board``
        channels if not yet); False while none of the channels is in the stream."""
        if self.severity is None:
            self._setup(n_board)
        return self.severity is not None

    def _setup(self, n_board: int) -> None:
        emit = self.log.emit
        if self.auto_channels and n_board != len(self.channels):
            if n_board > MAX_CHANNELS:
                emit("config", None, f"board sends {n_board} channels, more than the "
                     f"{MAX_CHANNELS} a configuration can name: ch0..ch{MAX_CHANNELS - 1} are "
                     f"monitored, the rest is not")
            self.channels = default_channels(min(n_board, MAX_CHANNELS), self.cfg.monitor)
        usable = tuple(ch for ch in self.channels if ch.index < n_board)
        if len(usable) < len(self.channels):
            missing = [ch.name for ch in self.channels if ch.index >= n_board]
            emit("config", None, f"board sends {n_board} channel(s); configured channel(s) "
                 f"{', '.join(missing)} not in the stream")
        if not usable:
            if not self._no_channels:
                self._no_channels = True
                emit("config", None, f"none of the configured channels is among the board's "
                     f"{n_board}: observations are not monitored until it sends them")
            return
        self._no_channels = False
        self.channels = usable
        self.severity = SeverityChain(usable, fs=self.clock.fs, block_len=self.clock.block_len,
                                      trace_filter=self.cfg.output.akf_trace_filter)
        self.log.add(self.severity.notes)
        self.severity.notes.clear()
        self.microphones, events = Microphones.create(self.cfg, usable, fs=self.clock.fs,
                                                      block_len=self.clock.block_len)
        self.log.add(events)
