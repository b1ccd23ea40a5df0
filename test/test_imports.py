"""The shape of the house, read from the source (``ast``; nothing here is imported, so this runs
without rclpy): which package may import which, no private names imported across modules, and
no import loop.

Rules, over every module of ``ecahd_core``, ``ecahd_ros`` and ``sim_bridge`` (found by walking
the directories, so a module that is added, moved or renamed is checked without editing this
file):

- ``ecahd_core`` is the rclpy-free library: it imports neither rclpy nor any other ROS 2 Python
  package (``rcl_interfaces``, ``*_msgs`` ...), nor ``ecahd_ros``, nor ``sim_bridge``.
- ``ecahd_ros`` never imports ``sim_bridge`` (the simulator depends on the ROS side, not the
  reverse; ``ecahd demo`` starts it as a process by module name, which is not an import).
- No ``from X import _name`` of a private name (one leading underscore, not a dunder) from
  another module: a helper two modules need is public and has one home.
- No import cycle among our modules. Every ``import`` counts, at module level *and* inside
  functions: the packages import heavy modules (torch, the benchmarks) lazily inside functions
  on purpose, so ``ecahd --help`` stays fast, and such an import does not run at import time,
  but it is still a dependency, and a loop through one is a loop a reader has to untangle
  (``bench/monitor.py`` -> ``commands/bench.py`` -> ``bench/monitor.py`` was one). Only imports
  under ``if TYPE_CHECKING:`` are left out: they never run.

An import counts as a dependency on the module it names: ``from pkg import name`` depends on
the submodule ``pkg.name`` when there is one, else on ``pkg`` itself; importing a submodule is
not counted as importing its parent packages' ``__init__`` (which would make every package that
re-exports its submodules look like a loop).
"""
from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("ecahd_core", "ecahd_ros", "sim_bridge")
# ROS 2 Python packages the library must not import, besides the *_msgs / *_srvs / *_interfaces
# message packages
ROS_PACKAGES = {"rclpy", "rcl_interfaces", "builtin_interfaces", "rosgraph_msgs", "launch",
                "launch_ros", "ament_index_python", "tf2_ros", "rosidl_runtime_py",
                "message_filters", "rosbag2_py"}

# (importing module, imported module, name): private names imported across modules on purpose.
# Empty: every such import has been made public. An entry needs a comment saying why.
PRIVATE_ALLOWED: set[tuple[str, str, str]] = set()


@dataclass(frozen=True)
class Import:
    """One imported name: ``module`` (absolute) and ``name`` (None for ``import module``)."""

    importer: str
    module: str
    name: str | None
    line: int
    in_function: bool
    type_checking: bool


def _module_files() -> dict[str, tuple[Path, bool]]:
    """{dotted module name: (file, is a package __init__)} of our three packages."""
    modules = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            if is_package:
                parts = parts[:-1]
            modules[".".join(parts)] = (path, is_package)
    return modules


MODULES = _module_files()


def _is_type_checking(test: ast.expr) -> bool:
    return any(isinstance(n, ast.Name) and n.id == "TYPE_CHECKING"
               or isinstance(n, ast.Attribute) and n.attr == "TYPE_CHECKING"
               for n in ast.walk(test))


def _imports(module: str, source: str, is_package: bool) -> list[Import]:
    """Every import statement in ``source``, the text of ``module``, relative ones made
    absolute."""
    package = module.split(".") if is_package else module.split(".")[:-1]
    found = []

    def visit(node: ast.AST, in_function: bool, type_checking: bool) -> None:
        for child in ast.iter_child_nodes(node):
            fn = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                   ast.Lambda))
            tc = type_checking or isinstance(child, ast.If) and _is_type_checking(child.test)
            if isinstance(child, ast.Import):
                found.extend(Import(module, alias.name, None, child.lineno, fn, tc)
                             for alias in child.names)
            elif isinstance(child, ast.ImportFrom):
                base = child.module or ""
                if child.level:  # from . import x / from ..y import z
                    parent = package[:len(package) - child.level + 1]
                    base = ".".join(parent + ([base] if base else []))
                found.extend(Import(module, base, alias.name, child.lineno, fn, tc)
                             for alias in child.names)
            visit(child, fn, tc)

    visit(ast.parse(source), False, False)
    return found


IMPORTS = {module: _imports(module, path.read_text(), is_package)
           for module, (path, is_package) in MODULES.items()}


def _top(module: str) -> str:
    return module.split(".")[0]


def _is_ros(module: str) -> bool:
    top = _top(module)
    return top in ROS_PACKAGES or top.endswith(("_msgs", "_srvs", "_interfaces"))


def _where(imp: Import) -> str:
    what = imp.module if imp.name is None else f"{imp.module} import {imp.name}"
    return f"{MODULES[imp.importer][0].relative_to(ROOT)}:{imp.line}: {what}"


