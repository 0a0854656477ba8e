"""No import cycles between the modules of twolevel, counting the imports made inside functions.

Every module under ``twolevel/`` is parsed with :mod:`ast`; each ``import a.b`` and
``from a import b`` anywhere in it (module level, functions, methods; relative forms resolved)
that names a module of twolevel is an edge of the import graph. A name imported from a package
is an edge to the submodule of that name when there is one, else to the package. A lazy import
inside a function, or one under ``if TYPE_CHECKING:`` (for annotations only), still makes the two
modules depend on each other — a reader needs both to understand either — so it counts like any
other.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "twolevel"


def modules() -> dict[str, Path]:
    """Dotted name → file of every module of twolevel (a package is its ``__init__.py``)."""
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = path.relative_to(ROOT.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement of ``tree``, at any depth (``if TYPE_CHECKING:`` blocks included)."""
    return [node for node in ast.walk(tree) if isinstance(node, (ast.Import, ast.ImportFrom))]


def _known(name: str, mods: dict[str, Path]) -> str | None:
    """The longest prefix of ``name`` that is a module of twolevel."""
    parts = name.split(".")
    while parts:
        cand = ".".join(parts)
        if cand in mods:
            return cand
        parts.pop()
    return None


def graph() -> dict[str, set[str]]:
    """Module → the twolevel modules it imports (anywhere in its code)."""
    mods = modules()
    out: dict[str, set[str]] = {m: set() for m in mods}
    for mod, path in mods.items():
        is_pkg = path.name == "__init__.py"
        package = mod.split(".") if is_pkg else mod.split(".")[:-1]
        for node in _imports(ast.parse(path.read_text(), str(path))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                base = node.module or ""
                if node.level:
                    anchor = package[: len(package) - (node.level - 1)]
                    base = ".".join(anchor + ([base] if base else []))
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    targets.append(sub if sub in mods else base)
            for t in targets:
                k = _known(t, mods)
                if k is not None and k != mod:
                    out[mod].add(k)
    return out


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of ``g`` with more than one module (Tarjan), each as
    its sorted modules."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    comps: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(g[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                comps.append(sorted(comp))

    for v in sorted(g):
        if v not in index:
            visit(v)
    return comps


def path_through(g: dict[str, set[str]], comp: list[str]) -> list[str]:
    """One cycle inside the component ``comp``, as modules a → b → … → a (shortest from its
    first module)."""
    start, inside = comp[0], set(comp)
    prev: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(g[v] & inside):
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(prev[path[-1]])
                    return [start] + path[::-1][1:] + [start]
                if w not in prev:
                    prev[w] = v
                    nxt.append(w)
        frontier = nxt
    return comp


def test_the_graph_sees_imports_inside_functions_and_relative_ones(tmp_path: Path) -> None:
    """The parser behind the test finds the import forms a cycle can hide in."""
    src = (
        "import twolevel.a\n"
        "from . import b\n"
        "from .c import thing\n"
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n"
        "    import twolevel.d\n"
        "def f():\n"
        "    from twolevel.e import g\n"
        "    class K:\n"
        "        def m(self):\n"
        "            import twolevel.h.i as j\n"
    )
    found = _imports(ast.parse(src))
    names = sorted(n.module or "." if isinstance(n, ast.ImportFrom) else n.names[0].name for n in found)
    assert names == [".", "c", "twolevel.a", "twolevel.d", "twolevel.e", "twolevel.h.i", "typing"]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert path_through({"a": {"b"}, "b": {"c", "a"}, "c": {"a"}}, ["a", "b", "c"]) == ["a", "b", "a"]


def test_no_import_cycles() -> None:
    g = graph()
    found = cycles(g)
    report = "\n".join(" → ".join(path_through(g, c)) + f"   (component: {', '.join(c)})" for c in found)
    assert not found, "import cycles between twolevel's modules:\n" + report


ARCHITECTURE = ROOT.parent / "docs" / "architecture.md"


def layers() -> list[set[str]]:
    """The layer list of ``docs/architecture.md`` ("## Layers", its first ``text`` block), lowest
    first: each line names the packages (or top-level modules) of one layer before its
    description."""
    text = ARCHITECTURE.read_text(encoding="utf-8")
    section = text.split("\n## Layers\n", 1)[1]
    block = section.split("```text\n", 1)[1].split("```", 1)[0]
    out = []
    for line in block.splitlines():
        names = line.split("  ", 1)[0]
        out.append({n.strip() for n in names.split(",") if n.strip()})
    return out[::-1]


def package(module: str) -> str:
    """``twolevel.x.y`` → ``x``; the package itself → ``twolevel``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def test_packages_import_only_their_layer_or_below() -> None:
    """Every package is placed in the documented layers, and none imports one above it."""
    rank = {name: i for i, names in enumerate(layers()) for name in names}
    g = graph()
    unplaced = sorted({package(m) for m in g} - set(rank))
    assert not unplaced, f"packages docs/architecture.md does not place in a layer: {unplaced}"
    up = sorted(f"{m} → {t}" for m, ts in g.items() for t in ts if rank[package(t)] > rank[package(m)])
    assert not up, "imports that go up a layer (docs/architecture.md, Layers):\n" + "\n".join(up)


def test_the_layer_list_parses() -> None:
    found = layers()
    assert found[0] == {"twolevel", "diagnostics", "files", "atomic", "interruption"} and found[-1] == {"cli", "__main__"}
    assert [n for names in found for n in names].count("world") == 1


def test_no_module_getattr_shims() -> None:
    """No module answers attribute lookups itself (``def __getattr__`` at module level): a name
    is found where it is defined or plainly imported."""
    shims = [name for name, path in modules().items()
             if any(isinstance(n, ast.FunctionDef) and n.name == "__getattr__" for n in ast.parse(path.read_text()).body)]
    assert not shims, shims
