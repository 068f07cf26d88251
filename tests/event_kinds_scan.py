"""The event kinds the daemon's code can write, read from its source.

An event record is made by a call to one of ``EMITTERS`` (``Event(kind, ...)``,
``proc.event(kind, ...)``, ``sink.emit(kind, ...)``, ``messages.event(stamp, kind, ...)``,
...). :func:`scan` walks every module of ``cmsensord`` but the report (which reads logs and
writes none) and resolves the kind of each such call: a string constant, either branch of a
conditional, a module constant (``DISK_EVENT``, ``tacho.edges.LOST``, the values of a dict
such as ``alarms.manager.KIND``) or a local assigned only constants. A kind passed on from
elsewhere (a parameter of the function, an object's ``.kind``, a name in ``FORWARDS``) is
made by another call the scan also resolves. Anything else (an f-string, a call) is a
problem: the schema's enum could not be checked against it.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "cmsensord"

#: callee name -> index of the kind among its positional arguments
EMITTERS = {"Event": 0, "TachoEvent": 0, "Transition": 0, "event": 0, "_event": 0, "emit": 0,
            "on_event": 0, "_on_event": 0}
#: ``module.callee`` whose kind is elsewhere: messages.event(stamp_ns, kind, ...)
EMITTERS_AT = {"messages.event": 1}
#: (module, function) -> the names there that pass on kinds made elsewhere
FORWARDS = {
    ("cmsensord/service/live.py", "link_events"): {"kind"},     # the link reader's (link.py _event)
    ("cmsensord/sinks/sink_events.py", "_deliver"): {"kind"},   # the sink's own emit()'s, queued
    ("cmsensord/sinks/tee.py", "drain_events"): {"kind"},       # the publisher's (publisher.py _event)
}


def _constants(tree: ast.Module) -> dict[str, list[str]]:
    """Module-level names bound to a string, or to a dict whose values are all strings."""
    out: dict[str, list[str]] = {}
    for node in tree.body:
        if isinstance(node, ast.Assign | ast.AnnAssign) and node.value is not None:
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            v = node.value
            if isinstance(v, ast.Constant) and isinstance(v.value, str):
                values = [v.value]
            elif isinstance(v, ast.Dict) and v.values and all(
                    isinstance(x, ast.Constant) and isinstance(x.value, str) for x in v.values):
                values = [x.value for x in v.values]        # type: ignore[union-attr]
            else:
                continue
            out.update({t.id: values for t in targets if isinstance(t, ast.Name)})
    return out


def _modules() -> dict[str, ast.Module]:
    return {str(p.relative_to(ROOT)): ast.parse(p.read_text(), str(p))
            for p in sorted(PACKAGE.rglob("*.py")) if "report" not in p.relative_to(PACKAGE).parts}


def _imported(tree: ast.Module, consts: dict[str, dict[str, list[str]]]) -> dict[str, list[str]]:
    """The constants a module imports by name (``from cmsensord.x import NAME``)."""
    out: dict[str, list[str]] = {}
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("cmsensord"):
            mod = consts.get(node.module.replace(".", "/") + ".py", {})
            out.update({a.asname or a.name: mod[a.name] for a in node.names if a.name in mod})
    return out


class _Kinds(ast.NodeVisitor):
    def __init__(self, module: str, names: dict[str, list[str]]) -> None:
        self.module, self.names = module, names
        self.kinds: dict[str, set[str]] = {}
        self.fields: dict[str, set[str]] = {}
        self.problems: list[str] = []
        self._funcs: list[ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda] = []

    def visit_FunctionDef(self, node: ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda) -> None:
        self._funcs.append(node)
        self.generic_visit(node)
        self._funcs.pop()

    visit_AsyncFunctionDef = visit_Lambda = visit_FunctionDef  # type: ignore[assignment]

    def visit_Call(self, node: ast.Call) -> None:
        self.generic_visit(node)
        f = node.func
        name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
        dotted = f"{f.value.id}.{f.attr}" if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) else ""
        at = EMITTERS_AT.get(dotted, EMITTERS.get(name))
        if at is None or len(node.args) + len(node.keywords) < 2:
            return                      # not an emitter; threading.Event(), a callback given a list
        kw = [k.value for k in node.keywords if k.arg == "kind"]
        expr = kw[0] if kw else node.args[at] if len(node.args) > at else None
        where = f"{self.module}:{node.lineno}"
        if expr is None or isinstance(expr, ast.Starred):
            self.problems.append(f"{where}: {ast.unparse(node)[:80]}: no kind argument")
            return
        for kind in self._resolve(expr, where):
            self.kinds.setdefault(kind, set()).add(where)
        for field in self._fields(node, name):
            self.fields.setdefault(field, set()).add(where)

    @staticmethod
    def _fields(node: ast.Call, name: str) -> list[str]:
        """The extra fields the call gives its event: keyword arguments, and the keys of an
        Event's ``fields`` dict."""
        out = [k.arg for k in node.keywords if k.arg not in (None, "kind", "log_level", "fields")]
        given = [k.value for k in node.keywords if k.arg == "fields"] + node.args[4:5]
        if name == "Event" and given and isinstance(given[0], ast.Dict):
            out += [k.value for k in given[0].keys if isinstance(k, ast.Constant) and isinstance(k.value, str)]
        return out

    def _resolve(self, e: ast.expr, where: str) -> list[str]:
        if isinstance(e, ast.Constant) and isinstance(e.value, str):
            return [e.value]
        if isinstance(e, ast.IfExp):
            return self._resolve(e.body, where) + self._resolve(e.orelse, where)
        if isinstance(e, ast.Attribute) and e.attr == "kind":
            return []                   # an event object's kind: made where the object is
        if isinstance(e, ast.Subscript) and isinstance(e.value, ast.Name) and e.value.id in self.names:
            return self.names[e.value.id]
        if isinstance(e, ast.Name):
            if e.id in self.names:
                return self.names[e.id]
            func = self._funcs[-1] if self._funcs else None
            if func is not None:
                a = func.args
                if e.id in {p.arg for p in a.posonlyargs + a.args + a.kwonlyargs}:
                    return []           # passed in: resolved at the callers
                if e.id in FORWARDS.get((self.module, getattr(func, "name", "<lambda>")), ()):
                    return []
                local = self._locals(func, e.id)
                if local is not None:
                    return [k for v in local for k in self._resolve(v, where)]
        self.problems.append(f"{where}: event kind {ast.unparse(e)!r} is not a constant")
        return []

    @staticmethod
    def _locals(func: ast.AST, name: str) -> list[ast.expr] | None:
        """The values assigned to local ``name`` in ``func`` when every binding is a plain assignment."""
        values: list[ast.expr] = []
        for node in ast.walk(func):
            if isinstance(node, ast.Name) and node.id == name and isinstance(node.ctx, ast.Store):
                parents = [a for a in ast.walk(func) if isinstance(a, ast.Assign) and node in a.targets]
                if not parents:
                    return None
                values.append(parents[0].value)
        return values or None


def scan() -> tuple[dict[str, set[str]], dict[str, set[str]], list[str]]:
    """(kind -> the places that write it, extra field -> the places that give it, problems:
    kinds that are not constants)."""
    trees = _modules()
    consts = {m: _constants(t) for m, t in trees.items()}
    kinds: dict[str, set[str]] = {}
    fields: dict[str, set[str]] = {}
    problems: list[str] = []
    for module, tree in trees.items():
        v = _Kinds(module, {**_imported(tree, consts), **consts[module]})
        v.visit(tree)
        for k, where in v.kinds.items():
            kinds.setdefault(k, set()).update(where)
        for k, where in v.fields.items():
            fields.setdefault(k, set()).update(where)
        problems += v.problems
    return kinds, fields, problems
