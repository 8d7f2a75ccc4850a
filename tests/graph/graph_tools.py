"""Helpers for the graph tests: find executables as ros2 run does, start and watch the graph."""

from pathlib import Path

import numpy as np

from tests.conftest import spin_until

NODES = ("estimator", "tile_sensor", "motion_commander")
#: Seconds the commander waits after its subscribers match. Right after discovery
#: a command can reach the estimator after the reading it caused (the commander
#: sees the estimator's subscription before the estimator has matched the
#: commander's publisher); the estimator then puts it back in its place and
#: republishes (core/causal_order.py), and the tests compare what settled
#: (``settled``). The settle time keeps such provisional estimates rare.
SETTLE = "3.0"


def executable(name: str) -> str:
    """What `ros2 run estimation_nodes <name>` runs: <prefix>/lib/estimation_nodes/<name>."""
    from ament_index_python.packages import get_package_prefix

    return str(Path(get_package_prefix("estimation_nodes")) / "lib" / "estimation_nodes" / name)


def node_command(name: str, scenario: Path, *args: str) -> list[str]:
    return [executable(name), "--ros-args", "--params-file", str(scenario), *args]


def start_graph(processes, scenario: Path, *commander_args: str, skip=(), listeners=None,
                estimator_args=()):
    """Start the three nodes (minus ``skip``); the commander exits after its last command.

    ``listeners`` is ``(executor, collector)``: the commander, which sets the run
    going, then starts only once each of the collector's subscriptions has matched
    a publisher. Samples of a volatile topic (tile_observation) published before
    the match never reach a reader; under CPU load the collector was seen to match
    the sensor seconds into a run and miss most of its readings.
    """
    started = {}
    for name in NODES:
        if name in skip or name == "motion_commander":
            continue
        extra = estimator_args if name == "estimator" else ()
        started[name] = processes(node_command(name, scenario, *extra))
    if listeners is not None:
        executor, collector = listeners
        assert spin_until(executor, collector.all_matched, 30.0), \
            f"the collector's subscriptions did not match: {collector.unmatched()}"
    if "motion_commander" not in skip:
        started["motion_commander"] = processes(node_command(
            "motion_commander", scenario, "-p", f"start_delay:={SETTLE}",
            "-p", "exit_when_done:=true", *commander_args))
    return started


def wait_for_commander(executor, started, timeout=60.0):
    commander = started["motion_commander"]
    assert spin_until(executor, lambda: commander.poll() is not None, timeout), \
        "the commander did not finish"
    assert commander.returncode == 0, commander.stdout.read()


def beliefs(messages):
    return [np.frombuffer(m.data, dtype=np.float64) for m in messages]


def resident_kib(pid: int) -> int:
    """Resident memory of a process in KiB (VmRSS)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise RuntimeError(f"no VmRSS for {pid}")


def settled(published, offline, atol: float):
    """The published beliefs that settled each offline one, asserting that every offline
    belief was published in order and that nothing published after the last of them is a
    belief the filter does not give (a provisional estimate, before a late event, is
    followed by those that replace it: estimation_nodes.tools.replay.estimator.align)."""
    from estimation_nodes.tools.replay.estimator import align

    alignment = align(published, offline, atol)
    assert alignment.matched == len(offline), (
        f"{alignment.matched} of {len(offline)} estimates settled as expected; published "
        f"{len(published)}")
    late = [i for i in alignment.superseded if i > alignment.last_match]
    assert not late, f"published after the last settled estimate: {late}"
    return [published[i] for i in alignment.settled]


def wait_quiet(executor, collector, quiet: float = 1.0, timeout: float = 20.0) -> None:
    """Spin until the collector has received nothing new for ``quiet`` seconds."""
    import time

    deadline = time.monotonic() + timeout
    total = sum(len(m) for m in collector.messages.values())
    since = time.monotonic()
    while time.monotonic() < deadline and time.monotonic() - since < quiet:
        executor.spin_once(timeout_sec=0.05)
        now_total = sum(len(m) for m in collector.messages.values())
        if now_total != total:
            total, since = now_total, time.monotonic()


def scaled(startup_s: float, factor: float = 10.0, floor: float = 30.0) -> float:
    """A deadline for a wait that follows a start-up of ``startup_s`` measured in the same
    run: ``factor`` times it, at least ``floor``. It only turns a hang into a failure that
    says what happened; the test waits for a condition, never for the time."""
    return max(floor, factor * startup_s)


def wait_for_line(process, text: str, timeout: float) -> str | None:
    """Read ``process``'s output until a line holding ``text``; that line, or None when the
    process ended or ``timeout`` s passed first (what was read is printed)."""
    import selectors
    import time

    deadline = time.monotonic() + timeout
    read = []
    with selectors.DefaultSelector() as selector:
        selector.register(process.stdout, selectors.EVENT_READ)
        while time.monotonic() < deadline:
            if not selector.select(timeout=max(0.0, deadline - time.monotonic())):
                break
            line = process.stdout.readline()
            if not line:
                break
            if text in line:
                return line
            read.append(line)
    print(f"no {text!r} from {process.args[:3]} in {timeout:.0f} s; it printed:\n"
          + "".join(read))
    return None


def wait_seconds(executor, seconds: float) -> None:
    """Keep spinning (so subscriptions are served) for a while."""
    spin_until(executor, lambda: False, seconds)
