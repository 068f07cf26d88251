"""The JSON of the messages a decision writes (severity, RMS indicator record, diagnostics),
formatted from a template per kind instead of by the JSON encoder: the same bytes.

:func:`~cmsensord.sinks.mcap_encoding.encode_message` turns a message into
``{"timestamp":{"sec":S,"nsec":N},...}`` with the stdlib's C encoder (compact separators,
ASCII strings, no NaN); a decision of 4 channels writes 9 messages whose encoding was most
of the sink's time.  Each function here formats one kind of message with the very text
functions that encoder uses: ``float.__repr__`` for a float, ``int.__repr__`` for an int,
``true``/``false`` for a bool and :func:`json.encoder.encode_basestring_ascii` for a string,
joined with the same separators in the dict's order.  It does so only for a message of
exactly the kind's fields, in the kind's order, each of exactly the type the template
formats, every float finite: for anything else (a further field, a None, a NaN, a numpy
value, a bool where an int is expected) it returns None and the message takes the plain
path, which sanitises and encodes it.  So each gives the plain path's bytes or nothing;
``tests/test_json_templates.py`` compares them on the messages of a damaged capture and on
every kind of deviation.

The JSON of a list that repeats from message to message (a severity message's flags,
counts and noise variances; an indicator record's ``unavailable``) is kept, keyed by the
tuple of its items; a key of ints, bools or integral floats could equal a list of other
types (``1 == 1.0 == True``), so such a list's item types are checked before its JSON is
looked up, and only lists of ints, of non-integral floats or of strings are kept.
"""

from __future__ import annotations

from collections.abc import Callable
from json.encoder import encode_basestring_ascii

__all__ = ["TEMPLATES", "severity", "indicators", "diagnostics"]

NS = 1_000_000_000
_frepr, _irepr = float.__repr__, int.__repr__
#: most lists whose JSON is kept
_MAX_LISTS = 512
_lists: dict[tuple, str] = {}          # lists of ints, and the link's counters
_float_lists: dict[tuple, str] = {}    # lists of non-integral floats
_str_lists: dict[tuple, str] = {}      # lists of strings
_strings: dict[str, str] = {}
_floats_kept: dict[float, str] = {}

_SEVERITY = ["channel", "severity_index", "level", "anomaly", "outliers", "f_r", "r", "failure",
             "missing", "transient"]
_INDICATORS = ["channel", "mode", "interval_s", "missing_fraction", "accel_rms", "unavailable"]
_DIAGNOSTICS = ["link", "queue_depth", "queue_drops", "lag_s", "observations", "uptime_s"]
_INT = {int}


def _str(s: object) -> str | None:
    """The JSON of a string (kept), None for anything else."""
    if type(s) is not str:
        return None
    j = _strings.get(s)
    if j is None:
        if len(_strings) >= _MAX_LISTS:
            _strings.clear()
        j = _strings[s] = encode_basestring_ascii(s)
    return j


def _keep(kept: dict[tuple, str], key: tuple, text: str) -> str:
    if len(kept) >= _MAX_LISTS:
        kept.clear()
    kept[key] = text
    return text


def _ints(a: list) -> str | None:
    """The JSON of a list of ints (not bools: their type is checked, as ``True == 1``), None
    for a list of anything else."""
    if a and set(map(type, a)) != _INT:
        return None
    key = tuple(a)
    return _lists.get(key) or _keep(_lists, key, "[" + ",".join(map(_irepr, a)) + "]")


def _floats(a: list) -> str | None:
    """The JSON of a list of finite non-integral floats, None for anything else.  Only such
    lists are kept: an item equal to a kept one is then a float of the same value (an int or
    a bool equals no non-integral float), so a key found needs no check of the items."""
    key = tuple(a)
    try:
        j = _float_lists.get(key)
    except TypeError:                   # an item that cannot be a key (a list): not a float
        return None
    if j is not None:
        return j
    if not all(type(v) is float and v - v == 0.0 and not v.is_integer() for v in a):
        return None
    return _keep(_float_lists, key, "[" + ",".join(map(_frepr, a)) + "]")


def _strs(a: list) -> str | None:
    """The JSON of a list of strings, None for anything else (a key found: equal strings,
    whose JSON is the same)."""
    key = tuple(a)
    try:
        j = _str_lists.get(key)
    except TypeError:                   # an item that cannot be a key: not a string
        return None
    if j is not None:
        return j
    if not all(type(v) is str for v in a):
        return None
    return _keep(_str_lists, key, "[" + ",".join(map(encode_basestring_ascii, a)) + "]")


