"""The grid nodes' settings (grid_localizer, planar_robot), validated from their parameter
values (GRID_LOCALIZER_SPECS, PLANAR_ROBOT_SPECS in params/specs.py)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from estimation_nodes.core.grid.likelihood_field import SensorField, grid_model
from estimation_nodes.core.grid.localization import GridLocalization
from estimation_nodes.core.grid.model import GridModel
from estimation_nodes.core.grid.motion import OdometryNoise
from estimation_nodes.core.grid.occupancy import OccupancyMap
from estimation_nodes.params.map_files import read_map_file
from estimation_nodes.params.specs import GRID_MODEL_SPECS, UNSET, spec_defaults


def laser_pose_given(values: Mapping[str, Any]) -> tuple[float, float, float] | None:
    """The ``laser_pose`` parameter, or None where it is unset (the localizer's default)."""
    given = values["laser_pose"]
    if given is UNSET or not len(given):
        return None
    if len(given) != 3 or not all(math.isfinite(v) for v in given):
        raise ValueError(f"laser_pose: expected [x, y, yaw], got {list(given)}")
    return (float(given[0]), float(given[1]), float(given[2]))


def sensor_field(values: Mapping[str, Any]) -> SensorField:
    """The likelihood field's parameters from a node's values (GRID_MODEL_SPECS)."""
    return SensorField(z_hit=values["laser_z_hit"], z_rand=values["laser_z_rand"],
                       sigma_hit=values["laser_sigma_hit"],
                       max_range=values["laser_max_range"],
                       max_distance=values["laser_likelihood_max_dist"],
                       laser_pose=laser_pose_given(values) or (0.0, 0.0, 0.0))


def odometry_noise(values: Mapping[str, Any]) -> OdometryNoise:
    """The odometry motion model's noise from a node's values (GRID_MODEL_SPECS)."""
    return OdometryNoise(alpha1=values["alpha1"], alpha2=values["alpha2"],
                         alpha3=values["alpha3"], alpha4=values["alpha4"])


#: AMCL's initial covariance for initial_pose (0.5 m, 0.5 m, pi/12 std).
AMCL_INITIAL_COVARIANCE = (0.25, 0.25, (math.pi / 12) ** 2)
ODOMETRY_SOURCES = ("tf", "topic")


@dataclass(frozen=True)
class GridFrames:
    """How the localizer sits in the tf tree (nav2_amcl's names)."""

    odometry_from_tf: bool = True
    odom_frame_id: str = "odom"
    base_frame_id: str = "base_link"
    global_frame_id: str = "map"
    tf_broadcast: bool = True
    transform_tolerance: float = 1.0
    #: The laser's mount given as a parameter, or None: from the tree (odometry from tf) or
    #: the robot's origin (odometry from the topic).
    laser_pose: tuple[float, float, float] | None = None
    #: (x, y, yaw) to start from (set_initial_pose), or None.
    initial_pose: tuple[float, float, float] | None = None


def grid_frames(values: Mapping[str, Any]) -> GridFrames:
    if values["odometry_source"] not in ODOMETRY_SOURCES:
        raise ValueError(f"odometry_source: expected one of {', '.join(ODOMETRY_SOURCES)}, "
                         f"got {values['odometry_source']!r}")
    for name in ("odom_frame_id", "base_frame_id", "global_frame_id"):
        if not values[name].strip():
            raise ValueError(f"{name}: expected a frame name, got an empty string")
    if len({values["odom_frame_id"], values["base_frame_id"], values["global_frame_id"]}) < 3:
        raise ValueError("odom_frame_id, base_frame_id, global_frame_id: expected three "
                         "different frames")
    initial = (values["initial_pose.x"], values["initial_pose.y"], values["initial_pose.yaw"])
    return GridFrames(
        odometry_from_tf=values["odometry_source"] == "tf",
        odom_frame_id=values["odom_frame_id"], base_frame_id=values["base_frame_id"],
        global_frame_id=values["global_frame_id"], tf_broadcast=values["tf_broadcast"],
        transform_tolerance=values["transform_tolerance"],
        laser_pose=laser_pose_given(values),
        initial_pose=initial if values["set_initial_pose"] else None)


@dataclass(frozen=True)
class GridLocalizerSettings:
    """The localizer's validated parameters; the map comes from map_file or the topic."""

    sensor: SensorField
    noise: OdometryNoise
    resolution: float
    heading_bins: int
    max_states: int
    #: From map_file, read and reduced at start-up; None: from the map topic.
    map: OccupancyMap | None
    model: GridModel | None
    update_min_d: float
    update_min_a: float
    max_odom_jump: float
    #: Seconds a scan waits for the odometry of its time.
    odom_wait: float
    kidnap_probability: float
    odometry_failure_probability: float
    belief_floor: float
    max_beams: int
    independent_beams: int
    quality_radius: float
    #: quality_angle, in radians.
    quality_angle: float
    history_depth: int
    diagnostics_period: float
    #: Whether the published pose is refined by the scan's fit (grid/scan_fit.py).
    scan_fit: bool = False
    frames: GridFrames = field(default_factory=GridFrames)

    def model_for(self, occupancy: OccupancyMap) -> GridModel:
        return grid_model(occupancy, self.resolution, self.heading_bins, self.sensor,
                          self.max_states, self.scan_fit)

    def localization(self, model: GridModel) -> GridLocalization:
        """A new belief on ``model`` with this update rule, uniform over the free cells."""
        return GridLocalization(model, self.noise, self.update_min_d, self.update_min_a,
                                self.max_odom_jump, self.kidnap_probability,
                                self.independent_beams, self.belief_floor,
                                self.odometry_failure_probability)


def build_grid_localizer_settings(values: Mapping[str, Any]) -> GridLocalizerSettings:
    """Validate the localizer's parameters; with map_file set, read it and check that it
    makes a state grid within max_states (a MapError names what is wrong)."""
    sensor = sensor_field(values)
    frames = grid_frames(values)
    occupancy = read_map_file(Path(values["map_file"])) if values["map_file"] else None
    model = grid_model(occupancy, values["resolution"], values["heading_bins"], sensor,
                       values["max_states"], values["scan_fit"]) if occupancy is not None \
        else None
    return GridLocalizerSettings(
        sensor, odometry_noise(values), values["resolution"], values["heading_bins"],
        values["max_states"], occupancy, model, update_min_d=values["update_min_d"],
        update_min_a=values["update_min_a"], max_odom_jump=values["max_odom_jump"],
        odom_wait=values["odom_wait"], kidnap_probability=values["kidnap_probability"],
        odometry_failure_probability=values["odometry_failure_probability"],
        max_beams=values["max_beams"],
        belief_floor=values["belief_floor"],
        independent_beams=values["laser_independent_beams"],
        quality_radius=values["quality_radius"],
        quality_angle=math.radians(values["quality_angle"]),
        history_depth=values["history_depth"], diagnostics_period=values["diagnostics_period"],
        scan_fit=values["scan_fit"], frames=frames)


@dataclass(frozen=True)
class PlanarRobotSettings:
    """The simulated robot's validated parameters (PLANAR_ROBOT_SPECS)."""

    map: OccupancyMap
    sensor: SensorField
    noise: OdometryNoise
    seed: int
    rate_hz: float
    speed: float
    turn_rate: float
    robot_radius: float
    beams: int
    scan_noise_std: float
    scan_random_fraction: float
    #: [x, y, yaw], or None: a free place drawn from the seed.
    initial_pose: tuple[float, float, float] | None
    duration: float
    exit_when_done: bool
    kidnap_after: float
    hold_until_matched: bool
    hold_for_nodes: tuple[str, ...]


def build_planar_robot_settings(values: Mapping[str, Any]) -> PlanarRobotSettings:
    """Validate the simulated robot's parameters and read its map (it needs one)."""
    if not values["map_file"]:
        raise ValueError("map_file: the simulated robot needs a map (map_server's YAML)")
    given = values["initial_pose"]
    initial_pose = None
    if given is not UNSET and len(given):
        if len(given) != 3 or not all(math.isfinite(v) for v in given):
            raise ValueError(f"initial_pose: expected [x, y, yaw], got {list(given)}")
        initial_pose = (float(given[0]), float(given[1]), float(given[2]))
    return PlanarRobotSettings(
        read_map_file(Path(values["map_file"])), sensor_field(values), odometry_noise(values),
        seed=values["seed"], rate_hz=values["rate_hz"], speed=values["speed"],
        turn_rate=values["turn_rate"], robot_radius=values["robot_radius"],
        beams=values["beams"], scan_noise_std=values["scan_noise_std"],
        scan_random_fraction=values["scan_random_fraction"], initial_pose=initial_pose,
        duration=values["duration"], exit_when_done=values["exit_when_done"],
        kidnap_after=values["kidnap_after"], hold_until_matched=values["hold_until_matched"],
        hold_for_nodes=tuple(name for name in values["hold_for_nodes"] if name))


def default_sensor_field() -> SensorField:
    """The likelihood field of the spec table's defaults."""
    return sensor_field(spec_defaults(GRID_MODEL_SPECS))


def default_odometry_noise() -> OdometryNoise:
    """The odometry noise of the spec table's defaults."""
    return odometry_noise(spec_defaults(GRID_MODEL_SPECS))
