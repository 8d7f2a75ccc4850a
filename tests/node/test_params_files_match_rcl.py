"""Our reading of a parameter file gives each node exactly what rcl gives it."""

from pathlib import Path

import pytest
from rclpy.node import Node

from estimation_nodes.params.param_files import read_node_parameters
from estimation_nodes.params.specs import NODE_SPECS
from tests.conftest import SCENARIOS
from tests.unit.test_params_files import FILE

#: Parameters every rclpy node declares itself.
RCLPY_OWN = {"use_sim_time", "start_type_description_service"}


def rcl_and_ours(path: Path, domain_id: int, namespace: str, name: str) -> tuple[dict, dict]:
    """What rcl gives node ``namespace/name`` from the file at ``path``, and what we read."""
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id,
               args=["test", "--ros-args", "--params-file", str(path)])
    try:
        node = Node(name, namespace=namespace, context=context,
                    automatically_declare_parameters_from_overrides=True)
        from_rcl = {key: parameter.value for key, parameter in node.get_parameters_by_prefix(
            "").items() if key not in RCLPY_OWN}
        fully_qualified = node.get_fully_qualified_name()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    ours = read_node_parameters(path.read_text(encoding="utf-8"), fully_qualified)
    return {k: list(v) if isinstance(v, list) else v for k, v in from_rcl.items()}, ours


@pytest.mark.parametrize("namespace, name", [
    ("/", "estimator"), ("/robot1", "estimator"), ("/fleet/robot2", "estimator"),
    ("/robot1", "tile_sensor"), ("/", "other"),
])
def test_node_parameters_equal_what_rcl_gives_the_node(tmp_path, ros_env, domain_id, namespace,
                                                       name):
    path = tmp_path / "params.yaml"
    path.write_text(FILE)
    from_rcl, ours = rcl_and_ours(path, domain_id, namespace, name)
    assert from_rcl == ours


@pytest.mark.parametrize("scenario", sorted(SCENARIOS.glob("*.yaml")), ids=lambda p: p.name)
def test_rcl_reads_every_scenario_file_as_we_do(ros_env, domain_id, scenario):
    # The files are commented throughout: rcl must still read every value, for every node.
    for node in NODE_SPECS:
        from_rcl, ours = rcl_and_ours(scenario, domain_id, "/robot1", node)
        assert from_rcl == ours, f"{scenario.name}, /robot1/{node}"
