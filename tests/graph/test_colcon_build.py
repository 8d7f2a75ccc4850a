"""The same tree builds in a colcon workspace, with the executables where ros2 run looks."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SOURCES = ("estimation_nodes", "msgs_config", "resource", "scripts", "package.xml",
           "pyproject.toml", "setup.py", "setup.cfg", "README.md")


def test_colcon_build_installs_an_ament_package(tmp_path, ros_env):
    colcon = Path(sys.executable).parent / "colcon"
    package = tmp_path / "src" / "estimation_nodes"
    package.mkdir(parents=True)
    for name in SOURCES:
        source = REPO / name
        if source.is_dir():
            shutil.copytree(source, package / name,
                            ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(source, package / name)
    env = dict(ros_env, PATH=f"{colcon.parent}{os.pathsep}{ros_env['PATH']}")
    result = subprocess.run([str(colcon), "build", "--event-handlers", "console_direct-"],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    prefix = tmp_path / "install" / "estimation_nodes"
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages"
            / "estimation_nodes").is_file()
    assert (prefix / "share" / "estimation_nodes" / "package.xml").is_file()
    for name in ("motion_commander", "tile_sensor", "estimator", "estimation_demo"):
        executable = prefix / "lib" / "estimation_nodes" / name
        assert os.access(executable, os.X_OK), f"{executable} missing or not executable"
        assert executable.read_text().startswith("#!"), executable
    # It runs: a bad parameter gives the node's own one-line error, exit 2.
    site = next(prefix.glob("lib/python3*/site-packages"))
    run = subprocess.run(
        [str(prefix / "lib" / "estimation_nodes" / "estimator"), "--ros-args",
         "-p", "motion_kernel:=[1.5]"],
        env={**env, "PYTHONPATH": str(site)}, capture_output=True, text=True, timeout=60)
    assert run.returncode == 2 and "motion_kernel" in run.stderr, run.stdout + run.stderr
