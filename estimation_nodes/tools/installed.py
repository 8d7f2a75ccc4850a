"""Where the package's and ROS's installed files are (params/installed.py holds the search)."""

from estimation_nodes.params.installed import share_dirs

__all__ = ["share_dirs"]
