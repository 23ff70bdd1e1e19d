"""The layering contract of ``server/diathermy``, read from the source (every import, lazy ones
included): each package imports only packages below it, modules import in no cycle, torch is
imported only by the surrogates and the worker, FastAPI only by the service.

    service -> engine -> {physics, surrogates} -> {mesh, fem}; datagen, report, worker above the
    engine; the command line on top.

``python -m tests.test_layering`` prints the package graph.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "server" / "diathermy"

RANK = {
    "errors": 0,
    "version": 0,
    "runtime": 0,
    "": 1,  # diathermy/__init__.py
    "mesh": 2,
    "fem": 2,
    "physics": 3,
    "scene": 4,
    "surrogates": 5,
    "engine": 6,
    "datagen": 7,
    "report": 7,
    "worker": 8,
    "service": 9,
    "cli": 10,
    "__main__": 11,
}
"""A package may import itself and packages of lower rank only."""

ONLY_IN = {"torch": ("surrogates", "worker"), "fastapi": ("service",), "starlette": ("service",)}
"""Third-party packages that only these packages may import."""


def modules(root: Path = PACKAGE) -> dict[str, Path]:
    """Every module of the package: dotted name -> file."""
    out = {}
    for path in root.rglob("*.py"):
        parts = path.relative_to(root.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


def imports(name: str, path: Path, known: dict[str, Path]) -> tuple[set[str], set[str]]:
    """(modules of the package, top-level third-party names) that module ``name`` imports."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    inside, outside = set(), set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*up, *([node.module] if node.module else [])])
            # ``from pkg import submodule`` imports the submodule, not pkg's namespace
            subs = [f"{base}.{a.name}" for a in node.names if f"{base}.{a.name}" in known]
            targets = subs if len(subs) == len(node.names) else [base, *subs]
        else:
            continue
        for t in targets:
            if t.split(".")[0] == "diathermy":
                while t not in known and "." in t:
                    t = t.rpartition(".")[0]
                if t in known and t != name:
                    inside.add(t)
            else:
                outside.add(t.split(".")[0])
    return inside, outside


def graph() -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    """Module graph inside the package, and third-party imports per module."""
    known = modules()
    edges, third = {}, {}
    for name, path in known.items():
        edges[name], third[name] = imports(name, path, known)
    return edges, third


def package_of(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(edges[w]))))
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
                    found.append(sorted(comp))
    return found


def layer_violations(edges: dict[str, set[str]]) -> list[str]:
    out = []
    for a, targets in sorted(edges.items()):
        pa = package_of(a)
        for b in sorted(targets):
            pb = package_of(b)
            if pa != pb and not RANK[pb] < RANK[pa]:
                out.append(f"{a} imports {b}: {pa or 'diathermy'} may not import {pb}")
    return out


def third_party_violations(third: dict[str, set[str]]) -> list[str]:
    out = []
    for module, names in sorted(third.items()):
        for name, allowed in ONLY_IN.items():
            if name in names and package_of(module) not in allowed:
                out.append(f"{module} imports {name}, allowed only in {', '.join(allowed)}")
    return out


def test_every_package_has_a_rank():
    edges, _ = graph()
    assert {package_of(m) for m in edges} <= set(RANK)


def test_packages_import_only_downwards():
    edges, _ = graph()
    assert layer_violations(edges) == []


def test_no_import_cycles():
    edges, _ = graph()
    assert cycles(edges) == []


def test_torch_and_fastapi_stay_in_their_packages():
    _, third = graph()
    assert third_party_violations(third) == []


def test_the_checker_sees_a_back_import_and_a_cycle():
    """The checks can fail: an engine module importing the service, and a two-module cycle."""
    edges = {"diathermy.engine.x": {"diathermy.service.y"}, "diathermy.service.y": set()}
    assert layer_violations(edges) == [
        "diathermy.engine.x imports diathermy.service.y: engine may not import service"
    ]
    assert cycles({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == [["a", "b"]]
    assert third_party_violations({"diathermy.engine.x": {"torch"}})


def package_graph() -> dict[str, set[str]]:
    edges, _ = graph()
    out: dict[str, set[str]] = defaultdict(set)
    for a, targets in edges.items():
        for b in targets:
            if package_of(a) != package_of(b):
                out[package_of(a) or "diathermy"].add(package_of(b) or "diathermy")
    return out


if __name__ == "__main__":
    for pkg, targets in sorted(package_graph().items(), key=lambda kv: -RANK.get(kv[0], 1)):
        print(f"{pkg} -> {', '.join(sorted(targets, key=lambda p: -RANK.get(p, 1)))}")
