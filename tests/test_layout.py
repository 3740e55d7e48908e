"""The packages' import graph: no circles, no import from a lower layer to a higher one, and
the real-cell path free of the simulator (read from the source with ``ast``, nothing imported).

Layers, lowest first: ``drivers.core`` (imports nothing else of finepos), ``calibration_free``
(the method on arrays: only the core), ``drivers`` (the devices), ``sim_backend`` (the
simulated cell and the emulators: drivers), ``controller`` (everything).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("drivers", "calibration_free", "sim_backend", "controller")
# What each package may import of the others (itself always).
ALLOWED = {
    "drivers.core": set(),
    "calibration_free": {"drivers.core"},
    "drivers": {"drivers.core"},
    "sim_backend": {"drivers.core", "drivers"},
    "controller": {"drivers.core", "drivers", "calibration_free", "sim_backend"},
}
# The modules a real cell runs (teach-in, positioning, grasp, the vision systems): none of them
# may reach the simulator, not even through another module.
REAL_CELL_PATH = ("controller.fine_positioner", "controller.loop", "controller.systems",
                  "controller.teach")


def _modules() -> dict[str, Path]:
    found = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


MODULES = _modules()


def _resolve(name: str) -> str | None:
    """The finepos module ``name`` refers to (a module, or the package of an imported name)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _imports(module: str) -> set[str]:
    path = MODULES[module]
    is_package = path.name == "__init__.py"
    targets = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")
                base = base[:len(base) - node.level + (1 if is_package else 0)]
                origin = ".".join(base + ([node.module] if node.module else []))
            else:
                origin = node.module or ""
            names = [f"{origin}.{alias.name}" for alias in node.names] + [origin]
        else:
            continue
        for name in names:
            if name.split(".")[0] in PACKAGES and (target := _resolve(name)) \
                    and target != module:
                targets.add(target)
    return targets


GRAPH = {module: _imports(module) for module in MODULES}


def _layer(module: str) -> str:
    return "drivers.core" if module.startswith("drivers.core") else module.split(".")[0]


def test_no_import_circle():
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    circles = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while (w := stack.pop()) != v:
                component.append(w)
            if component:
                circles.append(sorted([v, *component]))

    for module in GRAPH:
        if module not in index:
            visit(module)
    assert circles == []


@pytest.mark.parametrize("module", sorted(GRAPH))
def test_imports_stay_in_their_layer(module):
    layer = _layer(module)
    wrong = sorted(t for t in GRAPH[module] if _layer(t) != layer
                   and _layer(t) not in ALLOWED[layer])
    assert wrong == [], f"{module} ({layer}) may not import {wrong}"


@pytest.mark.parametrize("start", REAL_CELL_PATH)
def test_the_real_cell_path_never_reaches_the_simulator(start):
    seen, todo = set(), [m for m in GRAPH if m == start or m.startswith(start + ".")]
    while todo:
        module = todo.pop()
        if module not in seen:
            seen.add(module)
            todo.extend(GRAPH[module])
    assert sorted(m for m in seen if m.startswith("sim_backend")) == []
