"""The real ROS 2 Jazzy `ros2` command line against the installed package.

ros2cli is not on PyPI: ../shared/ros2cli/build.sh builds it into <repo>/.cache/ros2cli
once per session. Every command runs in the test's own ROS domain (``ros_env``), with
``--no-daemon`` wherever the verb has it; a ``ros2 daemon`` that a test's commands
started anyway is ended by its pid after the test, which then fails.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
BUILD_SCRIPT = REPO.parent / "shared" / "ros2cli" / "build.sh"
CLI_VENV = REPO / ".cache" / "ros2cli"


@pytest.fixture(scope="session")
def cli_venv() -> Path:
    if not BUILD_SCRIPT.is_file():
        pytest.skip("../shared/ros2cli not found: the real ros2 CLI cannot be built here")
    built = subprocess.run(["bash", str(BUILD_SCRIPT), str(CLI_VENV)],
                           capture_output=True, text=True, timeout=600)
    if built.returncode != 0:
        pytest.fail(f"building the ros2 CLI failed:\n{built.stdout}{built.stderr}")
    return CLI_VENV


@pytest.fixture
def cli_env(ros_env, cli_venv) -> dict[str, str]:
    """The test's ROS environment with the CLI venv's `ros2` first on PATH; AMENT_PREFIX_PATH
    names this project's venv (where the package is installed) and then the CLI's."""
    env = dict(ros_env)
    env["PATH"] = f"{cli_venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env["AMENT_PREFIX_PATH"] = f"{sys.prefix}{os.pathsep}{cli_venv}"
    return env


@pytest.fixture
def ros2(cli_env, daemon_guard):
    """``ros2(*args, timeout=30)``: run ``ros2 ARGS``; the CompletedProcess (stdout and
    stderr together in ``.stdout``). Each command and its output are printed (``pytest -s``)."""

    def run(*args: str, timeout: float = 30.0) -> subprocess.CompletedProcess:
        started = time.monotonic()
        done = subprocess.run(["ros2", *args], env=cli_env, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, timeout=timeout)
        print(f"$ ros2 {' '.join(args)}  # exit {done.returncode}, "
              f"{time.monotonic() - started:.1f} s\n{done.stdout}", flush=True)
        return done

    return run


def stop_group(process: subprocess.Popen, grace: float = 10.0) -> int:
    """Ctrl-C as a terminal sends it: SIGINT to the process group that `ros2 run` leads (its
    own pid; the node it started is in it), SIGKILL to that group after ``grace``.

    SIGINT to the `ros2 run` process alone does not reach the node: ros2run does not forward
    it, and keeps waiting for the node.
    """

    def signal_group(sig: int) -> None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, sig)

    if process.poll() is None:
        signal_group(signal.SIGINT)
        with contextlib.suppress(subprocess.TimeoutExpired):
            process.wait(timeout=grace)
    signal_group(signal.SIGKILL)  # whatever is left of the group, e.g. a node that hung
    process.wait()
    return process.returncode


@pytest.fixture
def ros2_start(cli_env, daemon_guard):
    """``ros2_start(*args)``: start a long-running ``ros2 ARGS`` (e.g. ``run``) in a process
    group of its own; ended by ``stop_group`` at teardown at the latest."""
    started: list[subprocess.Popen] = []

    def start(*args: str) -> subprocess.Popen:
        process = subprocess.Popen(["ros2", *args], env=cli_env, stdout=subprocess.PIPE,
                                   stderr=subprocess.STDOUT, text=True, start_new_session=True)
        started.append(process)
        return process

    try:
        yield start
    finally:
        for process in started:
            code = stop_group(process)
            print(f"$ ros2 {' '.join(process.args[1:])}  # exit {code}\n{process.stdout.read()}")


def daemon_pids(domain_id: int) -> list[int]:
    """Pids of the `ros2 daemon` of this ROS domain: its command line is
    ``python -c 'from ros2cli.daemon.daemonize import main; main()' --name ros2-daemon
    --ros-domain-id N --rmw-implementation ...``."""
    found = []
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        with contextlib.suppress(OSError):
            args = cmdline.read_bytes().decode(errors="replace").split("\0")
            domain = [b for a, b in zip(args, args[1:]) if a == "--ros-domain-id"]
            if "ros2-daemon" in args and domain == [str(domain_id)]:
                found.append(int(cmdline.parent.name))
    return found


def end_pid(pid: int, grace: float = 5.0) -> None:
    """SIGINT, then SIGKILL after ``grace``, to a process that is not our child."""
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGINT)
        deadline = time.monotonic() + grace
        while Path(f"/proc/{pid}").exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        if Path(f"/proc/{pid}").exists():
            os.kill(pid, signal.SIGKILL)


@pytest.fixture
def daemon_guard(domain_id):
    """After the test: no `ros2 daemon` it started in its domain may be running; one that
    is is ended by its pid, and the test fails. A daemon that was there before (another
    program's, on the same domain id) is not the test's: left alone."""
    before = set(daemon_pids(domain_id))
    yield
    daemons = [pid for pid in daemon_pids(domain_id) if pid not in before]
    for pid in daemons:
        end_pid(pid)
    assert not daemons, f"a ros2 daemon was started in domain {domain_id}: pids {daemons}"


def wait_for(check, timeout: float, what: str):
    """Poll ``check()`` until it returns something truthy; that value. Fails after ``timeout``."""
    deadline = time.monotonic() + timeout
    while True:
        result = check()
        if result:
            return result
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.1)
