"""The repository describes itself truly: the README's layout lists exactly the packages and
top-level modules on disk, the files it and docs/architecture.md name exist, nothing cites a
document outside the repository, and the tests share helpers only through ``tests/helpers``."""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PKG = REPO / "twolevel"


def _layout() -> dict[str, str]:
    """The README's ``## Layout`` block: entry (``twolevel/x/``, ``twolevel/x.py``,
    ``twolevel/x/y/`` for an indented sub-package, or another top-level path) → its text."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    block = text.split("\n## Layout\n", 1)[1].split("```\n", 1)[1].split("```", 1)[0]
    entries: dict[str, str] = {}
    top = current = ""
    for line in block.splitlines():
        m = re.match(r"^(\S+)\s+(.*)$", line)
        sub = re.match(r"^  (\w+/)\s+(.*)$", line)
        if m:
            top = current = m.group(1)
            entries[current] = m.group(2)
        elif sub:
            current = top + sub.group(1)
            entries[current] = sub.group(2)
        else:
            entries[current] += " " + line.strip()
    return entries


def test_the_readme_layout_lists_the_packages_on_disk() -> None:
    listed = {e for e in _layout() if e.startswith("twolevel/")}
    on_disk = {f"twolevel/{p.name}" for p in PKG.glob("*.py") if p.name != "__init__.py"}
    on_disk |= {f"{p.parent.relative_to(REPO)}/" for p in PKG.rglob("__init__.py") if p.parent != PKG}
    assert listed == on_disk, (sorted(on_disk - listed), sorted(listed - on_disk))


def test_the_files_the_readme_layout_names_exist() -> None:
    for entry, text in _layout().items():
        assert (REPO / entry).exists(), entry
        if entry.endswith("/"):
            for name in re.findall(r"\b(\w+\.(?:py|lark))\b", text):
                assert (REPO / entry / name).exists(), f"{entry} names {name}, which it does not hold"


def test_the_paths_docs_architecture_names_exist() -> None:
    text = (REPO / "docs" / "architecture.md").read_text(encoding="utf-8")
    paths = set(re.findall(r"`((?:twolevel|tests|benchmarks)/[\w/.]+)`", text))
    assert len(paths) > 20
    missing = sorted(p for p in paths if not (REPO / p).exists())
    assert not missing, missing
    for dotted in set(re.findall(r"`((?:stl|monitor|models|world|milp|compiler|safety|control|sim)\.[\w.]+)", text)):
        module, rest = dotted, []
        while module and not ((PKG / module.replace(".", "/")).with_suffix(".py").exists()
                              or (PKG / module.replace(".", "/") / "__init__.py").exists()):
            module, _, last = module.rpartition(".")
            rest.insert(0, last)
        assert module, dotted
        obj = importlib.import_module(f"twolevel.{module}")
        for name in rest:
            assert hasattr(obj, name), dotted
            obj = getattr(obj, name)


# Built from pieces so that this file does not cite what it forbids.
FORBIDDEN = re.compile("|".join([r"design\.md", r"anchors\.md", "proto" + "type", r"\bissue [0-9]",
                                 r"(?<![\w.])/(?:work|home|root|tmp)/"]), re.IGNORECASE)


def test_nothing_cites_a_document_outside_the_repository() -> None:
    """Code, tests, benchmarks, examples and docs cite docs/architecture.md or a module, never a
    document that is not in the repository, an issue number or a path of one machine."""
    found = []
    roots = [REPO / d for d in ("twolevel", "tests", "benchmarks", "examples", "docs", "rules", "maps", "scenarios")]
    for path in [REPO / "README.md"] + [p for r in roots for p in r.rglob("*") if p.is_file()]:
        if path.suffix not in (".py", ".md", ".stl", ".yaml", ".yml", ".lark", ".toml") or path == Path(__file__):
            continue
        for i, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            if FORBIDDEN.search(line):
                found.append(f"{path.relative_to(REPO)}:{i}: {line.strip()}")
    assert not found, "\n".join(found)


def test_tests_share_helpers_only_through_the_helpers_package() -> None:
    """No test edits ``sys.path``, and no test module imports another test module (shared code is
    in ``tests/helpers``, on the path through pytest's ``pythonpath``)."""
    tests = REPO / "tests"
    test_modules = {p.stem for p in tests.rglob("test_*.py")}
    bad = []
    for path in tests.rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and node.attr == "path" and isinstance(node.value, ast.Name) \
                    and node.value.id == "sys":
                bad.append(f"{path.relative_to(REPO)}:{node.lineno}: sys.path")
            if isinstance(node, ast.ImportFrom) and node.module:
                parts = set(node.module.split("."))
                if parts & test_modules or node.module.startswith("tests") or node.level:
                    bad.append(f"{path.relative_to(REPO)}:{node.lineno}: from {node.module}")
    assert not bad, bad
