"""The package picture of docs/architecture.md holds: every import (lazy ones inside functions too) follows the
allowed-imports table written there, the trainer does not import evaluation, and no module of any package imports
in a circle (type-only imports under ``TYPE_CHECKING`` count too: a circle of types is still a circle to read)."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("hrlsac_cli", "mavlink_signing", "missions", "sitl_bridge", "autonomy", "simulation", "policies")


SPLIT_PACKAGES = {"policies": None, "sitl_bridge": {"px4", "ardupilot"}}
"""Packages whose parts have rows of their own: every part of ``policies``; the two autopilot personalities of
``sitl_bridge`` (its other modules are its shared core)."""


def unit_of(module: str) -> str:
    """The row of the table a module belongs to: a top-level package, or a part of a split package."""
    parts = module.split(".")
    if parts[0] in SPLIT_PACKAGES and len(parts) > 1:
        parts_with_rows = SPLIT_PACKAGES[parts[0]]
        if parts_with_rows is None or parts[1] in parts_with_rows:
            return ".".join(parts[:2])
    return parts[0]


def allowed_imports() -> dict[str, set[str]]:
    text = (ROOT / "docs" / "architecture.md").read_text()
    block = re.search(r"<!-- allowed-imports -->\s*```text\n(.*?)```", text, re.S).group(1)
    table = {}
    for line in block.strip().splitlines():
        unit, _, targets = line.partition("->")
        table[unit.strip()] = set(targets.split())
    return table


def our_modules() -> dict[str, Path]:
    modules = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            modules[name.removesuffix(".__init__")] = path
    return modules


def imports_of(path: Path, known: set[str]) -> set[str]:
    """Our modules (or packages) that the file imports anywhere in it."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            # ``from pkg import name``: name may be a module of pkg, or something defined in it
            names = [f"{node.module}.{alias.name}" if f"{node.module}.{alias.name}" in known else node.module
                     for alias in node.names]
        else:
            continue
        found.update(name for name in names if name.split(".")[0] in PACKAGES)
    return found


MODULES = our_modules()
GRAPH = {module: imports_of(path, set(MODULES)) for module, path in MODULES.items()}


def test_the_table_names_every_unit_there_is():
    assert set(allowed_imports()) == {unit_of(module) for module in MODULES} - {"policies"}


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_follow_the_allowed_table(module):
    table = allowed_imports()
    unit = unit_of(module)
    allowed = table.get(unit, set()) | {unit}
    wrong = sorted(name for name in GRAPH[module] if unit_of(name) not in allowed)
    assert not wrong, f"{module} ({MODULES[module].relative_to(ROOT)}) imports {wrong}, outside {sorted(allowed)}"


def test_the_on_board_runtime_imports_no_training_code_and_no_simulator():
    for module in (m for m in MODULES if m.startswith("autonomy")):
        assert not {unit_of(name).split(".")[0] for name in GRAPH[module]} & {"policies", "sitl_bridge",
                                                                              "simulation"}, module


def test_the_trainer_is_handed_its_evaluation():
    assert not {name for name in GRAPH["policies.training.trainer"] if name.startswith("policies.evaluation")}


def cycles(modules: set[str]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), among ``modules``."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(module: str) -> None:
        index[module] = low[module] = len(index)
        stack.append(module)
        on_stack.add(module)
        for target in GRAPH[module] & modules:
            if target not in index:
                visit(target)
                low[module] = min(low[module], low[target])
            elif target in on_stack:
                low[module] = min(low[module], index[target])
        if low[module] == index[module]:
            component = []
            while True:
                top = stack.pop()
                on_stack.discard(top)
                component.append(top)
                if top == module:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for module in sorted(modules):
        if module not in index:
            visit(module)
    return found


@pytest.mark.parametrize("package", PACKAGES)
def test_no_module_imports_in_a_circle(package):
    assert cycles({m for m in MODULES if m.split(".")[0] == package}) == []


MODULE_LINE_LIMIT = 400
"""The house rule: a module is small enough to read in one sitting (docs/architecture.md)."""


def test_no_module_is_longer_than_the_limit():
    tops = (*PACKAGES, "benchmarks", "tests", "docs")
    long = {str(path.relative_to(ROOT)): length for top in tops for path in (ROOT / top).rglob("*.py")
            if (length := len(path.read_text().splitlines())) > MODULE_LINE_LIMIT}
    assert long == {}, f"split these modules by concern: {long}"
