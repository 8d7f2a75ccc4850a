"""Checks on a user's ROS parameter files before ROS reads them.

rcl's own parser fails with a long traceback; these checks say in one line
what is wrong with the file. Only yaml.safe_load is used: a parameter file
can never run code.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

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
