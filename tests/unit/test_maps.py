"""Map files as map_server reads them, and the grid models built from them."""

import math
from dataclasses import replace

import numpy as np
import pytest

from estimation_nodes.core import errors
from estimation_nodes.core.grid import likelihood_field
from estimation_nodes.core.grid.occupancy import OCCUPIED, UNKNOWN, OccupancyMap
from estimation_nodes.params import map_files as maps
from estimation_nodes.params.grid import default_sensor_field
from tests.conftest import REPO

MAPS = REPO / "maps"


def write_map(tmp_path, pixels, **fields):
    from PIL import Image

    Image.fromarray(np.asarray(pixels, dtype=np.uint8)).save(tmp_path / "m.png")
    spec = {"image": "m.png", "resolution": 0.1, "origin": [1.0, 2.0, 0.0], "negate": 0,
            "occupied_thresh": 0.65, "free_thresh": 0.196, **fields}
    text = "".join(f"{k}: {v}\n" for k, v in spec.items() if v is not None)
    (tmp_path / "m.yaml").write_text(text)
    return tmp_path / "m.yaml"


def test_pixels_become_occupancy_values_as_map_server_does(tmp_path):
    # Top row of the image is the map's last row; dark is occupied, light free.
    path = write_map(tmp_path, [[0, 254], [205, 254]])
    occupancy = maps.read_map_file(path)
    assert occupancy.cells.tolist() == [[-1, 0], [100, 0]]
    assert occupancy.resolution == 0.1 and occupancy.origin == (1.0, 2.0)


def test_negate_and_scale_modes(tmp_path):
    negated = maps.read_map_file(write_map(tmp_path, [[0, 254]], negate=1))
    assert negated.cells.tolist() == [[0, 100]]
    scaled = maps.read_map_file(write_map(tmp_path, [[128, 0]], mode="scale"))
    assert 1 <= scaled.cells[0, 0] <= 99 and scaled.cells[0, 1] == 100


@pytest.mark.parametrize("fields, message", [
    ({"resolution": 0}, "resolution"),
    ({"resolution": -0.1}, "resolution"),
    ({"origin": "[.nan, 0.0, 0.0]"}, "origin"),
    ({"origin": "[0.0, 0.0, 0.5]"}, "rotated"),
    ({"image": "missing.png"}, "does not exist"),
    ({"mode": "fancy"}, "mode"),
    ({"free_thresh": 0.9}, "free_thresh"),
    ({"image": None}, "image: missing"),
])
def test_bad_map_files_name_the_field(tmp_path, fields, message):
    path = write_map(tmp_path, [[254, 254], [254, 0]], **fields)
    with pytest.raises(errors.MapError, match=message):
        maps.read_map_file(path)


def test_not_yaml_and_missing_file(tmp_path):
    (tmp_path / "bad.yaml").write_text("image: [unclosed\n")
    with pytest.raises(errors.MapError, match="not valid YAML"):
        maps.read_map_file(tmp_path / "bad.yaml")
    with pytest.raises(errors.MapError, match="cannot read"):
        maps.read_map_file(tmp_path / "none.yaml")


@pytest.mark.parametrize("name", ["corridor", "office"])
def test_the_shipped_maps_load_at_the_default_resolution(name):
    occupancy = maps.read_map_file(MAPS / f"{name}.yaml")
    model = likelihood_field.grid_model(occupancy, 0.1, 72, default_sensor_field(), 5_000_000)
    assert model.free.any() and (~model.free).any()
    assert model.resolution == 0.1


def test_the_office_is_the_benchmark_size():
    occupancy = maps.read_map_file(MAPS / "office.yaml")
    model = likelihood_field.grid_model(occupancy, 0.1, 72, default_sensor_field(), 5_000_000)
    assert model.shape == (72, 200, 200)          # 2.88 million states


def test_reduction_free_only_where_every_map_cell_is_and_field_by_distance():
    cells = np.zeros((4, 6), dtype=np.int8)
    cells[0, 0] = OCCUPIED
    cells[3, 5] = UNKNOWN
    occupancy = OccupancyMap(cells, 0.05, (0.0, 0.0))
    sensor = replace(default_sensor_field(), sigma_hit=0.1, max_distance=1.0)
    model = likelihood_field.grid_model(occupancy, 0.1, 4, sensor, 1000)
    assert model.free.tolist() == [[False, True, True], [True, True, False]]
    # The block holding the obstacle is at distance 0: the field's largest value there.
    assert model.log_field[0, 0] == pytest.approx(math.log(0.5 + 0.5 / 12.0))
    assert model.log_field[0, 0] > model.log_field[1, 2] > model.log_outside - 1e-12


def test_a_resolution_not_a_multiple_of_the_map_and_too_many_states_are_refused():
    occupancy = OccupancyMap(np.zeros((10, 10), dtype=np.int8), 0.05, (0.0, 0.0))
    with pytest.raises(errors.MapError, match="whole multiple"):
        likelihood_field.grid_model(occupancy, 0.12, 8, default_sensor_field(), 10_000)
    with pytest.raises(errors.MapError, match="max_states"):
        likelihood_field.grid_model(occupancy, 0.05, 72, default_sensor_field(), 1000)
