"""Occupancy grid mapping with known poses, and estimation_map writing a map_server map
that the package's own map reader gives back cell for cell."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimation_nodes.core.grid.mapping import MappingModel, OccupancyGridMapper
from estimation_nodes.core.grid.occupancy import FREE, OCCUPIED, UNKNOWN, OccupancyMap
from estimation_nodes.core.sim import planar
from estimation_nodes.params import map_files
from estimation_nodes.tools.importers import cli as importer
from estimation_nodes.tools.mapping import cli
from tests.unit.test_importers import corrected_log

ANGLES = np.linspace(-math.pi, math.pi, 360, endpoint=False)


def room() -> planar.PlanarWorld:
    """A 4 m x 3 m room, walls one 0.05 m cell thick, its corner at (0, 0)."""
    cells = np.zeros((60, 80), dtype=np.int8)
    cells[[0, -1], :] = OCCUPIED
    cells[:, [0, -1]] = OCCUPIED
    return planar.planar_world(OccupancyMap(cells, 0.05, (0.0, 0.0)))


def mapped(poses, range_max=20.0) -> OccupancyMap:
    world = room()
    mapper = OccupancyGridMapper(MappingModel(0.05))
    for pose in poses:
        mapper.add_scan(pose, planar.ray_cast(world, pose, ANGLES, range_max), ANGLES,
                        range_max)
    return mapper.occupancy()


def value_at(occupancy: OccupancyMap, x: float, y: float) -> int:
    col = math.floor((x - occupancy.origin[0]) / occupancy.resolution)
    row = math.floor((y - occupancy.origin[1]) / occupancy.resolution)
    return int(occupancy.cells[row, col])


def test_the_walls_are_occupied_the_room_free_and_nothing_beyond_is_known():
    occupancy = mapped([(1.0, 1.0, 0.0), (3.0, 2.0, 1.0), (2.0, 1.5, -2.0)])
    # Cropped to what was seen: the room and its walls.
    assert occupancy.origin == pytest.approx((0.0, 0.0), abs=1e-9)
    assert occupancy.cells.shape == (60, 80)
    for x, y in [(0.02, 1.5), (3.98, 0.7), (2.0, 0.02), (1.1, 2.98)]:
        assert value_at(occupancy, x, y) == OCCUPIED, (x, y)
    for x, y in [(0.5, 0.5), (2.0, 1.5), (3.5, 2.5), (1.0, 2.8)]:
        assert value_at(occupancy, x, y) == FREE, (x, y)
    assert (occupancy.cells == OCCUPIED).sum() < 0.1 * occupancy.cells.size


def test_beams_without_a_return_tell_nothing():
    world = room()
    mapper = OccupancyGridMapper(MappingModel(0.05))
    mapper.add_scan((2.0, 1.5, 0.0), planar.ray_cast(world, (2.0, 1.5, 0.0), ANGLES, 20.0),
                    ANGLES, 20.0)
    before = mapper.occupancy()
    for no_return in (np.full(360, np.inf), np.full(360, 30.0), np.full(360, np.nan),
                      np.full(360, -1.0)):
        mapper.add_scan((2.0, 1.5, 0.0), no_return, ANGLES, 20.0)
    np.testing.assert_array_equal(mapper.occupancy().cells, before.cells)


def test_an_empty_mapper_and_bad_scans_are_refused():
    mapper = OccupancyGridMapper(MappingModel(0.05))
    with pytest.raises(ValueError, match="empty"):
        mapper.occupancy()
    with pytest.raises(ValueError, match="ranges and angles"):
        mapper.add_scan((0.0, 0.0, 0.0), np.ones(3), np.ones(4), 10.0)
    with pytest.raises(ValueError, match="pose"):
        mapper.add_scan((math.nan, 0.0, 0.0), np.ones(3), np.ones(3), 10.0)


def test_a_written_map_reads_back_cell_for_cell(tmp_path):
    occupancy = mapped([(1.0, 1.0, 0.0), (3.0, 2.0, 1.0)])
    path = map_files.write_map_file(tmp_path / "room", occupancy)
    back = map_files.read_map_file(path)
    np.testing.assert_array_equal(back.cells, occupancy.cells)
    assert back.resolution == occupancy.resolution
    assert back.origin == pytest.approx(occupancy.origin)
    assert set(np.unique(back.cells)) <= {FREE, OCCUPIED, UNKNOWN}


def test_estimation_map_maps_a_recording_at_its_ground_truth(tmp_path, capsys):
    log = tmp_path / "run.log"
    log.write_text(corrected_log())
    importer.main(["carmen", str(log), "-o", str(tmp_path / "run.mcap")])
    cli.main([str(tmp_path / "run.mcap"), "-o", str(tmp_path / "map"), "--resolution", "0.1"])
    printed = capsys.readouterr().out
    assert "2 scans mapped" in printed
    occupancy = map_files.read_map_file(tmp_path / "map.yaml")
    # The first scan's beam straight ahead (1.5 m, ... the log's 4 beams) ends in a
    # wall cell; the 81.83 m beam is no return and maps nothing.
    x, y, theta = 1.1, 0.05, 0.12
    angle = theta - math.pi / 2
    assert value_at(occupancy, x + 1.5 * math.cos(angle), y + 1.5 * math.sin(angle)) \
        == OCCUPIED
    assert occupancy.cells.shape[0] * 0.1 < 10 and occupancy.cells.shape[1] * 0.1 < 10


def test_estimation_map_of_a_recording_without_poses_is_one_line_and_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as ended:
        cli.main([str(tmp_path / "missing.mcap"), "-o", str(tmp_path / "map")])
    assert ended.value.code == 2
    assert capsys.readouterr().err.count("\n") == 1
