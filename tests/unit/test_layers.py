"""The layers import downwards only: core <- params <- nodes <- tools.

A module may import its own layer and the layers below it, never one above:
the core needs numpy, numba and scipy only, params never needs rclpy, and no node depends on
the tools that run it.
"""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "estimation_nodes"
LAYERS = ("core", "params", "nodes", "tools")
#: Third-party packages each layer may not import (rclpy and the ROS message packages).
ROS = ("rclpy", "rcl_interfaces", "std_msgs", "geometry_msgs", "std_srvs", "diagnostic_msgs")


def imported_modules(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.extend(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
    return names


def modules_of(layer: str) -> list[Path]:
    return sorted((PACKAGE / layer).rglob("*.py"))


def test_every_module_belongs_to_a_layer():
    loose = [p.name for p in PACKAGE.glob("*.py") if p.name != "__init__.py"]
    assert not loose, f"modules outside core/, params/, nodes/, tools/: {loose}"


@pytest.mark.parametrize("layer", LAYERS)
def test_a_layer_imports_only_itself_and_the_layers_below(layer):
    above = LAYERS[LAYERS.index(layer) + 1:]
    wrong = [f"{path.relative_to(PACKAGE)} imports {name}"
             for path in modules_of(layer) for name in imported_modules(path)
             if any(name.startswith(f"estimation_nodes.{upper}") for upper in above)]
    assert not wrong, f"{layer}/ points up: {wrong}"


@pytest.mark.parametrize("layer", ["core", "params"])
def test_core_and_params_never_import_ros(layer):
    wrong = [f"{path.relative_to(PACKAGE)} imports {name}"
             for path in modules_of(layer) for name in imported_modules(path)
             if name.split(".")[0] in ROS]
    assert not wrong, f"{layer}/ imports ROS: {wrong}"


def test_the_core_needs_only_numpy_numba_and_scipy():
    import sys

    allowed = ({"numpy", "numba", "scipy", "estimation_nodes", "__future__"}
               | set(sys.stdlib_module_names))
    wrong = [f"{path.relative_to(PACKAGE)} imports {name}" for path in modules_of("core")
             for name in imported_modules(path) if name.split(".")[0] not in allowed]
    assert not wrong, f"core/ needs more than numpy, numba and scipy: {wrong}"


def test_the_core_defines_its_exceptions_in_one_place():
    defined = [f"{path.relative_to(PACKAGE)}: {node.name}"
               for path in modules_of("core") if path.name != "errors.py"
               for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
               if isinstance(node, ast.ClassDef) and node.name.endswith("Error")]
    assert not defined, f"exceptions outside core/errors.py: {defined}"


def test_every_core_exception_is_an_estimation_error():
    import inspect

    from estimation_nodes.core import errors

    classes = [c for _, c in inspect.getmembers(errors, inspect.isclass)
               if c.__module__ == errors.__name__]
    assert len(classes) > 1
    assert all(issubclass(c, errors.EstimationError) for c in classes)
    assert issubclass(errors.EstimationError, ValueError)
