"""The core is numpy only: importing it must not pull in rclpy."""

import subprocess
import sys


def test_core_does_not_import_rclpy():
    probe = ("import sys, estimation_nodes.core; "
             "bad = sorted(m for m in sys.modules "
             "if m.split('.')[0] in ('rclpy', 'rcl_interfaces'));"
             "print(bad); sys.exit(1 if bad else 0)")
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 0, f"core imported ROS modules: {result.stdout}{result.stderr}"
