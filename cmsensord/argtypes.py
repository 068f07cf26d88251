"""Argument types of the command line: each turns one option's text into a value, or
raises ``argparse.ArgumentTypeError`` with what it expected and what it got."""

from __future__ import annotations

import argparse
from collections.abc import Callable

__all__ = ["comma_list", "count", "nonzero", "positive", "real"]


def real(text: str) -> float:
    """A finite number."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if v != v or abs(v) == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return v


def positive(text: str) -> float:
    """A finite number > 0."""
    v = real(text)
    if not v > 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
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
