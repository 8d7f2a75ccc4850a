"""Our reading of a parameter file gives each node exactly what rcl gives it."""

import pytest
from rclpy.node import Node

from estimation_nodes.params.param_files import read_node_parameters
from tests.unit.test_params_files import FILE

#: Parameters every rclpy node declares itself.
RCLPY_OWN = {"use_sim_time", "start_type_description_service"}


@pytest.mark.parametrize("namespace, name", [
    ("/", "estimator"), ("/robot1", "estimator"), ("/fleet/robot2", "estimator"),
    ("/robot1", "tile_sensor"), ("/", "other"),
])
def test_node_parameters_equal_what_rcl_gives_the_node(tmp_path, ros_env, domain_id, namespace,
                                                       name):
    import rclpy

    path = tmp_path / "params.yaml"
    path.write_text(FILE)
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
    ours = read_node_parameters(FILE, fully_qualified)
    assert {k: list(v) if isinstance(v, list) else v for k, v in from_rcl.items()} == ours
