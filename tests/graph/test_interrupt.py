"""Ctrl-C in every phase: SIGINT to the process group, as a terminal sends it.

For each kind of run, the demo gets one SIGINT at one of several moments, from
0.2 s after its start (still loading) to its linger; each node run alone (the
installed script, what ``ros2 run`` runs) gets one while loading, while it is
being made (it shows in the graph) and once it runs. Promised (README): the
demo exits 130, a node 0; no traceback; no process left of those it started.

Python's own start-up comes before any code of ours can take a SIGINT (it
prints "Fatal Python error"): the first moment is 0.2 s, or twice the start-up
of the same interpreter measured in this run when that is longer.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml

from tests.conftest import SCENARIOS, spin_until
from tests.graph.graph_tools import executable

#: The kinds of run, each shortened to a few steps: the Ctrl-C, not the run, is tested.
KINDS = {
    "example_6_14": {},
    "localization": {"/**/motion_commander": {"max_commands": 6}},
    "tracking_2d": {"/**/motion_commander": {"max_commands": 6}},
    "grid_corridor": {"/**/planar_robot": {"duration": 3.0}},
    # Long enough for the demo's monitor to match the robot's true_pose, which the robot
    # does not wait for, and print an update (the "running" moment).
    "landmarks": {"/**/landmark_robot": {"duration": 10.0}},
}
#: Nodes each run starts: the localization kinds the localizer and the robot, the others three.
NODE_COUNT = {"grid_corridor": 2, "landmarks": 2}
DEMO_MOMENTS = ("loading", "first_node_starting", "last_node_starting", "running", "linger")
#: What each node alone runs with, and the log line that says it runs.
NODES = {
    "estimator": ("localization.yaml", "ready:"),
    "tile_sensor": ("localization.yaml", "ready:"),
    "motion_commander": ("localization.yaml", "waiting for"),
    "linear_system": ("tracking_2d.yaml", "ready:"),
    "grid_localizer": ("grid_corridor.yaml", "ready:"),
    "planar_robot": ("grid_corridor.yaml", "ready:"),
    "ekf_localizer": ("landmarks.yaml", "ready:"),
    "landmark_robot": ("landmarks.yaml", "ready:"),
}
NODE_MOMENTS = ("loading", "in_the_graph", "running")


@pytest.fixture(scope="module")
def first_moment() -> float:
    """0.2 s, or twice what the interpreter takes now to reach the package's start-up code."""
    started = time.monotonic()
    subprocess.run([sys.executable, "-c", "import estimation_nodes.tools.start"], check=True,
                   timeout=60)
    return max(0.2, 2 * (time.monotonic() - started))


def takes_sigint(pid: int) -> bool:
    """Whether the process is the Python interpreter and catches or blocks SIGINT (/proc's
    exe; SigCgt, SigBlk): before the interpreter installs its handler, a SIGINT kills any
    Python program outright, which no code of ours can change; "loading" begins once it
    can be taken. (The installed scripts are shell wrappers that exec the interpreter,
    and dash catches SIGINT itself: a SIGINT between its exec and the interpreter's
    handler ended a play with no word and exit -2.)"""
    bit = 1 << (signal.SIGINT - 1)
    with contextlib.suppress(OSError):
        if not Path(os.readlink(f"/proc/{pid}/exe")).name.startswith("python"):
            return False
        fields = dict(line.split(":\t", 1) for line in
                      Path(f"/proc/{pid}/status").read_text().splitlines() if ":\t" in line)
        return bool((int(fields["SigCgt"], 16) | int(fields["SigBlk"], 16)) & bit)
    return False


def children_of(pid: int) -> list[int]:
    path = Path(f"/proc/{pid}/task/{pid}/children")
    with contextlib.suppress(OSError):
        return [int(p) for p in path.read_text().split()]
    return []


def running(pid: int) -> bool:
    """The process exists and is not a zombie waiting to be reaped."""
    with contextlib.suppress(OSError):
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    return False


def is_node(pid: int) -> bool:
    with contextlib.suppress(OSError):
        return b"estimation_nodes.nodes.start" in Path(f"/proc/{pid}/cmdline").read_bytes()
    return False


