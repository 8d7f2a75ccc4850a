"""Where the package's installed files are: the share/ folders of the prefixes (no rclpy)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

#: The source tree, for runs from a checkout.
SOURCE_TREE = Path(__file__).resolve().parents[2]


def share_dirs() -> list[Path]:
    """``<prefix>/share`` of every prefix on AMENT_PREFIX_PATH, then of this Python's prefix.

    The order is ament's: an overlay named first wins.
    """
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(sys.prefix)
    return [Path(p) / "share" for p in prefixes if (Path(p) / "share").is_dir()]


def package_file(name: str, folder: str) -> Path | None:
    """A file the package ships in ``folder`` (maps, msgs_config): installed first, then in
    the source tree; None when there is none."""
    for base in [share / "estimation_nodes" for share in share_dirs()] + [SOURCE_TREE]:
        for candidate in (base / folder / name, base / name):
            if candidate.is_file():
                return candidate
    return None
