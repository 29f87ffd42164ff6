"""The package's floors import only downward.

Floors, lowest first (docs/ARCHITECTURE.md):

0. `nfr_drake` (the package's `__init__`), `errors`, `jsonio`, `cpu`, `paths`, `parsing`: helpers
   every floor may use; `jsonio`, `paths` and `parsing` import `errors`.
1. `objects`: articulated object categories.
2. `world`: what planning, simulation and replays share: the robot model, keypoint trajectories,
   obstacle boxes, planned motions.
3. `data`: the camera model, camera placement, Drake rendering, datasets, capture sets.
4. `nfr`: the neural field.
5. `perception`, `inference`, `baseline`: photos to capture sets, the handle detector, fitting the
   field, the image-encoder baseline; `inference` may import `perception` (never the reverse),
   `baseline` imports neither.
6. `planning`: grasp frames, base placement, trajectory optimisation.
7. `systems`: Drake systems, simulation, replays, scenarios, tasks, the pipeline, `demo` and `plan`.
8. `eval`: evaluation runs, tables and plots.
9. `cli`: the `nfr-drake` command (it loads subcommands by name from every floor).

A module may import from its own sub-package, from a lower floor, and from a sub-package on its own
floor only where the order above says so. Every import statement counts, also inside functions and
under `TYPE_CHECKING`; a module that is on no floor fails the test.
"""

from __future__ import annotations

import ast
from pathlib import Path

import nfr_drake

PACKAGE_DIR = Path(nfr_drake.__file__).resolve().parent

FLOORS: list[tuple[str, ...]] = [
    ("nfr_drake", "errors", "jsonio", "cpu", "paths", "parsing"),
    ("objects",),
    ("world",),
    ("data",),
    ("nfr",),
    ("perception", "inference", "baseline"),
    ("planning",),
    ("systems",),
    ("eval",),
    ("cli",),
]
SAME_FLOOR_ALLOWED = {("jsonio", "errors"), ("paths", "errors"), ("parsing", "errors"),
                      ("inference", "perception")}
"""(importer, imported) pairs of different units on one floor that may import each other."""

FLOOR_OF = {unit: level for level, units in enumerate(FLOORS) for unit in units}


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE_DIR.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def unit_of(module: str) -> str:
    """The floor unit of a dotted module name inside nfr_drake: its sub-package or top-level module."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def imported_modules(tree: ast.Module, module: str, is_package: bool) -> list[tuple[int, str]]:
    """(line, dotted name) of every nfr_drake module imported anywhere in `tree`."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")
                base = base[:len(base) - node.level + (1 if is_package else 0)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            if target == "nfr_drake":  # `from nfr_drake import errors` names modules
                found += [(node.lineno, f"nfr_drake.{alias.name}") for alias in node.names
                          if alias.name in FLOOR_OF]
            found.append((node.lineno, target))
    return sorted((line, name) for line, name in found if name.split(".")[0] == "nfr_drake")


def violations() -> tuple[list[str], list[str]]:
    """(imports that go up or sideways without leave, modules on no floor)."""
    bad, unplaced = [], []
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        module = module_name(path)
        unit = unit_of(module)
        if unit not in FLOOR_OF:
            unplaced.append(module)
            continue
        tree = ast.parse(path.read_text(), filename=str(path))
        for line, target in imported_modules(tree, module, path.name == "__init__.py"):
            other = unit_of(target)
            if other == unit or other == "nfr_drake":
                continue
            if other not in FLOOR_OF:
                unplaced.append(target)
                continue
            up = FLOOR_OF[other] > FLOOR_OF[unit]
            sideways = FLOOR_OF[other] == FLOOR_OF[unit] and (unit, other) not in SAME_FLOOR_ALLOWED
            if up or sideways:
                where = "up" if up else "sideways"
                bad.append(f"{path.relative_to(PACKAGE_DIR.parent)}:{line}: {module} imports {target} "
                           f"({where}: {unit} on floor {FLOOR_OF[unit]}, {other} on floor {FLOOR_OF[other]})")
    return bad, sorted(set(unplaced))


def test_every_module_is_on_a_floor():
    _, unplaced = violations()
    assert not unplaced, "modules on no floor (add them to FLOORS):\n" + "\n".join(unplaced)


def test_no_import_goes_up_a_floor():
    bad, _ = violations()
    assert not bad, f"{len(bad)} imports against the floor order:\n" + "\n".join(bad)


def test_the_checker_sees_imports_inside_functions_and_relative_ones():
    source = "def f():\n    from nfr_drake.eval import plots\n\nfrom ..systems import task\n"
    found = imported_modules(ast.parse(source), "nfr_drake.planning.grasp", is_package=False)
    assert found == [(2, "nfr_drake.eval"), (4, "nfr_drake.systems")]