def started_by(pid: int) -> list[int]:
    """Processes that name ``pid`` as the parent they end with (the demo's nodes:
    nodes/process.PARENT_PID_ENV), whether or not this test saw them start."""
    marker = f"ESTIMATION_NODES_PARENT_PID={pid}".encode()
    found = []
    for environ in Path("/proc").glob("[0-9]*/environ"):
        with contextlib.suppress(OSError):
            if marker in environ.read_bytes().split(b"\0") and running(int(environ.parent.name)):
                found.append(int(environ.parent.name))
    return found


class Watched:
    """A command in a session (and process group) of its own; its output read as it comes,
    the children it starts noted as they appear."""

    def __init__(self, command: list[str], env: dict[str, str]) -> None:
        self.started = time.monotonic()
        self.process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE,
                                        stderr=subprocess.STDOUT, text=True,
                                        start_new_session=True)
        self.lines: list[str] = []
        self.children: list[int] = []      # in the order they appeared
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.process.stdout:
            self.lines.append(line)

    @property
    def output(self) -> str:
        return "".join(self.lines)

    def printed(self, text: str) -> bool:
        return any(text in line for line in self.lines)

    def note_children(self) -> None:
        """The node processes it started (not the helpers of its shell script: dirname)."""
        for child in children_of(self.process.pid):
            if child not in self.children and is_node(child):
                self.children.append(child)

    def wait_for(self, condition, what: str, timeout: float, spin=None) -> None:
        """Poll ``condition()`` (noting children, spinning ``spin()`` if given)."""
        deadline = time.monotonic() + timeout
        while not condition():
            self.note_children()
            if self.process.poll() is not None:
                pytest.fail(f"ended (exit {self.process.returncode}) before {what}:\n"
                            f"{self.finish()}")
            if time.monotonic() > deadline:
                pytest.fail(f"no {what} after {timeout:.0f} s:\n{self.output}")
            if spin is not None:
                spin()
            else:
                time.sleep(0.01)
        self.note_children()

    def interrupt(self) -> None:
        self.interrupted_at = time.monotonic() - self.started
        os.killpg(self.process.pid, signal.SIGINT)

    def finish(self, timeout: float = 60.0) -> str:
        """Wait for the end (SIGKILL to the group and to every child seen after
        ``timeout``); the whole output."""
        try:
            self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            for pid in self.children:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.process.pid, signal.SIGKILL)
            self.process.wait()
        self._reader.join(timeout=10)
        return self.output

    def left_behind(self) -> list[int]:
        """What is still running of the group, the children seen and those that name this
        process as theirs; each is ended by its pid."""
        left = set(pid for pid in self.children if running(pid))
        left |= set(started_by(self.process.pid))
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.process.pid, 0)
            left.add(-self.process.pid)    # the group still has a member
        for pid in left:
            with contextlib.suppress(ProcessLookupError):
                if pid < 0:
                    os.killpg(-pid, signal.SIGKILL)
                else:
                    os.kill(pid, signal.SIGKILL)
        return sorted(left)


def shortened(kind: str, tmp_path: Path) -> Path:
    document = yaml.safe_load((SCENARIOS / f"{kind}.yaml").read_text())
    for section, values in KINDS[kind].items():
        document[section]["ros__parameters"].update(values)
    path = tmp_path / f"{kind}.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


def wait_for_moment(watched: Watched, moment: str, first_moment: float, name: str,
                    ready: str, watcher, executor, limit: float = 60.0) -> None:
    """Wait (``limit`` s at most) for one of a program's moments: still ``loading``,
    ``in_the_graph`` (its node ``name`` seen by ``watcher``; from the start of its
    constructor on, parameters, map and kernels still being made), or ``running`` (it
    printed ``ready``)."""
    if moment == "loading":
        watched.wait_for(lambda: time.monotonic() - watched.started >= first_moment
                         and takes_sigint(watched.process.pid), "start", limit)
    elif moment == "in_the_graph":
        watched.wait_for(lambda: name in watcher.node.get_node_names(), "node in the graph",
                         limit, spin=lambda: spin_until(executor, lambda: False, 0.02))
    else:
        watched.wait_for(lambda: watched.printed(ready), f"{ready!r} line", limit)


