"""Reading one YAML configuration file, strictly: a regular file of at most
:data:`MAX_CONFIG_BYTES` in UTF-8 (never a FIFO's wait or a device read to the end), a key given
twice is an error, aliases expand to at most :data:`MAX_YAML_NODES` values, ``4e-3`` is a float
(YAML 1.2), and a scalar Python cannot make is refused with its place; every failure one
:class:`~.validation.ConfigError` line."""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path
from typing import Any

import yaml

from cmsensord.errors import file_kind

from .validation import ConfigError

__all__ = ["read_yaml", "MAX_CONFIG_BYTES", "MAX_YAML_NODES"]


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that rejects a key given twice in one mapping."""

    def get_single_node(self) -> Any:
        """The document's node graph, refused before construction if its aliases expand too far."""
        node = super().get_single_node()
        if node is not None:
            _expanded_nodes(node)
        return node

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, yaml.MappingNode):
            seen: set[Any] = set()
            for key_node, _value_node in node.value:
                key = self.construct_object(key_node, deep=True)
                try:
                    duplicate = key in seen
                    seen.add(key)
                except TypeError:  # unhashable key: SafeLoader reports it below
                    continue
                if duplicate:
                    raise yaml.constructor.ConstructorError(
                        "while constructing a mapping",
                        node.start_mark,
                        f"found duplicate key {key!r}",
                        key_node.start_mark,
                    )
        return super().construct_mapping(node, deep=deep)

    def construct_object(self, node: Any, deep: bool = False) -> Any:
        """A node's value; a scalar Python cannot make one of (a whole number of more than
        4,300 digits, a date with month 13, an empty ``!!int``) is refused with its place in the
        file (:func:`_unmade`)."""
        try:
            return super().construct_object(node, deep=deep)
        except (ValueError, OverflowError, IndexError, KeyError, AttributeError, TypeError) as err:
            if not isinstance(node, yaml.ScalarNode):
                raise
            mark = node.start_mark
            raise _TooLarge(f"line {mark.line + 1}, column {mark.column + 1}: {_unmade(node, err)}") from None


def _unmade(node: yaml.ScalarNode, err: Exception) -> str:
    """Why the scalar ``node`` (its tag, as written or resolved) makes no value: a whole number
    past the digits Python converts, or the value is not what its tag says."""
    value, kind = str(node.value), node.tag.rpartition(":")[2]
    shown = repr(value if len(value) <= 40 else value[:37] + "...")
    if kind == "int" and value.lstrip("+-").replace("_", "").isdigit():
        return f"number too large (a whole number of {len(value):,} characters)"
    if kind == "timestamp" and isinstance(err, ValueError) and str(err):
        return f"not a date ({err})"
    what = {"int": "a whole number", "float": "a number", "timestamp": "a date", "bool": "true or false"}
    return f"not {what.get(kind, f'a YAML {kind}')} ({shown})"


_StrictLoader.add_constructor(
    yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _StrictLoader.construct_mapping
)
# PyYAML follows YAML 1.1, where an exponent needs a dot and a sign: "4e-3" and "1.0e300"
# are strings there. Accept every exponent form as a float, as YAML 1.2 does ("4e-3" is
# how the paper writes R_min).
_StrictLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)


#: the largest configuration file read: the defaults with comments are ~10 kB
MAX_CONFIG_BYTES = 1 << 20
#: the most YAML nodes a document may stand for once every alias is expanded
MAX_YAML_NODES = 100_000


