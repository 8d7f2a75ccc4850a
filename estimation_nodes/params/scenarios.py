"""Which kind of run a scenario (a ROS parameter file) is: its own word, not a guess.

A scenario says its kind in a section for estimation_demo, which no node reads::

    /**/estimation_demo:
      ros__parameters:
        kind: grid

``tiles``: the book's tile world (estimator, tile_sensor, motion_commander);
``linear_system``: the matrix Kalman filter on a simulated linear system;
``grid``: grid localization on a map (grid_localizer, planar_robot); ``landmarks``:
the landmark EKF or UKF (ekf_localizer, landmark_robot). A file that says nothing is a
tile-world run, the package's first kind. A recording keeps its parameter file, so
estimation_replay and estimation_plot read the kind of a recorded run the same way.
"""

from __future__ import annotations

from typing import Any

import yaml

from estimation_nodes.params.param_files import node_parameters

KINDS = ("tiles", "linear_system", "grid", "landmarks", "fusion")
DEFAULT_KIND = "tiles"
#: The section's node name.
DEMO = "estimation_demo"


def scenario_kind(parameters_yaml: str) -> str:
    """The kind a parameter file's text says; ValueError for a kind that is none of KINDS."""
    document: Any = yaml.safe_load(parameters_yaml) or {}
    kind = node_parameters(document, f"/{DEMO}").get("kind", DEFAULT_KIND) \
        if isinstance(document, dict) else DEFAULT_KIND
    if kind not in KINDS:
        raise ValueError(f"kind: expected one of {', '.join(KINDS)} in the {DEMO} section, "
                         f"got {kind!r}")
    return kind