def _num(x: object) -> str | None:
    """An int or a finite float as JSON, None for anything else."""
    if type(x) is float:
        return _frepr(x) if x - x == 0.0 else None
    return _irepr(x) if type(x) is int else None


def _kept(x: object) -> str | None:
    """:func:`_num` of a value that repeats (f_r, an interval's length): a float's JSON kept,
    but a zero's (0.0 == -0.0, whose texts differ)."""
    if type(x) is float:
        j = _floats_kept.get(x)         # a finite non-zero float equal to x: x itself
        if j is None and x - x == 0.0:
            j = _frepr(x)
            if x:
                if len(_floats_kept) >= _MAX_LISTS:
                    _floats_kept.clear()
                _floats_kept[x] = j
        return j
    return _irepr(x) if type(x) is int else None


def severity(stamp_ns: int, m: dict) -> str | None:
    """A ``severity`` message of the paper's mode (no combined severity's fields)."""
    if list(m) != _SEVERITY:
        return None
    s, lv, fr, miss, fail, tr = m["severity_index"], m["level"], m["f_r"], m["missing"], m["failure"], \
        m["transient"]
    an, out, r = m["anomaly"], m["outliers"], m["r"]
    frj = _kept(fr)
    if not (type(s) is float and s - s == 0.0 and type(fr) is float and frj is not None and type(lv) is int
            and type(miss) is int and type(fail) is bool and type(tr) is bool and type(an) is list
            and type(out) is list and type(r) is list):
        return None
    ch, anj, outj, rj = _str(m["channel"]), _ints(an), _ints(out), _floats(r)
    if ch is None or anj is None or outj is None or rj is None:
        return None
    sec, nsec = divmod(stamp_ns, NS)
    return (f'{{"timestamp":{{"sec":{sec},"nsec":{nsec}}},"channel":{ch},"severity_index":{_frepr(s)},'
            f'"level":{_irepr(lv)},"anomaly":{anj},"outliers":{outj},"f_r":{frj},"r":{rj},'
            f'"failure":{"true" if fail else "false"},"missing":{_irepr(miss)},'
            f'"transient":{"true" if tr else "false"}}}')


def indicators(stamp_ns: int, m: dict) -> str | None:
    """An RMS-mode indicator record (the RAW mode's records take the plain path)."""
    if list(m) != _INDICATORS:
        return None
    un = m["unavailable"]
    ch, mode, iv, mf, acc = _str(m["channel"]), _str(m["mode"]), _kept(m["interval_s"]), \
        _num(m["missing_fraction"]), _num(m["accel_rms"])
    unj = _strs(un) if type(un) is list else None
    if ch is None or mode is None or iv is None or mf is None or acc is None or unj is None:
        return None
    sec, nsec = divmod(stamp_ns, NS)
    return (f'{{"timestamp":{{"sec":{sec},"nsec":{nsec}}},"channel":{ch},"mode":{mode},"interval_s":{iv},'
            f'"missing_fraction":{mf},"accel_rms":{acc},"unavailable":{unj}}}')


def _link(d: dict) -> str | None:
    """The JSON of a dict of string keys and int values (kept: the link's counters change with
    each read, not with each decision), None for anything else."""
    if type(d) is not dict or (d and set(map(type, d.values())) != _INT):
        return None
    key = tuple(d.items())              # int values: an equal key has equal ints
    j = _lists.get(key)
    if j is not None:
        return j
    parts = []
    for k, v in d.items():
        kj = _str(k)
        if kj is None:
            return None
        parts.append(f"{kj}:{_irepr(v)}")
    return _keep(_lists, key, "{" + ",".join(parts) + "}")


def diagnostics(stamp_ns: int, m: dict) -> str | None:
    """A ``/cm/diagnostics`` message without the live loop's further fields."""
    if list(m) != _DIAGNOSTICS:
        return None
    link, qd, qdr, lag, obs, up = _link(m["link"]), _num(m["queue_depth"]), _num(m["queue_drops"]), \
        _num(m["lag_s"]), _num(m["observations"]), _num(m["uptime_s"])
    if link is None or qd is None or qdr is None or lag is None or obs is None or up is None:
        return None
    sec, nsec = divmod(stamp_ns, NS)
    return (f'{{"timestamp":{{"sec":{sec},"nsec":{nsec}}},"link":{link},"queue_depth":{qd},'
            f'"queue_drops":{qdr},"lag_s":{lag},"observations":{obs},"uptime_s":{up}}}')


#: schema -> its template: the message's JSON body with the timestamp, or None (the plain path)
TEMPLATES: dict[str, Callable[[int, dict], str | None]] = {
    "severity": severity, "indicators": indicators, "diagnostics": diagnostics,
}
