"""The import graph of aw, aw_eval, aw_server, aw_view and assemblyworld, read from the source
(ast): no cycles between modules, none between folders (sub-packages such as aw.runner and
aw.agents), and no import from a lower layer into a higher one (aw is beneath aw_eval and
aw_server; aw_eval's kernels are beneath its protocol modules; the viewer, aw_view, is above aw
and aw_eval; the Inspect task, assemblyworld, above aw and aw_eval too). Imports inside
functions and under TYPE_CHECKING count: a lazy import is
still a dependency."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("aw", "aw_eval", "aw_server", "aw_view", "assemblyworld")


def _modules(root: Path) -> dict[str, Path]:
    mods = {}
    for pkg in PACKAGES:
        for f in (root / pkg).rglob("*.py"):
            parts = list(f.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join(parts)] = f
    return mods


def _imports(name: str, path: Path) -> list[tuple[str, str | None]]:
    """``(module, imported name or None)`` for every import statement of module ``name``."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: list[tuple[str, str | None]] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [(a.name, None) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out += [(mod, a.name) for a in node.names]
    return out


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """Module -> the project modules it imports. ``from pkg import name`` points at the module that
    defines ``name``: a submodule of that name, or the submodule the package re-exports it from."""
    mods = _modules(root)
    raw = {m: _imports(m, f) for m, f in mods.items()}

    def owner(mod: str) -> str | None:
        while mod and mod not in mods:
            mod = mod.rpartition(".")[0]
        return mod or None

    def source(mod: str, name: str | None, seen: frozenset = frozenset()) -> str | None:
        mod = owner(mod)
        if mod is None or name is None:
            return mod
        if f"{mod}.{name}" in mods:
            return f"{mod}.{name}"
        if mods[mod].name == "__init__.py" and (mod, name) not in seen:
            for sub, imported in raw[mod]:  # a package re-exporting the name: its defining module
                if imported == name and (owner(sub) or "").startswith(mod + "."):
                    return source(sub, name, seen | {(mod, name)})
        return mod

    graph: dict[str, set[str]] = {m: set() for m in mods}
    for m, imports in raw.items():
        for mod, name in imports:
            target = source(mod, name)
            if target and target != m and not m.startswith(target + "."):
                graph[m].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (iterative Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        found.append(sorted(comp))
    return found


def folder(module: str, packages: set[str]) -> str:
    """The sub-package a module lives in (``aw.runner.batch`` -> ``aw.runner``,
    ``aw_eval.report.html.page`` -> ``aw_eval.report``); a package's top-level modules
    (``aw.scene``) are its own floor, the package name. ``packages``: the modules that have
    submodules."""
    parts = module.split(".")
    return ".".join(parts[:2]) if len(parts) > 2 or module in packages else parts[0]


# Folders allowed to import each other, each with its reason. Empty: every folder stands above
# what it imports.
FOLDER_CYCLE_EXCEPTIONS: dict[frozenset[str], str] = {}


def folder_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """Folder -> the other folders it imports (package top-level modules left out: they are the
    package's own floor, which both its folders and its top files stand on)."""
    packages = {m.rpartition(".")[0] for m in graph}
    out: dict[str, set[str]] = {}
    for m, targets in graph.items():
        src = folder(m, packages)
        if "." not in src:
            continue
        for t in targets:
            dst = folder(t, packages)
            if dst != src and "." in dst:
                out.setdefault(src, set()).add(dst)
                out.setdefault(dst, set())
    return out


def folder_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Groups of folders that import each other, directly or around a loop, less the named exceptions."""
    found = cycles(folder_graph(graph))
    return [c for c in found if frozenset(c) not in FOLDER_CYCLE_EXCEPTIONS]


def _layer(module: str) -> str:
    if module == "aw_eval.kernels" or module.startswith("aw_eval.kernels."):
        return "aw_eval.kernels"
    return module.split(".")[0]


# what each layer may import besides itself (anything else is an upward or sideways import)
ALLOWED = {
    "aw": set(),
    "aw_eval.kernels": {"aw"},
    "aw_eval": {"aw", "aw_eval.kernels"},
    "aw_server": {"aw"},
    "aw_view": {"aw", "aw_eval"},
    "assemblyworld": {"aw", "aw_eval", "aw_eval.kernels"},
}


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    return sorted(
        f"{m} -> {t}"
        for m, targets in graph.items()
        for t in targets
        if _layer(t) != _layer(m) and _layer(t) not in ALLOWED[_layer(m)]
    )


def test_no_import_cycles():
    assert cycles(import_graph()) == []


def test_no_folders_import_each_other():
    assert folder_cycles(import_graph()) == []


def test_folder_cycles_are_seen(tmp_path):
    """On a made-up tree: two folders tied by a function-level import and a TYPE_CHECKING import
    are a folder cycle; a folder importing a package's top-level module that imports it back is not
    (the top files are the package's own floor)."""
    files = {
        "aw/__init__.py": "",
        "aw/top.py": "from aw.runner.batch import run\n",
        "aw/runner/__init__.py": "",
        "aw/runner/batch.py": "from aw.top import x\nfrom aw.agents.a import go\n",
        "aw/agents/__init__.py": "",
        "aw/agents/a.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from aw.runner.batch import run\n",
    }
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    graph = import_graph(tmp_path)
    assert folder_graph(graph) == {"aw.runner": {"aw.agents"}, "aw.agents": {"aw.runner"}}
    assert folder_cycles(graph) == [["aw.agents", "aw.runner"]]


def test_no_upward_imports():
    assert upward_imports(import_graph()) == []


def test_the_checks_see_cycles_and_upward_imports(tmp_path):
    """On a made-up tree: a lazy two-module cycle, one through a package's re-export, and an
    upward import are all reported; a package importing its own submodules is not a cycle."""
    files = {
        "aw/__init__.py": "",
        "aw/a.py": "def f():\n    from aw.b import g\n",
        "aw/b.py": "from aw import a\n",
        "aw/pkg/__init__.py": "from aw.pkg.inner import h\n",
        "aw/pkg/inner.py": "from aw.c import k\n",
        "aw/c.py": "from aw.pkg import h\n",
        "aw/d.py": "import aw_eval.x\n",
        "aw_eval/__init__.py": "from aw_eval.x import y\n",
        "aw_eval/x.py": "from aw_eval.kernels import z\n",
        "aw_eval/kernels/__init__.py": "from aw_eval.kernels.z import z\n",
        "aw_eval/kernels/z.py": "from aw_eval import x\n",
        "aw_server/__init__.py": "",
        "aw_view/__init__.py": "",
    }
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    graph = import_graph(tmp_path)
    assert sorted(cycles(graph)) == [["aw.a", "aw.b"], ["aw.c", "aw.pkg.inner"], ["aw_eval.kernels.z", "aw_eval.x"]]
    assert upward_imports(graph) == ["aw.d -> aw_eval.x", "aw_eval.kernels.z -> aw_eval.x"]


@pytest.mark.parametrize("package", PACKAGES)
def test_every_package_is_read(package):
    assert any(m == package or m.startswith(package + ".") for m in import_graph())
