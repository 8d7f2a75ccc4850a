"""Record every topic of a run to MCAP until SIGINT: an observer the tests start as a process.

    python -m tests.graph.record_run OUT.mcap PARAMS.yaml

It is the demo's monitor and recorder without the demo, so it can run on
another (simulated) host than the estimator, as a recorder beside a sensor
would. The parameter file goes into the recording for estimation_replay.
Prints "recording" once its subscriptions exist.
"""

from __future__ import annotations

import sys
from pathlib import Path

import rclpy
from rclpy.executors import ExternalShutdownException

from estimation_nodes.params import topics
from estimation_nodes.tools.demo.monitor import RunMonitor
from estimation_nodes.tools.recording.mcap import McapRunWriter


def main() -> None:
    out, params = Path(sys.argv[1]), Path(sys.argv[2])
    rclpy.init()
    writer = McapRunWriter(out, {f"/{t}": n for t, n in topics.TOPIC_TYPES.items()},
                           {"parameters_yaml": params.read_text(encoding="utf-8"),
                            "parameters_file": str(params)})
    monitor = RunMonitor(quiet=True, sinks=[writer])
    print("recording", flush=True)
    try:
        rclpy.spin(monitor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        monitor.destroy_node()
        writer.close()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
