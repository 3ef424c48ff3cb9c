"""The import graph of our packages, read from the source files' syntax trees: every import
statement, at module level and inside functions alike (a function-level import is a
dependency all the same, only a later one). Nodes are dotted module names; an import of a
name that is not a module of ours (``from fsw.health import JetHealth``) is an edge to the
module that defines it, an import of another package's module (numpy, zenoh) is no edge.
"""
from __future__ import annotations

import ast
from collections import deque
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("fsw", "sim", "gse", "common", "interfaces", "ellipsled", "tests")
GENERATED = ROOT / "interfaces" / "mavlink" / "generated"      # pymavlink's output: imports the stdlib only


def modules(root: Path = ROOT, packages=PACKAGES) -> dict[str, Path]:
    """Dotted name -> source file of every module of ``packages`` under ``root``."""
    out = {}
    for pkg in packages:
        for p in sorted((root / pkg).rglob("*.py")):
            if GENERATED in p.parents:
                continue
            parts = p.relative_to(root).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return out


def _ours(name: str, known) -> str | None:
    """The module of ours ``name`` is, or is defined in (its longest known prefix)."""
    while name and name not in known:
        name = name.rpartition(".")[0]
    return name or None


def imports_of(name: str, path: Path, known) -> set[str]:
    """The modules of ours (among ``known``) that module ``name`` at ``path`` imports."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module
            # ``from pkg import sub`` imports the module pkg.sub; ``from mod import name`` imports mod
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in known else mod for a in node.names]
        else:
            continue
        out.update(t for t in (_ours(x, known) for x in targets) if t is not None)
    out.discard(name)
    return out


def graph(root: Path = ROOT, packages=PACKAGES) -> dict[str, set[str]]:
    """Module -> the modules of ours it imports."""
    mods = modules(root, packages)
    return {name: imports_of(name, path, mods) for name, path in mods.items()}


def _components(g: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of ``g`` with more than one module (Tarjan, iterative)."""
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    for start in sorted(g):
        if start in index:
            continue
        work = [(start, iter(sorted(g[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(g.get(w, ())))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
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
                    out.append(sorted(comp))
    return out


def _circle_through(g: dict[str, set[str]], start: str, within: set[str]) -> list[str]:
    """A shortest import path from ``start`` back to itself inside ``within``: [start, ..., start]."""
    came = {start: None}
    queue = deque([start])
    while queue:
        v = queue.popleft()
        for w in sorted(g[v] & within):
            if w == start:
                path = [v]                          # v, its parent, ..., start
                while came[path[-1]] is not None:
                    path.append(came[path[-1]])
                return path[::-1] + [start]
            if w not in came:
                came[w] = v
                queue.append(w)
    raise ValueError(f"{start} is on no circle")


def circles(g: dict[str, set[str]]) -> list[list[str]]:
    """One import circle per set of modules that import each other, each as a path
    [a, b, ..., a] through the set's first module."""
    return [_circle_through(g, comp[0], set(comp)) for comp in _components(g)]


def _packages_of(name: str, g: dict[str, set[str]]) -> list[str]:
    """The packages of ours that hold module ``name`` (importing it runs their __init__)."""
    parts = name.split(".")
    return [p for p in (".".join(parts[:i]) for i in range(1, len(parts))) if p in g]


def _edges(g: dict[str, set[str]], v: str, with_packages: bool) -> list[str]:
    return sorted(g.get(v, set()) | (set(_packages_of(v, g)) if with_packages else set()))


def reachable(g: dict[str, set[str]], start: str, with_packages: bool = False) -> set[str]:
    """Every module ``start`` imports, directly or through others (``start`` included);
    ``with_packages``: with the packages that hold each (and what they import)."""
    seen, todo = {start}, [start]
    while todo:
        for w in _edges(g, todo.pop(), with_packages):
            if w not in seen:
                seen.add(w)
                todo.append(w)
    return seen


def import_path(g: dict[str, set[str]], start: str, goal: str) -> list[str]:
    """A shortest chain of imports [start, ..., goal] (through the packages that hold modules too)."""
    came = {start: None}
    queue = deque([start])
    while queue:
        v = queue.popleft()
        if v == goal:
            path = [v]
            while came[path[-1]] is not None:
                path.append(came[path[-1]])
            return path[::-1]
        for w in _edges(g, v, True):
            if w not in came:
                came[w] = v
                queue.append(w)
    raise ValueError(f"{start} does not reach {goal}")
