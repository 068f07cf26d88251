"""The JSON texts of /orders messages from their numbers, by a template of their shape.

An /orders message (:func:`cmsensord.monitor.messages.orders`) has the same text from
message to message but for its numbers: the channel, the method, ``valid`` and each
component's name and order repeat; the speed, each component's frequency, RMS and
amplitude and the missing fraction change.  The JSON encoder walks the whole dict each
time, its keys and strings about half of a message's encoding time (the numbers'
``repr`` the other half).  :class:`OrdersTemplate` is the text of one shape (channel,
method, components, ``valid`` true: every number present) made once by the plain
encoder itself (:func:`~cmsensord.sinks.mcap_encoding.encode_message` of the message with
its numbers replaced by markers), with the numbers' places left as ``%r``: a message's
text is then the template filled with its numbers, each by ``float.__repr__``, which is
what the JSON encoder writes for a float.

The text is the plain encoder's, byte for byte, for numbers that are finite Python
floats (the maker's to ensure: the plain encoder leaves a NaN or infinity out, and writes
an ``int`` or a numpy scalar otherwise); ``tests/test_orders_encoding.py`` holds every
message of a replay, and numbers at the edges (negative zero, subnormal, huge, tiny,
integral), to the plain encoder.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

from cmsensord.sinks.mcap_encoding import encode_message

__all__ = ["OrdersTemplate"]


def _marker(i: int) -> str:
    """The string standing for the i-th number while the template is made (its JSON text
    is checked to occur once)."""
    return f"\x00{i}\x00"


class OrdersTemplate:
    """The text of the /orders messages of one shape: ``channel``, ``method``, components
    ``(name, order)`` (order None for a fixed frequency), every number present (``valid``
    true).  :attr:`text` is None when the shape has no template (a marker's text occurs
    more than once: a name made of those characters); its messages are then encoded plain."""

    def __init__(self, channel: str, method: str, components: Sequence[tuple[Any, Any]]) -> None:
        K = len(components)
        self.n_numbers = 3 * K + 2
        k = iter(range(self.n_numbers))
        entries = [{"name": name, "order": order, "freq_hz": _marker(next(k)), "rms": _marker(next(k)),
                    "amplitude": _marker(next(k))} for name, order in components]
        skeleton = {"channel": channel, "speed_rpm": _marker(next(k)), "valid": True, "method": method,
                    "orders": entries, "missing_fraction": _marker(next(k))}
        self.text = self._template(encode_message("/orders", 0, skeleton).decode(), K)

    def _template(self, text: str, K: int) -> str | None:
        head = '{"timestamp":{"sec":0,"nsec":0},'
        assert text.startswith(head)
        text = "{" + text[len(head):]
        pieces = []
        for i in [3 * K] + list(range(3 * K)) + [3 * K + 1]:   # the numbers in the message's order
            mark = json.dumps(_marker(i))      # the marker's JSON text, as the encoder writes it
            if text.count(mark) != 1:
                return None
            before, text = text.split(mark)
            pieces.append(before.replace("%", "%%"))
        pieces.append(text.replace("%", "%%"))
        return "%r".join(pieces)

    def fill(self, numbers: Sequence[float]) -> str:
        """The text of the message whose numbers (finite Python floats) are, in order: the
        speed, each component's frequency, RMS and amplitude, the missing fraction."""
        return self.text % tuple(numbers)       # type: ignore[operator]
