"""estimation_demo: start the three nodes, show the run as it happens, summarize it.

The nodes run as separate processes (as a launch file would start them), or in
this one process with ``--in-process``. A monitor node here prints each
estimate as it arrives; when the motion commander has sent its last command
the graph stays up ``--linger`` seconds for late subscribers, then every
process this script started is ended by its own pid.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from estimation_nodes.params import topics
from estimation_nodes.params.param_files import check_params_file
from estimation_nodes.params.scenarios import scenario_kind
from estimation_nodes.tools.demo.graph_runtime import (
    INTERRUPTED,
    HeldInterrupts,
    NodeStart,
    run_graph,
    spin_until,
)
from estimation_nodes.tools.demo.overrides import node_overrides
from estimation_nodes.tools.installed import share_dirs
from estimation_nodes.tools.live_view.server import LiveViewError, parse_address
from estimation_nodes.tools.recording.completeness import SequenceGaps
from estimation_nodes.tools.recording.mcap import RecordingError
from estimation_nodes.tools.recording.run_record import RunRecord, summarize

#: A run where localization visibly succeeds; the book's own world and examples are
#: other scenarios, named in the summary.
DEFAULT_SCENARIO = "localization"
#: Subscribers the commander waits for: the sensor, the estimator and this script's monitor.
REQUIRED_SUBSCRIBERS = 3


class DemoError(Exception):
    """A problem with the user's input: printed as one line, exit code 2."""


def scenario_dirs() -> list[Path]:
    """Where installed and source-tree scenario files live, most specific first."""
    dirs = [share / "estimation_nodes" / "msgs_config" for share in share_dirs()]
    dirs.append(Path(__file__).resolve().parents[3] / "msgs_config")
    return [d for d in dirs if d.is_dir()]


def find_scenario(name: str) -> Path:
    # A scenario is a name, not a path: --params-file is for files of your own.
    if not re.fullmatch(r"[A-Za-z0-9_-]+", name):
        raise DemoError(f"--scenario: {name!r} is not a scenario name (letters, digits, _ "
                        f"and -); give a file with --params-file")
    for directory in scenario_dirs():
        candidate = directory / f"{name}.yaml"
        if candidate.is_file():
            return candidate
    raise DemoError(f"--scenario: no scenario named {name!r}; known scenarios: "
                    f"{known_scenarios()}")


#: The simulated world each kind of tile or Kalman run drives.
SIMULATORS = {"tiles": "tile_sensor", "linear_system": "linear_system"}


def kind_of(params: Path) -> str:
    """The kind of run the parameter file says it is (params/scenarios.py)."""
    try:
        return scenario_kind(params.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise DemoError(f"{params}: {error}") from None


def simulator_for(params: Path) -> str:
    """The simulator of a tile or linear-system run."""
    return SIMULATORS[kind_of(params)]


def known_scenarios() -> list[str]:
    return sorted({p.stem for d in scenario_dirs() for p in d.glob("*.yaml")})


def other_scenarios(ran: Path) -> str:
    """The line that tells a newcomer where the book's examples are."""
    others = [name for name in known_scenarios() if name != ran.stem]
    return (f"  other scenarios: {', '.join(others)} (estimation_demo --scenario NAME; "
            f"book_world and example_* are the textbook's world and worked examples)")


def checked_params_file(path: Path) -> Path:
    try:
        return check_params_file(path)
    except ValueError as error:
        raise DemoError(f"--params-file: {error}") from None


def ros_environment() -> dict[str, str]:
    """This process's environment with DDS confined to localhost unless the user chose."""
    env = dict(os.environ)
    if "ROS_AUTOMATIC_DISCOVERY_RANGE" not in env and "ROS_LOCALHOST_ONLY" not in env:
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        print("estimation_demo: ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (DDS stays on this "
              "machine; set the variable yourself to change it)")
    env.setdefault("ROS_DOMAIN_ID", "0")
    print(f"estimation_demo: ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']} "
          f"(use the same to watch with ros2 topic echo)")
    return env


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="estimation_demo", description=__doc__.split("\n")[0])
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--scenario", default=DEFAULT_SCENARIO,
                        help="scenario name from msgs_config (default: %(default)s)")
    source.add_argument("--params-file", type=Path, help="a ROS parameter file of your own")
    parser.add_argument("--settle", type=float, default=2.0,
                        help="seconds for the graph to discover itself before the first "
                             "command (default: %(default)s)")
    parser.add_argument("--linger", type=float, default=2.0,
                        help="seconds the graph stays up after the last command "
                             "(default: %(default)s)")
    parser.add_argument("--timeout", type=float, default=600.0,
                        help="give up after this many seconds (default: %(default)s)")
    parser.add_argument("--in-process", action="store_true",
                        help="run the three nodes in this process instead of three")
    parser.add_argument("--quiet", action="store_true", help="print only the summary")
    parser.add_argument("--record", type=Path, metavar="FILE.mcap",
                        help="write every topic of the run to a ROS 2 MCAP file")
    parser.add_argument("--plot", type=Path, metavar="FILE.png",
                        help="render the run as a PNG when it is over")
    parser.add_argument("--foxglove", metavar="[HOST:]PORT",
                        help="serve every topic live to Foxglove on a WebSocket (host "
                             "127.0.0.1 unless given; port 0 takes a free one)")
    args = parser.parse_args(argv)
    if args.settle < 0 or args.linger < 0 or args.timeout <= 0:
        parser.error("--settle and --linger must be >= 0, --timeout > 0")
    return args


