"""ROS parameter files: checked before rcl reads them, and read as rcl reads them.

rcl's own parser fails with a long traceback; ``check_params_file`` says in one
line what is wrong with a file. ``node_parameters`` gives the values one node
gets from a file, by rcl's rules, for tools that read a file without rcl
(the offline replay). Only yaml.safe_load is used: a parameter file can never
run code.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml


def check_params_file(path: Path) -> Path:
    """A readable YAML file whose top level maps node names to ros__parameters.

    Raises ValueError with a one-line reason; returns the resolved path.
    """
    if not path.is_file():
        raise ValueError(f"{path} is not a file")
    try:
        content = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError(f"cannot read {path}: {error}") from None
    except yaml.YAMLError as error:
        where = getattr(error, "problem_mark", None)
        line = f" (line {where.line + 1})" if where is not None else ""
        raise ValueError(f"{path} is not valid YAML{line}: "
                         f"{getattr(error, 'problem', None) or error}") from None
    if not isinstance(content, dict) or not all(
        isinstance(section, dict) and isinstance(section.get("ros__parameters"), dict)
        for section in content.values()
    ):
        raise ValueError(f"{path} must map node names to 'ros__parameters:' sections")
    return path.resolve()


def params_files_in(argv: Sequence[str]) -> list[Path]:
    """The files named by ``--params-file`` in a ROS command line."""
    return [Path(argv[i + 1]) for i, arg in enumerate(argv[:-1]) if arg == "--params-file"]


def _section_pattern(key: str) -> re.Pattern[str]:
    """The node names a section key applies to, as rcl matches them.

    A key without a leading slash is taken from the root; ``/**`` stands for
    any number of namespace levels (none included) and ``/*`` for exactly one.
    """
    name = key if key.startswith("/") else "/" + key
    parts = re.split(r"(/\*\*|/\*)", name)
    wildcard = {"/**": r"(/[^/]+)*", "/*": r"/[^/]+"}
    return re.compile("".join(wildcard.get(part, re.escape(part)) for part in parts))


def _flatten(parameters: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested YAML (kalman: {x0: 3}) to ROS parameter names (kalman.x0)."""
    flat: dict[str, Any] = {}
    for key, value in parameters.items():
        if isinstance(value, Mapping):
            flat.update(_flatten(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


def node_parameters(document: Mapping[str, Any], node: str) -> dict[str, Any]:
    """The parameters a file gives the node with fully qualified name ``node``.

    Every section whose key matches the name applies (``/**``, ``/**/estimator``,
    ``/robot1/estimator``, ``estimator``), in the file's order, a later section
    overriding what an earlier one set, as rcl does when a node starts.
    """
    values: dict[str, Any] = {}
    for key, section in document.items():
        if _section_pattern(str(key)).fullmatch(node) and isinstance(section, Mapping):
            values.update(_flatten(section.get("ros__parameters") or {}))
    return values


def read_node_parameters(parameters_yaml: str, node: str) -> dict[str, Any]:
    """``node_parameters`` of a parameter file's text (safe_load: a file never runs code)."""
    document = yaml.safe_load(parameters_yaml) or {}
    if not isinstance(document, Mapping):
        raise ValueError("a parameter file must map node names to 'ros__parameters:' sections")
    return node_parameters(document, node)
