"""No import cycles among the project's modules (synth, blender_scripts, renderer_jobs, prior).

The graph is built statically with ``ast``, so bpy and torch need not be installed. Every
``import`` statement counts, at module level or inside a function (also under
``if TYPE_CHECKING:``); relative imports are resolved. ``import a.b.c`` (or ``from a.b.c
import x``) is an edge to ``a.b.c`` and to the packages ``a`` and ``a.b`` that are modules of
the project (have an ``__init__.py``), because importing it runs their ``__init__`` first;
except a package that contains the importing module, which is already being imported by then.
``from a.b import name`` is an edge to ``a.b.name`` when that is a module, else to ``a.b``.
In a file that calls ``importlib.import_module``, every string constant that names a project
module counts as ``import`` of it (a table of names imported in a loop, too); a name built at run
time is not seen.
"""

from __future__ import annotations

import ast
from collections import deque
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("synth", "blender_scripts", "renderer_jobs", "prior")
#: Cycles known when this test was written, each to be removed here when its fix lands (the
#: test fails for a new cycle, and for a listed one that is gone).
KNOWN_CYCLES: set[tuple[str, ...]] = set()


def project_modules(root: Path, packages=PACKAGES) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` file under the packages."""
    mods = {}
    for pkg in packages:
        for path in sorted((root / pkg).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join(parts)] = path
    return mods


def _imported_names(name: str, path: Path, mods: dict[str, Path]) -> list[str]:
    """The module names one file's import statements name (before the package rule)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = []
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    if any(isinstance(n, ast.Call) and _is_import_module(n.func) for n in ast.walk(tree)):
        # a file that imports by name: every string naming a project module is an edge (names
        # kept in a table and passed to import_module in a loop, too)
        out.extend(n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and n.value in mods)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.extend(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[:len(parts) - (node.level - 1)] + ([node.module] if node.module else []))
            else:
                base = node.module
            for a in node.names:
                sub = f"{base}.{a.name}"
                out.append(sub if sub in mods else base)
    return out


def _is_import_module(func: ast.expr) -> bool:
    return (isinstance(func, ast.Attribute) and func.attr == "import_module") or \
        (isinstance(func, ast.Name) and func.id == "import_module")


def import_graph(root: Path = ROOT, packages=PACKAGES) -> dict[str, set[str]]:
    """Module -> the project modules its import statements import (see the module docstring)."""
    mods = project_modules(root, packages)
    graph: dict[str, set[str]] = {}
    for name, path in mods.items():
        own = name.split(".")
        ancestors = {".".join(own[:i]) for i in range(1, len(own))}
        edges = set()
        for target in _imported_names(name, path, mods):
            parts = target.split(".")
            for i in range(1, len(parts)):
                prefix = ".".join(parts[:i])
                if prefix in mods and prefix not in ancestors:
                    edges.add(prefix)
            if target in mods:
                edges.add(target)
        edges.discard(name)
        graph[name] = edges
    return graph


def find_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle (``[a, b, ..., a]``) per strongly connected component with more than one module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []

    def visit(v: str) -> None:  # Tarjan; the project is small enough for recursion
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                components.append(comp)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return [_cycle_in(graph, comp) for comp in components]


def _cycle_in(graph: dict[str, set[str]], comp: set[str]) -> list[str]:
    """A shortest cycle through the component's first module (breadth-first)."""
    start = min(comp)
    parent = {start: start}
    queue = deque([start])
    while queue:
        v = queue.popleft()
        for w in sorted(graph[v] & comp):
            if w == start:
                path = [v]
                while path[-1] != start:
                    path.append(parent[path[-1]])
                return path[::-1] + [start]
            if w not in parent:
                parent[w] = v
                queue.append(w)
    raise AssertionError(f"no cycle in component {sorted(comp)}")  # pragma: no cover


def test_no_import_cycles_in_the_project():
    graph = import_graph()
    assert "synth.dataset.shards" in graph and "blender_scripts.worker" in graph
    cycles = {tuple(c[:-1]): c for c in find_cycles(graph)}
    new = [c for k, c in cycles.items() if k not in KNOWN_CYCLES]
    assert not new, "import cycle(s):\n" + "\n".join(" -> ".join(c) for c in new)
    gone = KNOWN_CYCLES - set(cycles)
    assert not gone, f"cycle(s) {sorted(gone)} no longer exist: remove them from KNOWN_CYCLES"


def test_dataset_imports_nothing_above_it():
    graph = import_graph()
    upward = ("synth.plan", "synth.cli", "synth.render", "blender_scripts", "renderer_jobs", "prior")
    bad = {m: sorted(t for t in ts if t.startswith(upward)) for m, ts in graph.items()
           if m.startswith("synth.dataset")}
    assert {m: ts for m, ts in bad.items() if ts} == {}


def _write(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)


def test_the_checker_finds_cycles(tmp_path):
    _write(tmp_path, {
        "pkg/__init__.py": "",
        "pkg/a.py": "import os\nfrom pkg.b import f\n",
        "pkg/b.py": "def f():\n    from . import a\n",              # function-level, relative
        "pkg/sub/__init__.py": "from pkg.c import g\n",               # a package __init__ ...
        "pkg/sub/m.py": "",
        "pkg/c.py": "def g():\n    import pkg.sub.m\n",               # ... runs when pkg.sub.m is imported
        "pkg/d.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.e import E\n",
        "pkg/e.py": "from .d import *\n",
        "pkg/ok/__init__.py": "from .x import X\n",                   # re-exports are not cycles
        "pkg/ok/x.py": "from pkg.ok.y import Y\nX = 1\n",
        "pkg/ok/y.py": "Y = 2\n",
        "pkg/f.py": "import importlib\nfor m in ('pkg.g',):\n    importlib.import_module(m)\n",
        "pkg/g.py": "def main():\n    from pkg.f import x\n",              # by string one way, plainly back
    })
    graph = import_graph(tmp_path, ("pkg",))
    assert graph["pkg.b"] == {"pkg.a"} and graph["pkg.c"] == {"pkg.sub", "pkg.sub.m"}
    assert graph["pkg.ok.x"] == {"pkg.ok.y"} and graph["pkg.ok"] == {"pkg.ok.x"}
    cycles = sorted(find_cycles(graph))
    assert cycles == [["pkg.a", "pkg.b", "pkg.a"], ["pkg.c", "pkg.sub", "pkg.c"], ["pkg.d", "pkg.e", "pkg.d"],
                      ["pkg.f", "pkg.g", "pkg.f"]]
