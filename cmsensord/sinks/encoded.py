"""A message dict that carries its own JSON text, made with it by whoever built both at once.

:class:`EncodedMessage` is a ``dict`` (every reader of messages reads it as one) with one
more attribute, :attr:`~EncodedMessage.text`: the compact JSON of its fields without the
``timestamp``, exactly what :func:`~cmsensord.sinks.mcap_encoding.encode_message` would
make of the dict, which then takes the text instead of encoding the dict again (the
/orders messages, :mod:`cmsensord.sinks.orders_encoding`).  Changing the dict through any
of its own methods drops the text (the dict is then encoded as any other); its nested
lists and dicts are the maker's and are not changed after it is made.
"""

from __future__ import annotations

from typing import Any

__all__ = ["EncodedMessage"]


class EncodedMessage(dict):
    """A message dict and its JSON text (None: encode the dict)."""

    __slots__ = ("text",)

    def __init__(self, fields: dict, text: str | None) -> None:
        super().__init__(fields)
        self.text = text

    def __reduce__(self) -> tuple:
        return (EncodedMessage, (dict(self), self.text))

    def __setitem__(self, key: Any, value: Any) -> None:
        self.text = None
        super().__setitem__(key, value)

    def __delitem__(self, key: Any) -> None:
        self.text = None
        super().__delitem__(key)

    def __ior__(self, other: Any) -> EncodedMessage:      # type: ignore[misc]
        self.text = None
        super().__ior__(other)
        return self

    def clear(self) -> None:
        self.text = None
        super().clear()

    def pop(self, *args: Any) -> Any:
        self.text = None
        return super().pop(*args)

    def popitem(self) -> Any:
        self.text = None
        return super().popitem()

    def setdefault(self, key: Any, default: Any = None) -> Any:
        self.text = None
        return super().setdefault(key, default)

    def update(self, *args: Any, **kwargs: Any) -> None:
        self.text = None
        super().update(*args, **kwargs)
