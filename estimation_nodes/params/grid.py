"""The grid nodes' settings (grid_localizer, planar_robot), validated from their parameter
values (GRID_LOCALIZER_SPECS, PLANAR_ROBOT_SPECS in params/specs.py)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from estimation_nodes.core.grid.likelihood_field import SensorField, grid_model
from estimation_nodes.core.grid.occupancy import OccupancyMap
from estimation_nodes.core.grid.steps import GridModel, OdometryNoise
from estimation_nodes.params.map_files import read_map_file
from estimation_nodes.params.specs import GRID_MODEL_SPECS, spec_defaults


def sensor_field(values: Mapping[str, Any]) -> SensorField:
    """The likelihood field's parameters from a node's values (GRID_MODEL_SPECS)."""
    return SensorField(z_hit=values["laser_z_hit"], z_rand=values["laser_z_rand"],
                       sigma_hit=values["laser_sigma_hit"],
                       max_range=values["laser_max_range"],
                       max_distance=values["laser_likelihood_max_dist"])


def odometry_noise(values: Mapping[str, Any]) -> OdometryNoise:
    """The odometry motion model's noise from a node's values (GRID_MODEL_SPECS)."""
    return OdometryNoise(alpha1=values["alpha1"], alpha2=values["alpha2"],
                         alpha3=values["alpha3"], alpha4=values["alpha4"])


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

    def model_for(self, occupancy: OccupancyMap) -> GridModel:
        return grid_model(occupancy, self.resolution, self.heading_bins, self.sensor,
                          self.max_states)


def build_grid_localizer_settings(values: Mapping[str, Any]) -> GridLocalizerSettings:
    """Validate the localizer's parameters; with map_file set, read it and check that it
    makes a state grid within max_states (a MapError names what is wrong)."""
    sensor = sensor_field(values)
    if not values["frame_id"].strip():
        raise ValueError("frame_id: expected a frame name, got an empty string")
    occupancy = read_map_file(Path(values["map_file"])) if values["map_file"] else None
    model = grid_model(occupancy, values["resolution"], values["heading_bins"], sensor,
                       values["max_states"]) if occupancy is not None else None
    return GridLocalizerSettings(sensor, odometry_noise(values), values["resolution"],
                                 values["heading_bins"], values["max_states"], occupancy,
                                 model)


def default_sensor_field() -> SensorField:
    """The likelihood field of the spec table's defaults."""
    return sensor_field(spec_defaults(GRID_MODEL_SPECS))


def default_odometry_noise() -> OdometryNoise:
    """The odometry noise of the spec table's defaults."""
    return odometry_noise(spec_defaults(GRID_MODEL_SPECS))
