"""Argument types of the command line: each turns one option's text into a value, or
raises ``argparse.ArgumentTypeError`` with what it expected and what it got."""

from __future__ import annotations

import argparse
from collections.abc import Callable

__all__ = ["Percent", "board_time", "comma_list", "count", "nonnegative", "nonzero", "positive", "real"]


def real(text: str) -> float:
    """A finite number."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if v != v or abs(v) == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return v


class Percent(float):
    """A share of a capture's board time, in % (``--to 20%``)."""

    def seconds(self, total_s: float) -> float:
        """The board seconds it is of a capture of ``total_s``."""
        return total_s * float(self) / 100.0

    def __str__(self) -> str:
        return f"{float(self):g} %"


def board_time(text: str) -> float:
    """Board seconds >= 0, or ``P%``: that share of the capture (a :class:`Percent`, 0-100)."""
    pct = text.strip().endswith("%")
    try:
        v = real(text.strip().rstrip("%").strip())
    except argparse.ArgumentTypeError:
        v = -1.0
    if v < 0 or (pct and v > 100):
        raise argparse.ArgumentTypeError(f"expected board seconds >= 0 or a percentage 0-100%, got {text!r}")
    return Percent(v) if pct else v


def positive(text: str) -> float:
    """A finite number > 0."""
    v = real(text)
    if not v > 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return v


def nonnegative(text: str) -> float:
    """A finite number >= 0."""
    v = real(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}")
    return v


def nonzero(text: str) -> float:
    """A finite number other than 0."""
    v = real(text)
    if v == 0:
        raise argparse.ArgumentTypeError("expected a non-zero number, got 0")
    return v


def count(lo: int, hi: int) -> Callable[[str], int]:
    """An integer lo..hi."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer {lo}..{hi}, got {text!r}") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"expected an integer {lo}..{hi}, got {v}")
        return v
    return parse


def comma_list(text: str) -> tuple[str, ...]:
    """Comma-separated items, at least one."""
    items = tuple(t.strip() for t in text.split(",") if t.strip())
    if not items:
        raise argparse.ArgumentTypeError(f"expected a comma-separated list, got {text!r}")
    return items