def commander_overrides(settle: float, exit_when_done: bool) -> list[str]:
    return ["-p", f"exit_when_done:={str(exit_when_done).lower()}",
            "-p", f"start_delay:={settle}",
            "-p", f"required_subscribers:={REQUIRED_SUBSCRIBERS}"]


def main(argv: Sequence[str] | None = None) -> None:
    """The demo; a Ctrl-C in any phase ends it with exit code 130 and no traceback."""
    try:
        code = run_demo(argv)
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)   # the end has begun
        code = INTERRUPTED
    sys.exit(code)


def run_demo(argv: Sequence[str] | None) -> int:
    args = parse_args(argv)
    try:
        params = checked_params_file(args.params_file or find_scenario(args.scenario))
        args.foxglove = foxglove_address(args.foxglove)   # (host, port) from here on
    except DemoError as error:
        print(f"estimation_demo: {error}", file=sys.stderr)
        return 2
    env = ros_environment()
    os.environ.update(env)
    print(f"estimation_demo: parameters from {params}")
    try:
        kind = kind_of(params)
    except DemoError as error:
        print(f"estimation_demo: {error}", file=sys.stderr)
        return 2
    if kind in ("grid", "landmarks"):
        return run_grid_scenario(params, args, kind)
    if kind == "fusion":
        from estimation_nodes.tools.demo import fusion_run

        return fusion_run.run(params, args)
    runner = run_in_process if args.in_process else run_processes
    try:
        code, record, gaps = runner(params, args)
    except RecordingError as error:
        print(f"estimation_demo: {error}", file=sys.stderr)
        return 2
    except LiveViewError as error:
        print(f"estimation_demo: --foxglove: {error}", file=sys.stderr)
        return 2
    print(summarize(record))
    print(other_scenarios(params))
    if args.record:
        code = report_recording(args.record, gaps, code)
    if args.plot:
        from estimation_nodes.tools.plot.estimator import render

        print(f"estimation_demo: plot written to {render(record, args.plot)}")
    return code


def foxglove_address(text: str | None) -> tuple[str, int] | None:
    if text is None:
        return None
    try:
        return parse_address(text)
    except LiveViewError as error:
        raise DemoError(f"--foxglove: {error}") from None


def resolved(topic_types: dict[str, str]) -> dict[str, str]:
    """Topics as the nodes resolve them: this script runs them in the root namespace."""
    return {topic if topic.startswith("/") else f"/{topic}": name
            for topic, name in topic_types.items()}


