"""The frame-to-message processing step: :class:`Processor` and its in-memory sink.

The monitoring chain lives in :mod:`cmsensord.monitor` (docs/architecture.md);
this module keeps the names its users import.
"""

from __future__ import annotations

from cmsensord.monitor.processor import Processor
from cmsensord.monitor.severity import ChannelView
from cmsensord.sinks.memory import ListSink, Sink

__all__ = ["Processor", "ChannelView", "ListSink", "Sink"]
