"""What the demo adds to a scenario's parameters so that its monitor, and the recording the
monitor writes, lose nothing of the run (no rclpy here: imported before rclpy is).

- Who must hear a reading before it goes out: each simulator holds its readings (or
  the robot its first step), and the commander its first command, until the nodes its
  ``hold_for_nodes`` / ``required_nodes`` name are matched subscribers
  (nodes/subscribers.py). The demo adds its monitor to those the scenario names. A
  count of subscribers, or the monitor seeing the publishers from its side, is not
  enough: a publisher that has not matched the monitor yet sends it nothing, and a
  recording that lacks the first scan the localizer took does not replay.
- How many estimates each output keeps: the outputs are reliable and transient_local,
  keeping ``history_depth`` messages; with 1, a monitor busy for the time between two
  estimates loses one. The demo raises it to what HISTORY_BYTES holds of the largest
  output (a 1e6-cell belief is 8 MB), at most HISTORY_LIMIT messages, and never lowers
  what the scenario gives.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from estimation_nodes.core.errors import MapError
from estimation_nodes.params.map_files import read_map_file
from estimation_nodes.params.models import read_world_file
from estimation_nodes.params.param_files import read_node_parameters
from estimation_nodes.params.simulators import build_commander_settings
from estimation_nodes.params.specs import NODE_SPECS, UNSET, spec_defaults
from estimation_nodes.params.values import as_list

#: The demo's monitor nodes (tools/demo/monitor.py, grid_run.py): a tile or Kalman run's,
#: a grid or landmarks run's.
MONITOR = "estimation_demo_monitor"
GRID_MONITOR = "estimation_demo_grid_monitor"

#: Bytes of its largest message each output of the estimator or a localizer may keep for
#: the monitor: 4 beliefs of a million cells, a run's worth of anything small...
HISTORY_BYTES = 32 * 2**20
#: ...and at most this many messages (the landmarks scenario publishes some 3,300 poses).
HISTORY_LIMIT = 10_000
#: A PoseWithCovarianceStamped's CDR bytes, about (36 + 7 doubles and a header): the
#: smallest estimate the depth is reckoned for.
POSE_BYTES = 400

#: Each kind's estimating node and the simulator that holds its readings for it.
ESTIMATING_NODE = {"tiles": "estimator", "linear_system": "estimator",
                   "grid": "grid_localizer", "landmarks": "ekf_localizer"}
SIMULATOR = {"tiles": "tile_sensor", "linear_system": "linear_system",
             "grid": "planar_robot", "landmarks": "landmark_robot"}


def node_values(parameters_yaml: str, node: str) -> dict[str, Any]:
    """The values the root-namespace node ``node`` gets from the file: its defaults, then
    every section that applies to it."""
    values = spec_defaults(NODE_SPECS[node])
    values.update(read_node_parameters(parameters_yaml, f"/{node}"))
    return values


def history_depth(message_bytes: int, given: int) -> int:
    """The depth the demo runs an output at: HISTORY_BYTES of ``message_bytes`` messages
    (at least 1, at most HISTORY_LIMIT), or ``given`` if that is more."""
    return max(int(given), min(HISTORY_LIMIT, max(1, HISTORY_BYTES // max(message_bytes, 1))))


def largest_output_bytes(parameters_yaml: str, kind: str) -> int | None:
    """The bytes of the largest message the kind's estimating node publishes, about; None
    when the parameters do not say (a bad value, which the node itself then reports)."""
    try:
        if kind in ("tiles", "linear_system"):
            return _estimator_bytes(node_values(parameters_yaml, "estimator"))
        if kind == "grid":
            return _grid_bytes(parameters_yaml)
    except (ValueError, TypeError, KeyError, MapError):
        return None
    return POSE_BYTES


def _estimator_bytes(values: Mapping[str, Any]) -> int:
    """A belief (a double per cell) or a Kalman state (x and P), whichever is larger."""
    world_file = values.get("world_file") or ""
    cells = len(read_world_file(world_file)) if world_file \
        else len(as_list("world", values["world"]))
    n = len(as_list("kalman.matrix.x0", values["kalman.matrix.x0"])) \
        if values["kalman.mode"] == "matrix" else 1
    return max(8 * max(cells, n + n * n), POSE_BYTES)


def _grid_bytes(parameters_yaml: str) -> int:
    """belief_map: a byte per cell of the state grid, the map at the localizer's
    resolution (its map_file's, else the one the robot publishes)."""
    values = node_values(parameters_yaml, "grid_localizer")
    map_file = values["map_file"] or node_values(parameters_yaml, "planar_robot")["map_file"]
    if not map_file:
        return POSE_BYTES
    occupancy = read_map_file(Path(map_file))
    scale = occupancy.resolution / float(values["resolution"])
    rows, columns = occupancy.cells.shape
    return max(math.ceil(rows * scale) * math.ceil(columns * scale), POSE_BYTES)


def held_for(parameters_yaml: str, node: str, monitor: str) -> list[str]:
    """The nodes ``node`` (a simulator, or the commander) waits for in the scenario, and
    the monitor."""
    values = node_values(parameters_yaml, node)
    if node == "motion_commander":
        values["required_subscribers"] = max(int(values["required_subscribers"]), 1)
        names = list(build_commander_settings(values).required_nodes)
    else:
        given = values["hold_for_nodes"]
        names = [] if given is UNSET else [str(name).strip() for name in given]
    return [name for name in names if name] + ([monitor] if monitor not in names else [])


def node_overrides(parameters_yaml: str, kind: str, monitor_hears_inputs: bool
                   ) -> dict[str, tuple[str, ...]]:
    """ROS arguments the demo gives each node of a ``kind`` run, by node name.

    ``monitor_hears_inputs``: whether the monitor subscribes to the simulator's readings
    (a grid or landmarks run's does only to record or serve them); if not, nothing waits
    for it there. The outputs are latched: the monitor gets what they keep however late
    it matches, and the depth sees to the rest.
    """
    overrides: dict[str, tuple[str, ...]] = {}
    estimating = ESTIMATING_NODE[kind]
    size = largest_output_bytes(parameters_yaml, kind)
    try:
        if size is not None:
            given = node_values(parameters_yaml, estimating)["history_depth"]
            overrides[estimating] = ("-p", f"history_depth:={history_depth(size, given)}")
    except (ValueError, TypeError):
        pass                            # the node says what is wrong when it starts
    monitor = GRID_MONITOR if kind in ("grid", "landmarks") else MONITOR
    waiting = [SIMULATOR[kind]] if monitor_hears_inputs else []
    if kind in ("tiles", "linear_system"):
        waiting.append("motion_commander")
    for node in waiting:
        parameter = "required_nodes" if node == "motion_commander" else "hold_for_nodes"
        try:
            names = held_for(parameters_yaml, node, monitor)
        except (ValueError, TypeError):
            continue                    # the node says what is wrong when it starts
        overrides[node] = ("-p", f"{parameter}:=[{', '.join(names)}]")
    return overrides
