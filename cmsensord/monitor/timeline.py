"""A compact severity timeline per channel, for the summary printed at the end of a run.

Bounded memory whatever the run's length: at most ``BINS`` bins, each the highest
severity of its span of decisions; when full, neighbouring bins merge and a bin
spans twice as many decisions.  Also the board time at which each severity level
was first reached.
"""

from __future__ import annotations

__all__ = ["BINS", "SeverityTimeline"]

#: bins in the rendered timeline
BINS = 60
_BARS = "·▁▂▃▄▅▆▇█"


class SeverityTimeline:
    """Severity of every decision of one channel, folded into at most BINS bins."""

    def __init__(self, bins: int = BINS) -> None:
        self.bins: list[float] = []
        self.size = bins
        self.span = 1                 # decisions per bin
        self._fill = 0                # decisions in the last bin
        self.first: dict[float, float] = {}    # severity level -> board seconds first reached
        self.decisions = 0
        self.start_s: float | None = None
        self.end_s: float | None = None

    def add(self, t_s: float, severity: float) -> None:
        """One decision ending at board second ``t_s``."""
        if self.start_s is None:
            self.start_s = t_s
        self.end_s = t_s
        self.decisions += 1
        for level in (0.1, 0.5, 1.0):
            if severity >= level - 1e-9 and level not in self.first:
                self.first[level] = t_s
        if self.bins and self._fill < self.span:
            self.bins[-1] = max(self.bins[-1], severity)
            self._fill += 1
            return
        if len(self.bins) == self.size:        # every bin is full: merge pairs, double the span
            self.bins = [max(self.bins[i:i + 2]) for i in range(0, self.size, 2)]
            self.span *= 2
        self.bins.append(severity)
        self._fill = 1

    def bars(self) -> str:
        """One character per bin: the bin's highest severity, blank for 0, full block for 1."""
        return "".join(_BARS[min(8, int(round(s * 8)))] for s in self.bins)

    def render(self) -> str:
        """``|bars| t0-t1 s; first 0.1 at .. s, 0.5 at .. s, 1.0 at .. s`` (or 'never above 0')."""
        if not self.decisions:
            return "no decision"
        firsts = ", ".join(f"{lv:g} at {t:.0f} s" for lv, t in sorted(self.first.items()))
        return (f"|{self.bars()}| {self.start_s:.0f}-{self.end_s:.0f} s; "
                + (f"first {firsts}" if firsts else "never above 0"))
