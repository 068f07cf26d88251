"""The Processor's figures, read-only, for the status line, the summary and the tools: each is
the figure of the part that owns it (the board's STATUS and channels, the shaft, the events, the
RAW input, the block clock)."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from cmsensord.config import ChannelConfig, Config
    from cmsensord.dsp.tacho import TachoTracker
    from cmsensord.monitor.capture import Captures
    from cmsensord.monitor.channels import ChannelSetup
    from cmsensord.monitor.clock import BlockClock
    from cmsensord.monitor.events import EventLog
    from cmsensord.monitor.held import Held
    from cmsensord.monitor.indicators import Indicators
    from cmsensord.monitor.orders import OrderChain
    from cmsensord.monitor.raw import RawInput
    from cmsensord.monitor.severity import ChannelView, SeverityChain
    from cmsensord.monitor.shaft import Shaft
    from cmsensord.protocol import Status


class Figures:
    """Read-only figures of the parts (a base of :class:`~cmsensord.monitor.processor.Processor`)."""

    setup: ChannelSetup
    shaft: Shaft
    log: EventLog
    raw: RawInput
    clock: BlockClock
    clock_ns: Callable[[], int]

    @property
    def status(self) -> Status | None:
        """The board's newest good STATUS."""
        return self.setup.status

    @property
    def channels(self) -> tuple[ChannelConfig, ...]:
        """The monitored channels."""
        return self.setup.channels

    @property
    def severity(self) -> SeverityChain | None:
        """The severity chain of the monitored channels, once the board's channels are known."""
        return self.setup.severity

    @property
    def views(self) -> list[ChannelView]:
        """The severity figures of every channel monitored in the run, in the order first
        monitored, also of those no longer in the board's stream (:attr:`ChannelView.left_s`)."""
        return self.setup.views

    @property
    def tacho(self) -> TachoTracker | None:
        """The tacho tracker, once the board has announced a tacho."""
        return self.shaft.tacho

    @property
    def events(self) -> deque[dict]:
        """The recent events, newest last."""
        return self.log.recent

    @property
    def event_counts(self) -> dict[str, int]:
        """Events by kind, since the start."""
        return self.log.counts

    @property
    def fs(self) -> int:
        """The board's samples per second."""
        return self.clock.fs

    @property
    def block_len(self) -> int:
        """Samples in a board block."""
        return self.clock.block_len

    @property
    def anchor_ns(self) -> int | None:
        """The wall clock at the first frame."""
        return self.clock.anchor_ns

    @property
    def next_slot(self) -> int:
        """The next observation slot expected."""
        return self.clock.next_slot

    @property
    def board_seconds(self) -> float:
        """The board's clock at the end of the processed observations."""
        return self.clock.board_seconds

    @property
    def adc_seconds(self) -> float:
        """ADC time covered by the observations processed so far."""
        return self.clock.adc_seconds

    def lag_s(self) -> float:
        """Wall-clock lag of the newest processed observation (live mode)."""
        last = self.clock.last_stamp_ns
        return max(0.0, (self.clock_ns() - last) / 1e9) if last else 0.0

    def raw_calibration(self):
        """Per board channel scale/offset: STATUS, overridden by the configuration."""
        return self.raw.calibration(self.status)


class Stage(Figures):
    """What the Processor's stages (:class:`~cmsensord.monitor.raw_stage.RawStage`,
    :class:`~cmsensord.monitor.observing.Observing`) use of it, declared once: its configuration,
    sink and parts, and the calls they make of it."""

    cfg: Config
    sink: Any
    held: Held
    indicators: Indicators
    captures: Captures | None
    orders: OrderChain | None
    _out: Callable[..., list]
    _hand_over: Callable[[], Any]

    if TYPE_CHECKING:
        def event(self, kind: str, channel: str | None, message: str, stamp_ns: int | None = None,
                  **extra: Any) -> None: ...