def _target(imp: Import) -> str | None:
    """Which of our modules ``imp`` depends on (None: not one of ours)."""
    if imp.name is not None and f"{imp.module}.{imp.name}" in MODULES:
        return f"{imp.module}.{imp.name}"
    return imp.module if imp.module in MODULES else None


def _graph() -> dict[str, set[str]]:
    """{module: modules of ours it imports} (every import but TYPE_CHECKING-only ones)."""
    return {m: {t for imp in imports if not imp.type_checking
                and (t := _target(imp)) is not None and t != m}
            for m, imports in IMPORTS.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    component = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        component.append(w)
                        if w == v:
                            break
                    if len(component) > 1:
                        out.append(sorted(component))
    return out


def test_the_packages_are_found():
    # a walk that found nothing would make every test below pass: each package has modules,
    # and the checks see imports (ecahd_ros imports rclpy, sim_bridge imports ecahd_ros)
    for package in PACKAGES:
        assert package in MODULES and len([m for m in MODULES if _top(m) == package]) > 1
    assert any(imp.module == "rclpy" or _top(imp.module) == "rclpy"
               for m, imports in IMPORTS.items() if _top(m) == "ecahd_ros" for imp in imports)
    assert any(_target(imp) and _top(_target(imp)) == "ecahd_ros"
               for m, imports in IMPORTS.items() if _top(m) == "sim_bridge" for imp in imports)


def test_the_core_imports_no_ros_and_neither_node_package():
    bad = [_where(imp) for m, imports in IMPORTS.items() if _top(m) == "ecahd_core"
           for imp in imports
           if _is_ros(imp.module) or _top(imp.module) in ("ecahd_ros", "sim_bridge")]
    assert not bad, "ecahd_core must stay rclpy-free:\n" + "\n".join(bad)


def test_the_ros_side_does_not_import_the_simulator():
    bad = [_where(imp) for m, imports in IMPORTS.items() if _top(m) == "ecahd_ros"
           for imp in imports if _top(imp.module) == "sim_bridge"]
    assert not bad, "ecahd_ros must not depend on sim_bridge:\n" + "\n".join(bad)


def _private(name: str | None) -> bool:
    return bool(name) and name.startswith("_") and not name.startswith("__")


def test_no_private_name_is_imported_from_another_module():
    bad = [_where(imp) for imports in IMPORTS.values() for imp in imports
           if _private(imp.name) and imp.module != imp.importer
           and (imp.importer, imp.module, imp.name) not in PRIVATE_ALLOWED]
    assert not bad, ("private names imported across modules (make them public, in one "
                     "home):\n" + "\n".join(bad))


def test_there_is_no_import_cycle():
    cycles = _cycles(_graph())
    assert not cycles, "import cycles (modules that import each other, directly or not):\n" + \
        "\n".join("a cycle through " + ", ".join(c) for c in cycles)


# ------------------------------------------------------------------- the checks themselves
def test_the_cycle_finder_finds_cycles_and_only_cycles():
    # a -> b -> c -> a is one cycle; d -> a hangs off it; e <-> f is another; g alone
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"f"}, "f": {"e"}, "g": set()}
    assert sorted(_cycles(graph)) == [["a", "b", "c"], ["e", "f"]]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []


@pytest.mark.parametrize("name, private", [("_write_json", True), ("write_json", False),
                                           ("__version__", False), ("_", True), (None, False)])
def test_private_names_are_told_from_public_ones(name, private):
    assert _private(name) is private


@pytest.mark.parametrize("module, ros", [("rclpy.node", True), ("nav_msgs.msg", True),
                                         ("rcl_interfaces.msg", True), ("numpy", False),
                                         ("rosbags.highlevel", False), ("torch", False)])
def test_ros_packages_are_told_from_others(module, ros):
    assert _is_ros(module) is ros


def test_imports_are_read_with_their_place_and_relative_ones_made_absolute():
    source = """
import os, numpy as np
from typing import TYPE_CHECKING
from . import sibling
from ..other import thing as t
if TYPE_CHECKING:
    from torch import Tensor

class Holder:
    from json import dumps  # runs at import time: module level

def lazy():
    from ecahd_core.errors import EcahdError
    return EcahdError
"""
    got = [(i.module, i.name, i.in_function, i.type_checking)
           for i in _imports("pkg.sub.mod", source, is_package=False)]
    assert got == [("os", None, False, False), ("numpy", None, False, False),
                   ("typing", "TYPE_CHECKING", False, False),
                   ("pkg.sub", "sibling", False, False), ("pkg.other", "thing", False, False),
                   ("torch", "Tensor", False, True), ("json", "dumps", False, False),
                   ("ecahd_core.errors", "EcahdError", True, False)]
    # in a package's __init__, "." is the package itself
    assert [(i.module, i.name) for i in _imports("pkg.sub", "from . import x", True)] == \
        [("pkg.sub", "x")]
