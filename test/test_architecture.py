"""The house holds: layers, package dependency direction, one way to run a node (docs/ARCHITECTURE.md).

Read from the source (AST), not by importing, so a function-local import counts as much as a top-level one.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGES = ("hyst_common", "hyst_model", "hyst_sim", "hyst_control", "hyst_driver", "hyst_bringup")
#: The order of the house: a package may import only packages of a lower level (never sideways or up).
LEVEL = {"hyst_common": 0, "hyst_model": 1, "hyst_sim": 2, "hyst_control": 2, "hyst_driver": 2, "hyst_bringup": 3}
#: Which hyst packages each package may import: arrows point down only (and the driver needs no model).
ALLOWED = {
    "hyst_common": set(),
    "hyst_model": {"hyst_common"},
    "hyst_sim": {"hyst_common", "hyst_model"},
    "hyst_control": {"hyst_common", "hyst_model"},
    "hyst_driver": {"hyst_common"},
    "hyst_bringup": {"hyst_common", "hyst_model", "hyst_sim", "hyst_control", "hyst_driver"},
}
#: Imports that break ALLOWED, file by file. A ratchet: a new violation fails, and so does a listed one that is
#: gone (remove it here). Empty since issue #12 (hardware facts to hyst_common, harnesses to hyst_bringup).
KNOWN: set[tuple[str, str]] = set()
#: Besides the *_node.py modules, the only modules that may import rclpy.
RCLPY_OK = {"hyst_common/node.py", "hyst_bringup/composed.py"}


def _modules():
    for pkg in PACKAGES:
        for path in sorted((SRC / pkg / pkg).rglob("*.py")):
            yield pkg, path, ast.parse(path.read_text(encoding="utf-8"))


def _imported(tree: ast.AST) -> set[str]:
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module.split(".")[0])
    return out


def _rel(pkg: str, path: Path) -> str:
    return f"{pkg}/{path.relative_to(SRC / pkg / pkg).as_posix()}"


def test_package_dependencies_point_down():
    found = set()
    for pkg, path, tree in _modules():
        for dep in _imported(tree) & set(PACKAGES) - {pkg}:
            if dep not in ALLOWED[pkg]:
                found.add((_rel(pkg, path), dep))
    new, gone = found - KNOWN, KNOWN - found
    assert not new, f"imports against the dependency direction: {sorted(new)}"
    assert not gone, f"fixed, remove from KNOWN: {sorted(gone)}"


def test_allowed_follows_the_levels_and_package_xml_declares_exactly_the_allowed_imports():
    """common < model < sim, control, driver < bringup; each package.xml's hyst exec_depends are allowed ones and
    cover every hyst package the code imports (so colcon orders the build and a rig installs what is needed)."""
    assert set(LEVEL) == set(PACKAGES) == set(ALLOWED)
    for pkg, deps in ALLOWED.items():
        assert all(LEVEL[d] < LEVEL[pkg] for d in deps), pkg
    imported: dict[str, set[str]] = {p: set() for p in PACKAGES}
    for pkg, _, tree in _modules():
        imported[pkg] |= _imported(tree) & set(PACKAGES) - {pkg}
    for pkg in PACKAGES:
        xml = (SRC / pkg / "package.xml").read_text(encoding="utf-8")
        declared = {d for d in PACKAGES if f"<exec_depend>{d}</exec_depend>" in xml}
        assert declared <= ALLOWED[pkg], f"{pkg}/package.xml depends upward or sideways: {declared - ALLOWED[pkg]}"
        assert imported[pkg] <= declared, f"{pkg} imports undeclared packages: {imported[pkg] - declared}"


def test_rclpy_only_in_nodes_and_the_runner():
    bad = [_rel(pkg, path) for pkg, path, tree in _modules()
           if "rclpy" in _imported(tree) and not path.name.endswith("_node.py")
           and _rel(pkg, path) not in RCLPY_OK]
    assert not bad, f"rclpy imported outside *_node.py: {bad}"


PARAMETER_NODES = ["hyst_control/controller_node.py", "hyst_control/reference_node.py",
                   "hyst_control/excite_node.py", "hyst_model/ident_node.py", "hyst_model/residual_node.py",
                   "hyst_sim/sim_node.py", "hyst_driver/driver_node.py"]
NODE_FILES = sorted(_rel(pkg, path) for pkg, path, _ in _modules() if path.name.endswith("_node.py"))


def _main_calls(rel: str) -> tuple[set[str], set[str]]:
    """Names and attribute names called in the module's ``main``."""
    pkg, name = rel.split("/")
    tree = ast.parse((SRC / pkg / pkg / name).read_text(encoding="utf-8"))
    main = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "main")
    calls = [c for c in ast.walk(main) if isinstance(c, ast.Call)]
    return {getattr(c.func, "id", "") for c in calls}, {getattr(c.func, "attr", "") for c in calls}


@pytest.mark.parametrize("rel", NODE_FILES)
def test_every_node_main_goes_through_the_one_runner(rel):
    names, attrs = _main_calls(rel)
    assert "run_node" in names, f"{rel}: main() does not call run_node"
    assert not {"init", "spin", "spin_once", "try_shutdown"} & attrs, f"{rel}: main() runs rclpy itself"


@pytest.mark.parametrize("rel", PARAMETER_NODES)
def test_parameter_nodes_have_all_or_nothing_parameters(rel):
    pkg, name = rel.split("/")
    tree = ast.parse((SRC / pkg / pkg / name).read_text(encoding="utf-8"))
    classes = [n for n in tree.body if isinstance(n, ast.ClassDef) and n.name.endswith("Node")]
    assert classes and all(any(getattr(b, "id", "") == "AtomicParametersNode" for b in c.bases) for c in classes)


@pytest.mark.parametrize("pkg", PACKAGES)
def test_a_package_tests_itself_with_its_own_dependencies_only(pkg):
    """A rig that installs only the driver (and hyst_common) can run the driver's tests: a package's tests import
    what the package may import, nothing above it (cross-package tests live in the top-level test/: the
    controllers on the sim's plant in test/control/)."""
    bad = []
    for path in sorted((SRC / pkg / "test").rglob("*.py")):
        extra = _imported(ast.parse(path.read_text(encoding="utf-8"))) & set(PACKAGES) - ALLOWED[pkg] - {pkg}
        if extra:
            bad.append((path.name, sorted(extra)))
    assert not bad, bad