def ended_quietly(watched: Watched, output: str, moment: str, code: int) -> str:
    """Assert that the program ended with ``code`` and printed no traceback; what to say
    of the run where a later assertion fails."""
    where = f"SIGINT {watched.interrupted_at:.2f} s after start ({moment}):\n{output}"
    assert "Traceback" not in output and "Fatal Python error" not in output, where
    assert watched.process.returncode == code, where
    return where


@pytest.mark.timeout(150)
@pytest.mark.parametrize("moment", DEMO_MOMENTS)
@pytest.mark.parametrize("kind", KINDS)
def test_ctrl_c_of_the_demo_exits_130_quietly_leaving_nothing(ros_env, tmp_path, first_moment,
                                                             kind, moment):
    nodes = NODE_COUNT.get(kind, 3)
    demo = Watched([executable("estimation_demo"), "--params-file", str(shortened(kind, tmp_path)),
                    "--settle", "0.5", "--linger", "3.0"], ros_env)
    try:
        # Each wait only gives a hang a limit; the signal goes at the condition.
        limit = 90.0
        if moment == "loading":
            demo.wait_for(lambda: time.monotonic() - demo.started >= first_moment
                          and takes_sigint(demo.process.pid), "start", limit)
        elif moment == "first_node_starting":
            demo.wait_for(lambda: len(demo.children) >= 1, "first node", limit)
        elif moment == "last_node_starting":
            demo.wait_for(lambda: len(demo.children) >= nodes, "last node", limit)
        elif moment == "running":
            demo.wait_for(lambda: demo.printed("update   1") or demo.printed("step   1"),
                          "first estimate", limit)
        else:   # the main node (started last) has ended: the graph lingers
            demo.wait_for(lambda: len(demo.children) >= nodes
                          and not running(demo.children[nodes - 1]), "end of the run", limit)
        demo.interrupt()
        output = demo.finish()
        left = demo.left_behind()
    finally:
        if demo.process.poll() is None:
            demo.finish(timeout=0)
    where = ended_quietly(demo, output, moment, 130)
    assert not left, f"left running: {left}; {where}"


@pytest.mark.timeout(90)
@pytest.mark.parametrize("moment", NODE_MOMENTS)
@pytest.mark.parametrize("name", NODES)
def test_ctrl_c_of_a_node_alone_exits_0_quietly(ros_env, executor, collector_factory,
                                                first_moment, name, moment):
    params, ready = NODES[name]
    watcher = collector_factory({}, name="watcher") if moment == "in_the_graph" else None
    node = Watched([executable(name), "--ros-args", "--params-file", str(SCENARIOS / params)],
                   ros_env)
    try:
        wait_for_moment(node, moment, first_moment, name, ready, watcher, executor)
        node.interrupt()
        output = node.finish()
        left = node.left_behind()
    finally:
        if node.process.poll() is None:
            node.finish(timeout=0)
    where = ended_quietly(node, output, moment, 0)
    assert not left, f"left running: {left}; {where}"


PLAY_MOMENTS = ("loading", "in_the_graph", "playing")


@pytest.fixture
def slow_recording(tmp_path) -> Path:
    """A recording of a few seconds, to be played at a tenth of its rate: it is still
    playing when the signal comes."""
    from estimation_nodes.tools.importers import cli
    from tests.unit.test_importers import corrected_log

    log = tmp_path / "run.log"
    log.write_text(corrected_log())
    out = tmp_path / "run.mcap"
    cli.main(["carmen", str(log), "-o", str(out)])
    return out


@pytest.mark.timeout(90)
@pytest.mark.parametrize("moment", PLAY_MOMENTS)
def test_ctrl_c_of_a_play_exits_130_quietly(ros_env, executor, collector_factory,
                                            first_moment, slow_recording, moment):
    watcher = collector_factory({}, name="watcher") if moment == "in_the_graph" else None
    play = Watched([executable("estimation_play"), str(slow_recording), "--rate", "0.1"],
                   ros_env)
    try:
        wait_for_moment(play, moment.replace("playing", "running"), first_moment,
                        "estimation_play", "messages on", watcher, executor)
        play.interrupt()
        output = play.finish()
    finally:
        if play.process.poll() is None:
            play.finish(timeout=0)
    ended_quietly(play, output, moment, 130)
