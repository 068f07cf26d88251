"""The house rules, checked: no import cycle, no module over 600 lines, no function over 80
lines except the justified hot loops named here, no wire protocol or I/O module imported by the
pure DSP of cmsensord/dsp (CONTRIBUTING.md)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("cmsensord", "firmware_sim")
#: functions allowed over 80 lines, each a hot loop whose docstring says why (none now: the
#: decoder's loop, the last one, was split when the wire kernel took its place)
LONG_FUNCTIONS: set[str] = set()
#: the wire protocol and the I/O at the edges, which nothing in cmsensord/dsp may import
WIRE_AND_IO = ("cmsensord.protocol", "cmsensord.link", "cmsensord.source", "cmsensord.sinks", "cmsensord.service")


def _sources() -> dict[str, Path]:
    """Module name -> file, for every module of the packages."""
    mods = {}
    for pkg in PACKAGES:
        for f in sorted((ROOT / pkg).rglob("*.py")):
            name = ".".join(f.relative_to(ROOT).with_suffix("").parts)
            mods[name.removesuffix(".__init__")] = f
    return mods


def _imports(name: str, path: Path, mods: dict[str, Path], annotations: bool = False) -> set[str]:
    """The package modules ``name`` imports at run time (anywhere in the file, lazily or not);
    with ``annotations``, also those imported for type checking only."""
    pkg = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    typing_only = set() if annotations else {
        id(n) for block in ast.walk(tree) if isinstance(block, ast.If)
        and isinstance(block.test, ast.Name) and block.test.id == "TYPE_CHECKING" for n in ast.walk(block)}
    out = set()
    for node in ast.walk(tree):
        if id(node) in typing_only:            # annotations only: not imported at run time
            continue
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")[: len(pkg.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            cands = [f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in mods] or [target]
        elif isinstance(node, ast.Import):
            cands = [a.name for a in node.names]
        else:
            continue
        for c in cands:
            while c and c not in mods:
                c = c.rsplit(".", 1)[0] if "." in c else ""
            if c and c != name:
                out.add(c)
    return out


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_no_import_cycle():
    mods = _sources()
    graph = {name: _imports(name, path, mods) for name, path in mods.items()}
    assert _cycles(graph) == []


def test_the_cycle_finder_finds_one():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == [["a", "b", "c"]]


def test_dsp_imports_no_wire_protocol_and_no_io():
    """Nothing under cmsensord/dsp imports the wire protocol, the link, the source, the sinks or
    the service, not even for annotations: the DSP takes arrays, never frames or files."""
    mods = _sources()
    found = {f"{name} -> {dep}" for name, path in mods.items() if name.startswith("cmsensord.dsp")
             for dep in _imports(name, path, mods, annotations=True)
             if any(dep == w or dep.startswith(f"{w}.") for w in WIRE_AND_IO)}
    assert found == set()


def test_no_module_over_600_lines():
    """Python modules, and the C kernels' source files too."""
    files = [f for pkg in (*PACKAGES, "tests", "bench") for pattern in ("*.py", "*.c", "*.h")
             for f in (ROOT / pkg).rglob(pattern)]
    long = {str(f.relative_to(ROOT)): n for f in files
            if (n := len(f.read_text(encoding="utf-8").splitlines())) > 600}
    assert long == {}


def test_no_function_over_80_lines_but_the_named_hot_loops():
    long = set()
    for path in _sources().values():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            size = (node.end_lineno or node.lineno) - node.lineno + 1 if isinstance(
                node, (ast.FunctionDef, ast.AsyncFunctionDef)) else 0
            if size > 80:
                long.add(f"{path.relative_to(ROOT)}::{node.name}")
    assert long == LONG_FUNCTIONS


def test_every_monitor_module_is_in_the_architecture_table():
    """docs/architecture.md names each module of the monitoring chain with its one job."""
    table = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    modules = {f.name for f in (ROOT / "cmsensord" / "monitor").glob("*.py") if f.name != "__init__.py"}
    assert {m for m in modules if f"| `{m}` |" not in table} == set()
