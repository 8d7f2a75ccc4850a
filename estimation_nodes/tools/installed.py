"""Where the package's and ROS's installed files are: the share/ folders of the prefixes."""

from __future__ import annotations

import os
import sys
from pathlib import Path


def share_dirs() -> list[Path]:
    """``<prefix>/share`` of every prefix on AMENT_PREFIX_PATH, then of this Python's prefix.

    The order is ament's: an overlay named first wins.
    """
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(sys.prefix)
    return [Path(p) / "share" for p in prefixes if (Path(p) / "share").is_dir()]
