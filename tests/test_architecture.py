"""The package's structure stays as docs/architecture.md describes it: modules of one
concept (short), no import cycles, the layers importing only downwards."""

from __future__ import annotations

import ast
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


def modules() -> dict[str, Path]:
    return {".".join(("lhgraph", *p.relative_to(PACKAGE).with_suffix("").parts))
            .removesuffix(".__init__"): p for p in PACKAGE.rglob("*.py")}


def module_imports(path: Path) -> set[str]:
    """lhgraph modules imported at module level (outside functions and TYPE_CHECKING)."""
    out: set[str] = set()
    tree = ast.parse(path.read_text())
    for node in tree.body:
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            continue
        for sub in ast.walk(node) if not isinstance(node, ast.FunctionDef | ast.ClassDef) \
                else []:
            if isinstance(sub, ast.ImportFrom) and sub.module and sub.level == 0 \
                    and sub.module.startswith("lhgraph"):
                out.add(sub.module)
            elif isinstance(sub, ast.Import):
                out.update(a.name for a in sub.names if a.name.startswith("lhgraph"))
    return out


def all_imports(path: Path) -> set[str]:
    """Every lhgraph module ``path`` imports, at module level, in functions or for typing."""
    return {n.module for n in ast.walk(ast.parse(path.read_text()))
            if isinstance(n, ast.ImportFrom) and n.module and n.module.startswith("lhgraph.")}


def layer(module: str) -> int:
    return LAYERS[module.split(".")[1]]


@pytest.mark.parametrize("name", sorted(modules()))
def test_module_is_short(name):
    lines = len(modules()[name].read_text().splitlines())
    assert lines <= MAX_LINES, f"{name}: {lines} lines (split it by concept)"


def test_no_import_cycle():
    mods = modules()
    graph = {m: {i for i in module_imports(p) if i in mods} for m, p in mods.items()}
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


def test_layers_import_downwards():
    upward = []
    for m, p in modules().items():
        if m in ("lhgraph", "lhgraph.__main__"):
            continue
        for i in all_imports(p):
            if layer(i) > layer(m):
                upward.append(f"{m} imports {i}")
    assert not upward, "\n".join(sorted(upward))
