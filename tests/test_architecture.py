"""The package's structure stays as docs/architecture.md describes it: modules of one
concept (short), no import cycles (not even through imports inside functions or for typing),
the layers importing only downwards, no private name used outside its module (nor by the
tests and benchmarks), no god classes."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "lhgraph"
MAX_LINES = 450

# the rank of each subpackage: a module imports from its own rank or lower ones only
LAYERS = {
    "errors": 0, "choices": 0, "geometry": 1, "config": 2, "model": 2, "io": 2,
    "signal": 3, "device": 3,
    "estimation": 4, "sim": 4, "importers": 5, "report": 6, "workflow": 7, "cli": 8,
}


@functools.cache
def modules() -> dict[str, Path]:
    return {".".join(("lhgraph", *p.relative_to(PACKAGE).with_suffix("").parts))
            .removesuffix(".__init__"): p for p in PACKAGE.rglob("*.py")}


def imported(node: ast.ImportFrom | ast.Import) -> set[str]:
    """The lhgraph modules one import statement loads (``from lhgraph.x import y`` loads
    ``lhgraph.x.y`` when that is a module, else ``lhgraph.x``)."""
    if isinstance(node, ast.Import):
        return {a.name for a in node.names if a.name.startswith("lhgraph")}
    if not node.module or node.level or not node.module.startswith("lhgraph"):
        return set()
    mods = modules()
    return {f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in mods else node.module
            for a in node.names}


def all_imports(path: Path) -> set[str]:
    """Every lhgraph module ``path`` imports, at module level, in functions or for typing."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom | ast.Import):
            out |= imported(node)
    return out


def layer(module: str) -> int:
    return LAYERS[module.split(".")[1]]


@pytest.mark.parametrize("name", sorted(modules()))
def test_module_is_short(name):
    lines = len(modules()[name].read_text().splitlines())
    assert lines <= MAX_LINES, f"{name}: {lines} lines (split it by concept)"


def test_no_import_cycle():
    mods = modules()
    graph = {m: {i for i in all_imports(p) if i in mods and i != m} for m, p in mods.items()}
    state: dict[str, int] = {}

    def visit(m: str, stack: list[str]) -> None:
        state[m] = 1
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                cycle = stack[stack.index(n):] + [n] if n in stack else [m, n]
                raise AssertionError("import cycle: " + " -> ".join(cycle))
            if n not in state:
                visit(n, [*stack, n])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])


def private_uses(path: Path) -> list[str]:
    """Where ``path`` uses another lhgraph module's private name (``from lhgraph.x import
    _y`` or ``lhgraph_module._y``), as ``line: name``."""
    tree = ast.parse(path.read_text())
    mods = modules()
    aliases: set[str] = set()
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("lhgraph"):
            for a in node.names:
                if f"{node.module}.{a.name}" in mods:
                    aliases.add(a.asname or a.name)
                if a.name.startswith("_") and not a.name.startswith("__"):
                    out.append(f"{node.lineno}: {node.module}.{a.name}")
        elif isinstance(node, ast.Import):
            aliases |= {a.asname or a.name.split(".")[0] for a in node.names
                        if a.name.startswith("lhgraph")}
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and node.attr.startswith("_")
                and not node.attr.startswith("__")):
            base = ast.unparse(node.value)
            if base in aliases or base.startswith("lhgraph."):
                out.append(f"{node.lineno}: {base}.{node.attr}")
    return out


STDLIB_HOOKS = {"_get_help_string"}
"""Private names our classes override because the standard library calls them (argparse's
help formatter), not our own."""


@functools.cache
def private_members() -> dict[str, set[str]]:
    """The private methods and attributes of lhgraph's classes: name -> defining modules."""
    out: dict[str, set[str]] = {}
    for m, path in modules().items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                names = [b.name for b in node.body if isinstance(b, ast.FunctionDef)]
                names += [b.target.id for b in node.body
                          if isinstance(b, ast.AnnAssign) and isinstance(b.target, ast.Name)]
            elif (isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store)
                  and ast.unparse(node.value) == "self"):
                names = [node.attr]
            else:
                continue
            for name in names:
                if name.startswith("_") and not name.startswith("__"):
                    out.setdefault(name, set()).add(m)
    return out


def private_member_uses(path: Path, module: str) -> list[str]:
    """Where ``path`` reaches into an lhgraph object's private member defined elsewhere."""
    members = private_members()
    return [f"{node.lineno}: {ast.unparse(node)}" for node in ast.walk(ast.parse(path.read_text()))
            if isinstance(node, ast.Attribute) and node.attr in members
            and node.attr not in STDLIB_HOOKS and module not in members[node.attr]
            and ast.unparse(node.value) not in ("self", "cls")]


def test_no_private_name_crosses_a_module():
    root = PACKAGE.parent
    files = {**{m: p for m, p in modules().items()},
             **{str(p): p for p in [*(root / "tests").glob("*.py"),
                                    *(root / "benchmarks").glob("*.py")]}}
    uses = [f"{path.relative_to(root)}:{use}" for name, path in files.items()
            for use in private_uses(path) + private_member_uses(path, name)]
    assert not uses, "private names used outside their module:\n" + "\n".join(sorted(uses))


def test_layers_import_downwards():
    upward = []
    for m, p in modules().items():
        if m in ("lhgraph", "lhgraph.__main__"):
            continue
        for i in all_imports(p):
            if layer(i) > layer(m):
                upward.append(f"{m} imports {i}")
    assert not upward, "\n".join(sorted(upward))


MAX_METHODS = 22
MAX_CLASS_LINES = 280
MAX_FIELDS = 30
WIRE_FORMATS = {"lhgraph.device.protocol"}
"""Modules whose classes mirror the firmware's wire formats field by field (exempt from
``MAX_FIELDS``)."""


def classes() -> list[tuple[str, ast.ClassDef]]:
    """Every class of the package, with its module."""
    return [(name, node) for name, path in modules().items()
            for node in ast.walk(ast.parse(path.read_text())) if isinstance(node, ast.ClassDef)]


@pytest.mark.parametrize("name, node", classes(), ids=lambda x: getattr(x, "name", x))
def test_class_is_small(name, node):
    """No god classes: at most MAX_METHODS methods and MAX_CLASS_LINES lines a class, and at
    most MAX_FIELDS annotated fields unless it mirrors a wire format."""
    methods = [b for b in node.body if isinstance(b, ast.FunctionDef | ast.AsyncFunctionDef)]
    fields = [b for b in node.body if isinstance(b, ast.AnnAssign)]
    assert len(methods) <= MAX_METHODS, f"{name}.{node.name}: {len(methods)} methods"
    lines = node.end_lineno - node.lineno + 1
    assert lines <= MAX_CLASS_LINES, f"{name}.{node.name}: {lines} lines"
    assert len(fields) <= MAX_FIELDS or name in WIRE_FORMATS, \
        f"{name}.{node.name}: {len(fields)} annotated fields"