def run_grid_scenario(params: Path, args: argparse.Namespace, kind: str) -> int:
    """A grid or landmark localization run (tools/demo/grid_run.py); its exit code."""
    from estimation_nodes.tools.demo import grid_run as grid_demo

    if args.in_process:
        print(f"estimation_demo: --in-process is not available for {kind} runs",
              file=sys.stderr)
        return 2
    if args.plot and not args.record:
        # The picture is drawn from a recording of the run.
        args.record = args.plot.with_suffix(".mcap")
    grid_topics = resolved(topics.GRID_TOPIC_TYPES if kind == "grid"
                           else topics.LANDMARK_TOPIC_TYPES)
    try:
        sinks = make_sinks(params, args, grid_topics,
                           {**grid_topics, topics.DIAGNOSTICS: topics.LIVE_TOPIC_TYPES[
                               topics.DIAGNOSTICS]})
    except (RecordingError, LiveViewError) as error:
        print(f"estimation_demo: {error}", file=sys.stderr)
        return 2
    try:
        code, record = grid_demo.run(params, args, sinks, kind)
    finally:
        close_sinks(sinks)
    print(record.summary())
    print(other_scenarios(params))
    if args.record:
        code = report_recording(args.record, recording_gaps(sinks), code)
    if args.plot and code == 0:
        try:
            print(f"estimation_demo: plot written to {render_run(args, kind)}")
        except ValueError as error:
            print(f"estimation_demo: no plot: {error}", file=sys.stderr)
            return 1
    return code


def render_run(args: argparse.Namespace, kind: str) -> Path:
    """The picture of a recorded grid or landmarks run (tools/plot/)."""
    if kind == "landmarks":
        from estimation_nodes.tools.plot.landmarks import render_landmarks

        return render_landmarks(args.record, args.plot)
    from estimation_nodes.tools.plot.grid_localizer import render_grid

    return render_grid(args.record, args.plot)


def make_sinks(params: Path, args: argparse.Namespace, recorded: dict[str, str] | None = None,
               served: dict[str, str] | None = None) -> list:
    """Where the monitor writes raw messages: the Foxglove live view (--foxglove), the MCAP
    file (--record); by default with the tile and Kalman topics. The live view starts
    first: a port in use fails before a file is made."""
    sinks: list = []
    try:
        if args.foxglove:
            from estimation_nodes.tools.live_view.server import LiveView

            view = LiveView(*args.foxglove, served or resolved(topics.LIVE_TOPIC_TYPES))
            sinks.append(view)
            print(f"estimation_demo: Foxglove live view on {view.url} (in Foxglove: Open "
                  f"connection, Foxglove WebSocket)", flush=True)
        if args.record:
            from estimation_nodes.tools.recording.mcap import McapRunWriter

            text = params.read_text(encoding="utf-8")
            metadata = {"parameters_yaml": text, "parameters_file": str(params),
                        "kind": scenario_kind(text)}
            sinks.append(McapRunWriter(args.record, recorded or resolved(topics.TOPIC_TYPES),
                                       metadata))
    except Exception:
        close_sinks(sinks)
        raise
    return sinks


def close_sinks(sinks: list) -> None:
    for sink in sinks:
        sink.close()


def recording_gaps(sinks: list) -> SequenceGaps | None:
    """What the recording among ``sinks`` holds of what was published (None: no recording)."""
    from estimation_nodes.tools.recording.mcap import McapRunWriter

    return next((sink.gaps for sink in sinks if isinstance(sink, McapRunWriter)), None)


def report_recording(path: Path, gaps: SequenceGaps | None, code: int) -> int:
    """Say at the end of the run whether the recording holds every message published (from
    each publisher's first to the last recorded), not only at replay time; the exit code:
    1 for a recording that misses some, else ``code``."""
    missing = gaps.describe() if gaps is not None else []
    if not missing:
        recorded = f"{gaps.recorded} messages, " if gaps is not None else ""
        print(f"estimation_demo: recorded to {path} ({recorded}none missing)")
        return code
    print(f"estimation_demo: recorded to {path}, but it misses messages that were published:",
          file=sys.stderr)
    for line in missing:
        print(f"  {line}", file=sys.stderr)
    print("  estimation_replay cannot compare what was computed from them", file=sys.stderr)
    return code or 1


def make_monitor(args: argparse.Namespace, sinks: list):
    """The monitor node, feeding ``sinks``."""
    from estimation_nodes.tools.demo.monitor import RunMonitor

    # /diagnostics only when a live view shows it: the monitor has no other use for it.
    extra = {topics.DIAGNOSTICS: topics.LIVE_TOPIC_TYPES[topics.DIAGNOSTICS]} \
        if args.foxglove else {}
    # Every node of the run is started after this: what was published before is not its.
    return RunMonitor(quiet=args.quiet, sinks=sinks, sink_only_topics=extra,
                      run_started_ns=time.time_ns())


