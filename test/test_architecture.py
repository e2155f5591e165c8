"""The house holds: layers, package dependency direction, one way to run a node (docs/ARCHITECTURE.md).

Read from the source (AST), not by importing, so a function-local import counts as much as a top-level one.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGES = ("hyst_common", "hyst_model", "hyst_sim", "hyst_control", "hyst_driver", "hyst_bringup")
#: Which hyst packages each package may import: arrows point down only.
ALLOWED = {
    "hyst_common": set(),
    "hyst_model": {"hyst_common"},
    "hyst_sim": {"hyst_common", "hyst_model"},
    "hyst_control": {"hyst_common", "hyst_model"},
    "hyst_driver": {"hyst_common"},
    "hyst_bringup": {"hyst_common", "hyst_model", "hyst_sim", "hyst_control", "hyst_driver"},
}
#: Imports that break ALLOWED today, file by file (issue #12: harnesses to a top package, hardware facts to the
#: bottom). A ratchet: a new violation fails, and so does a listed one that is gone (remove it here).
KNOWN = {
    ("hyst_control/cli_track.py", "hyst_sim"), ("hyst_control/composed.py", "hyst_sim"),
    ("hyst_control/demo.py", "hyst_sim"),
    ("hyst_control/loop.py", "hyst_sim"),
}
#: Besides the *_node.py modules, the only modules that may import rclpy.
RCLPY_OK = {"hyst_common/node.py", "hyst_control/composed.py"}


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


def test_rclpy_only_in_nodes_and_the_runner():
    bad = [_rel(pkg, path) for pkg, path, tree in _modules()
           if "rclpy" in _imported(tree) and not path.name.endswith("_node.py")
           and _rel(pkg, path) not in RCLPY_OK]
    assert not bad, f"rclpy imported outside *_node.py: {bad}"


PARAMETER_NODES = ["hyst_control/controller_node.py", "hyst_control/reference_node.py",
                   "hyst_control/excite_node.py", "hyst_model/ident_node.py", "hyst_model/residual_node.py",
                   "hyst_sim/sim_node.py"]


@pytest.mark.parametrize("rel", PARAMETER_NODES)
def test_parameter_nodes_run_through_the_runner_with_all_or_nothing_parameters(rel):
    pkg, name = rel.split("/")
    tree = ast.parse((SRC / pkg / pkg / name).read_text(encoding="utf-8"))
    classes = [n for n in tree.body if isinstance(n, ast.ClassDef) and n.name.endswith("Node")]
    assert classes and all(any(getattr(b, "id", "") == "AtomicParametersNode" for b in c.bases) for c in classes)
    main = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "main")
    calls = {getattr(c.func, "id", "") for c in ast.walk(main) if isinstance(c, ast.Call)}
    assert "run_node" in calls and "init" not in {getattr(c.func, "attr", "") for c in ast.walk(main)
                                                   if isinstance(c, ast.Call)}


def test_the_driver_node_has_all_or_nothing_parameters():
    """Its main keeps its own loop for now (a spinner thread, the ramp to v_safe before the port closes)."""
    tree = ast.parse((SRC / "hyst_driver" / "hyst_driver" / "driver_node.py").read_text(encoding="utf-8"))
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "DriverNode")
    assert [getattr(b, "id", "") for b in cls.bases] == ["AtomicParametersNode"]
