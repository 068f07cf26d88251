"""A sink that keeps messages in memory (tests, tools)."""

from __future__ import annotations


class ListSink:
    """A sink that keeps messages in memory (tests, the simulate summary)."""

    def __init__(self) -> None:
        self.messages: list[tuple[str, int, dict]] = []

    def write(self, topic: str, schema: str, stamp_ns: int, msg: dict) -> None:
        self.messages.append((topic, stamp_ns, msg))

    def write_group(self, messages: list[tuple[str, str, int, dict]]) -> bool:
        """Each message in turn (in memory a group cannot be split by a crash); True."""
        for m in messages:
            self.write(*m)
        return True

    def topic(self, name: str) -> list[dict]:
        return [m for t, _, m in self.messages if t == name]