# --- running the graph -----------------------------------------------------------------------


def demo_overrides(params: Path) -> dict[str, tuple[str, ...]]:
    """What the demo adds to each node's parameters (overrides.py): its monitor among the
    nodes the simulator and the commander wait for, the estimator's depth raised."""
    text = params.read_text(encoding="utf-8")
    return node_overrides(text, scenario_kind(text), monitor_hears_inputs=True)


def run_processes(params: Path, args: argparse.Namespace
                  ) -> tuple[int, RunRecord, SequenceGaps | None]:
    """The estimator, the simulator, then the commander, each a process of its own."""
    simulator = simulator_for(params)
    heard = topics.ESTIMATOR_OUTPUTS + topics.SIMULATOR_OUTPUTS[simulator]
    overrides = demo_overrides(params)
    sinks = make_sinks(params, args)
    try:
        code, monitor = run_graph(params, lambda: make_monitor(args, sinks), [
            NodeStart("estimator", overrides.get("estimator", ())),
            NodeStart(simulator, overrides.get(simulator, ())),
            # Last, so it finds the others soonest; once the monitor hears the simulator's
            # and the estimator's first messages.
            NodeStart("motion_commander", (*commander_overrides(args.settle, True),
                                           *overrides.get("motion_commander", ())),
                      ready=lambda monitor: monitor.publishers_matched(heard)),
        ], "motion_commander", args.timeout, args.linger)
    finally:
        close_sinks(sinks)
    return (code, monitor.record if monitor is not None else RunRecord(),
            recording_gaps(sinks))


def run_in_process(params: Path, args: argparse.Namespace
                   ) -> tuple[int, RunRecord, SequenceGaps | None]:
    # One process: each parameter reaches the one node here that declares it.
    ros_args = ["--ros-args", "--params-file", str(params),
                *commander_overrides(args.settle, exit_when_done=False),
                *(arg for node_args in demo_overrides(params).values() for arg in node_args)]
    executor = None
    nodes = []
    sinks: list = []
    code = 0
    # A Ctrl-C is noted and acted on between spins, as run_graph (graph_runtime.py) does;
    # rclpy and the nodes are imported under the hold for the reason given there.
    held = HeldInterrupts()
    with held:
        import rclpy
        from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        from estimation_nodes.nodes.estimator import Estimator
        from estimation_nodes.nodes.linear_system import LinearSystem
        from estimation_nodes.nodes.motion_commander import MotionCommander
        from estimation_nodes.nodes.parameters import ConfigurationError
        from estimation_nodes.nodes.tile_sensor import TileSensor

        try:
            if held.noted:
                raise KeyboardInterrupt
            # Without rclpy's signal handler, as run_graph says why.
            rclpy.init(args=["estimation_demo", *ros_args],
                       signal_handler_options=SignalHandlerOptions.NO)
            executor = SingleThreadedExecutor()
            sinks = make_sinks(params, args)
            nodes.append(make_monitor(args, sinks))
            simulator = LinearSystem if simulator_for(params) == "linear_system" \
                else TileSensor
            for node_class in (Estimator, simulator, MotionCommander):
                nodes.append(node_class())
            for node in nodes:
                executor.add_node(node)
            commander = nodes[-1]
            limit = commander.command_limit
            done = spin_until(executor, lambda: held.noted or (
                limit is not None and commander.sent >= limit), args.timeout)
            if held.noted:
                raise KeyboardInterrupt
            if not done:
                print("estimation_demo: stopped early: timeout", file=sys.stderr)
                code = 1
            spin_until(executor, lambda: held.noted, args.linger)
        except ConfigurationError as error:
            print(f"estimation_demo: invalid parameter {error}", file=sys.stderr)
            code = 2
        except (KeyboardInterrupt, ExternalShutdownException):
            code = INTERRUPTED
        finally:
            for node in nodes:
                node.destroy_node()
            close_sinks(sinks)
            if executor is not None:
                executor.shutdown(timeout_sec=1.0)
            rclpy.try_shutdown()
    if held.noted or code == INTERRUPTED:
        code = INTERRUPTED
        signal.signal(signal.SIGINT, signal.SIG_IGN)   # the summary is printed whole
    return code, nodes[0].record if nodes else RunRecord(), recording_gaps(sinks)


if __name__ == "__main__":
    main()
