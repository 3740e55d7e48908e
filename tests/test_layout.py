"""The packages' import graph: no circles, no import from a lower layer to a higher one, and
the real-cell path free of the simulator and the lab (read from the source with ``ast``,
nothing imported).

Layers, lowest first: ``drivers.core`` (imports nothing else of finepos), ``calibration_free``
(the method on arrays: only the core), ``drivers`` (the devices), ``sim_backend`` (the
simulated cell and the emulators: drivers), ``controller`` (everything).

The real-cell path: the modules behind the commands a cell runs (``finepos serve``, teach,
acquire, train, rezero, position, grasp, check...) and everything they import, at module level
or inside a function (not under ``if TYPE_CHECKING:``, which never runs). It reaches neither
``sim_backend`` nor the lab (the evaluation, the benchmarks, the soak, the comparisons and the
filter search). The one exception is ``controller.simulated``, the product's door into the
simulator: its imports of the simulator sit inside functions that run only when the config
names a simulated device, so they are not followed; its module-level imports are. The CLI
imports its command modules by name (``importlib``), which ``ast`` does not see:
``tests/test_product_path.py`` runs each cell command on a real cell's config and checks that
none of the simulator or the lab was loaded.
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
# The modules a real cell runs: the CLI, the modules behind its cell commands
# (``controller.cli.CELL_COMMAND_MODULES``), the service, teach-in, positioning, grasp and the
# vision systems. None of them may reach the simulator or the lab, not even through another
# module.
REAL_CELL_PATH = ("controller.cli", "controller.commands.serve", "controller.commands.ctl",
                  "controller.commands.workflow", "controller.commands.check",
                  "controller.commands.fit_timing", "controller.commands.replay",
                  "controller.service.service", "controller.fine_positioner", "controller.loop",
                  "controller.systems", "controller.teach", "controller.calibration")
# The lab: the simulator, the evaluation and comparisons (filter search, Table 1, paired
# comparison), the benchmarks, the soak, and the research commands.
LAB = ("sim_backend", "controller.evaluation", "controller.service.soak",
       "controller.service.bench", "controller.service.halt_bench", "controller.recording.bench",
       "calibration_free.bench", "calibration_free.filter2d_reference",
       "controller.commands.evaluate", "controller.commands.table1",
       "controller.commands.filter_search", "controller.commands.compare",
       "controller.commands.grasp_sweep", "controller.commands.demo")
# The product's door into the simulator: only its module-level imports are followed.
SIMULATOR_DOOR = "controller.simulated"


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


def _type_checking_only(node: ast.AST) -> bool:
    """``if TYPE_CHECKING:`` (its imports are for annotations, never run)."""
    return isinstance(node, ast.If) and ast.unparse(node.test) in ("TYPE_CHECKING",
                                                                   "typing.TYPE_CHECKING")


def _import_nodes(tree: ast.AST, in_functions: bool, run_only: bool):
    """The import statements of ``tree``: with ``in_functions`` False none inside a function
    body (only those run when the module is loaded); with ``run_only`` none under
    ``if TYPE_CHECKING:``."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        elif not in_functions and isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                    ast.Lambda)):
            continue
        elif not (run_only and _type_checking_only(node)):
            yield from _import_nodes(node, in_functions, run_only)


def _imports(module: str, in_functions: bool = True, run_only: bool = False) -> set[str]:
    path = MODULES[module]
    is_package = path.name == "__init__.py"
    targets = set()
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in _import_nodes(tree, in_functions, run_only):
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
        for name in names:
            if name.split(".")[0] in PACKAGES and (target := _resolve(name)) \
                    and target != module:
                targets.add(target)
    return targets


GRAPH = {module: _imports(module) for module in MODULES}
# What a module may load on a real cell: every import that runs, the door's function-level
# ones left out.
REAL_CELL_GRAPH = {module: _imports(module, in_functions=module != SIMULATOR_DOOR,
                                    run_only=True)
                   for module in MODULES}


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


def _is_lab(module: str) -> bool:
    return any(module == lab or module.startswith(lab + ".") for lab in LAB)


@pytest.mark.parametrize("start", REAL_CELL_PATH)
def test_the_real_cell_path_reaches_neither_the_simulator_nor_the_lab(start):
    assert start in MODULES, f"{start}: no such module (REAL_CELL_PATH is out of date)"
    via: dict[str, str | None] = {m: None for m in MODULES
                                  if m == start or m.startswith(start + ".")}
    todo = list(via)
    while todo:
        module = todo.pop()
        for target in REAL_CELL_GRAPH[module]:
            if target not in via:
                via[target] = module
                todo.append(target)

    def chain(module: str) -> str:
        links = [module]
        while (module := via[module]) is not None:
            links.append(module)
        return " <- ".join(links)

    assert [chain(m) for m in sorted(via) if _is_lab(m)] == []


def test_the_simulator_door_imports_the_simulator_only_inside_functions():
    assert SIMULATOR_DOOR in MODULES
    assert sorted(m for m in REAL_CELL_GRAPH[SIMULATOR_DOOR] if _is_lab(m)) == []
    assert any(m.startswith("sim_backend") for m in GRAPH[SIMULATOR_DOOR])
