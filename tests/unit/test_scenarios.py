"""A scenario says which kind of run it is; the demo and the replay read it, not guess it."""

import pytest

from estimation_nodes.params.scenarios import KINDS, scenario_kind
from tests.conftest import SCENARIOS

EXPECTED = {"book_world": "tiles", "example_6_14": "tiles", "example_6_18": "tiles",
            "localization": "tiles", "tracking_2d": "linear_system", "grid_corridor": "grid",
            "grid_localization": "grid", "landmarks": "landmarks", "fusion": "fusion"}


def test_every_shipped_scenario_says_its_kind():
    shipped = {path.stem: scenario_kind(path.read_text()) for path in SCENARIOS.glob("*.yaml")}
    assert shipped == EXPECTED
    assert set(shipped.values()) == set(KINDS)


def test_a_file_that_says_nothing_is_a_tile_run_and_a_wrong_kind_is_named():
    assert scenario_kind("/**/estimator:\n  ros__parameters:\n    world: [dark]\n") == "tiles"
    assert scenario_kind("") == "tiles"
    with pytest.raises(ValueError, match="kind: expected one of tiles"):
        scenario_kind("/**/estimation_demo:\n  ros__parameters:\n    kind: grd\n")