def _read_text(path: str | Path, source: str) -> str:
    """The text of a regular file of at most MAX_CONFIG_BYTES; anything else is a ConfigError.

    The file is opened non-blocking, so a FIFO never waits for a writer, and its type is
    checked on the open descriptor before anything is read (a device such as /dev/zero
    is refused, not read to the end of memory).
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise ConfigError(source, None, "file not found (`cmsensord config --default > FILE` writes one with every "
                          "setting)") from None
    except PermissionError:
        raise ConfigError(source, None, "cannot read: permission denied") from None
    except OSError as err:
        raise ConfigError(source, None, f"cannot read: {err.strerror or err}") from None
    except ValueError as err:  # a name the OS cannot take (a NUL byte, shown escaped)
        reason = "not a usable file name: it contains a NUL byte" if "\0" in source else f"cannot read: {err}"
        raise ConfigError(source.replace("\0", "\\0"), None, reason) from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        if stat.S_ISDIR(mode):
            raise ConfigError(source, None, "is a directory, not a file")
        raise ConfigError(source, None, f"not a regular file (a {file_kind(mode)}); "
                          "give the path of a YAML file")
    with os.fdopen(fd, "rb") as f:
        try:
            data = f.read(MAX_CONFIG_BYTES + 1)
        except OSError as err:
            raise ConfigError(source, None, f"cannot read: {err.strerror or err}") from None
    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(source, None, f"larger than {MAX_CONFIG_BYTES} bytes: not a configuration file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ConfigError(source, None, _not_text(source, data, err.start)) from None


def _not_text(source: str, data: bytes, start: int) -> str:
    """Why the configuration file ``source`` (its bytes ``data``) is no text: an MCAP log or a
    capture given as the configuration, with what reads it, or the first byte that is not UTF-8."""
    from cmsensord.sinks.mcap_chunks import MAGIC
    from cmsensord.sinks.mcap_records import is_capture

    site = "--config takes a YAML site file (`cmsensord config --default > site.yaml` writes one)"
    if data.startswith(MAGIC):
        return (f"an MCAP log (cmsensord's output), not a configuration: `cmsensord summary` and "
                f"`cmsensord report` read it; {site}")
    if is_capture(source):
        return (f"a capture of the board's serial stream, not a configuration: replay, calibrate and vkf read "
                f"it (`cmsensord replay {source} --config site.yaml`); {site}")
    return f"not UTF-8 text (byte offset {start})"


class _TooLarge(Exception):
    """Internal: the YAML document stands for too many nodes (aliases), or refers to itself,
    or holds a value Python cannot make (a whole number past 4,300 digits, an impossible date)."""


def _expanded_nodes(root: yaml.Node) -> int:
    """How many nodes ``root`` stands for with every alias expanded (shared nodes counted each
    time they are referred to), computed without expanding; raises _TooLarge past
    MAX_YAML_NODES or when a node contains itself."""
    sizes: dict[int, int] = {}
    open_nodes: set[int] = set()

    def size(node: yaml.Node) -> int:
        key = id(node)
        if key in sizes:
            return sizes[key]
        if key in open_nodes:
            raise _TooLarge("a YAML alias refers to a node that contains it (a recursive structure)")
        total = 1
        if isinstance(node, (yaml.SequenceNode, yaml.MappingNode)):
            open_nodes.add(key)
            children = (node.value if isinstance(node, yaml.SequenceNode)
                        else [n for pair in node.value for n in pair])
            for child in children:
                total += size(child)
                if total > MAX_YAML_NODES:
                    raise _TooLarge(f"YAML aliases expand to more than {MAX_YAML_NODES} values")
            open_nodes.discard(key)
        sizes[key] = total
        return total

    return size(root)


def _yaml_reason(err: yaml.YAMLError) -> str:
    mark = getattr(err, "problem_mark", None) or getattr(err, "context_mark", None)
    problem = getattr(err, "problem", None) or getattr(err, "context", None) or str(err)
    if "'\\t'" in problem:
        problem += ": indent with spaces, not tabs"
    if mark is not None:
        return f"YAML syntax error at line {mark.line + 1}, column {mark.column + 1}: {problem}"
    return f"YAML syntax error: {problem}"


def read_yaml(path: str | Path, source: str) -> Any:
    """The document of the YAML file ``path`` (None when it is empty or comments only);
    ConfigError naming ``source`` when it cannot be read or is no good YAML."""
    text = _read_text(path, source)
    try:
        return yaml.load(text, Loader=_StrictLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as err:
        raise ConfigError(source, None, _yaml_reason(err)) from None
    except RecursionError:
        raise ConfigError(source, None, "YAML nested too deeply") from None
    except _TooLarge as err:
        raise ConfigError(source, None, str(err)) from None
