"""Parameter files read as rcl reads them: which sections apply to which node, and in what order.

tests/node/test_params_files_match_rcl.py checks the same cases against what
rclpy itself gives a node.
"""

import textwrap

import pytest

from estimation_nodes.params.param_files import node_parameters, read_node_parameters
from estimation_nodes.tools.replay.estimator import estimator_values

FILE = textwrap.dedent("""
    /**:
      ros__parameters:
        world: [dark, dark, bright]
        frame_id: everywhere
    /**/estimator:
      ros__parameters:
        kalman:
          var_z: 9.0
    /robot1/estimator:
      ros__parameters:
        frame_id: robot1
    /robot1/*:
      ros__parameters:
        history_depth: 7
    estimator:
      ros__parameters:
        frame_id: root
    /**/tile_sensor:
      ros__parameters:
        seed: 3
    /*:
      ros__parameters:
        diagnostics_period: 2.0
        frame_id: last
""")


@pytest.mark.parametrize("node, expected", [
    ("/estimator", {"world": ["dark", "dark", "bright"], "frame_id": "last", "kalman.var_z": 9.0,
                    "diagnostics_period": 2.0}),
    ("/robot1/estimator", {"world": ["dark", "dark", "bright"], "frame_id": "robot1",
                           "kalman.var_z": 9.0, "history_depth": 7}),
    ("/fleet/robot2/estimator", {"world": ["dark", "dark", "bright"], "frame_id": "everywhere",
                                 "kalman.var_z": 9.0}),
    ("/robot1/tile_sensor", {"world": ["dark", "dark", "bright"], "frame_id": "everywhere",
                             "history_depth": 7, "seed": 3}),
    ("/other", {"world": ["dark", "dark", "bright"], "frame_id": "last",
                "diagnostics_period": 2.0}),
])
def test_the_sections_that_apply_to_a_node_and_their_order(node, expected):
    assert read_node_parameters(FILE, node) == expected


def test_a_later_section_overrides_an_earlier_one():
    document = {"/**/estimator": {"ros__parameters": {"frame_id": "first"}},
                "/**": {"ros__parameters": {"frame_id": "second"}}}
    assert node_parameters(document, "/estimator") == {"frame_id": "second"}


def test_replay_reads_a_shared_wildcard_section():
    values = estimator_values(FILE)
    assert values["world"] == ["dark", "dark", "bright"]
    assert values["kalman.var_z"] == 9.0
    assert values["kalman.var_u"] == 2.0   # a default where the file says nothing


def test_a_file_that_is_not_a_mapping_is_refused():
    with pytest.raises(ValueError, match="map node names"):
        read_node_parameters("- just\n- a list\n", "/estimator")
