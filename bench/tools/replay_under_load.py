"""Recorded runs replayed with a core kept busy: issue 35's acceptance, as a new user runs it.

    .venv/bin/python bench/tools/replay_under_load.py [--runs 10] [--load 1] [SCENARIO ...]
    make replay-under-load REPLAY_ARGS="--runs 2"

For each scenario (by default every recorded kind of run: grid_corridor,
grid_localization, localization, tracking_2d, landmarks), ``--runs`` fresh runs in a
row of ``estimation_demo --scenario S --record F`` then ``estimation_replay F``, with
``--load`` busy loops beside them that this script starts and ends by their pids. Prints
a line per run and then, per scenario, how many replayed EQUAL, how many recordings the
demo itself found incomplete, and how many demos failed. A measurement, not a test: it
asserts nothing, and its exit code is 0 whatever it counted (130 after a Ctrl-C, with the
counts so far).
"""

from __future__ import annotations

import argparse
import re
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench
from bench.common import confine_ros, executable, table  # noqa: E402

SCENARIOS = ("grid_corridor", "grid_localization", "localization", "tracking_2d", "landmarks")
#: A run takes up to a minute and a half of robot time plus start-up; a hung one ends here.
DEMO_TIMEOUT_S = 900
REPLAY_TIMEOUT_S = 600
VERDICT = re.compile(r"^online vs offline to \S+: (EQUAL|DIFFERENT.*)$", re.M)


def start_load(count: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(count)]


def stop_load(load: list[subprocess.Popen]) -> None:
    for process in load:
        process.kill()
    for process in load:
        process.wait()


def one_run(scenario: str, folder: Path, index: int) -> dict[str, str]:
    """Record one demo run of ``scenario`` and replay it; what each said."""
    recording = folder / f"{scenario}_{index}.mcap"
    started = time.monotonic()
    try:
        demo = subprocess.run([executable("estimation_demo"), "--scenario", scenario, "--quiet",
                               "--record", str(recording)], capture_output=True, text=True,
                              timeout=DEMO_TIMEOUT_S)
        demo_code, demo_err = demo.returncode, demo.stderr
    except subprocess.TimeoutExpired:
        demo_code, demo_err = "timeout", ""
    result = {"demo": str(demo_code),
              "recording": "incomplete" if "misses messages" in demo_err else "complete"}
    # What the demo said the recording misses, then the replay's first differences: why.
    notes = [line.strip() for line in demo_err.splitlines() if line.startswith("  /")]
    if recording.is_file():
        replay = subprocess.run([executable("estimation_replay"), str(recording)],
                                capture_output=True, text=True, timeout=REPLAY_TIMEOUT_S)
        found = VERDICT.search(replay.stdout)
        result["replay"] = found.group(1) if found else f"exit {replay.returncode}"
        notes += [line for line in replay.stdout.splitlines()
                  if ": " in line and not line.startswith((" ", "pose:", "online vs"))
                  and " compared" not in line]
        recording.unlink()
    else:
        result["replay"] = "no recording"
        notes += demo_err.strip().splitlines()[-1:]
    return {**result, "seconds": f"{time.monotonic() - started:.0f}",
            "detail": "; ".join(notes[:2])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scenarios", nargs="*", default=list(SCENARIOS), metavar="SCENARIO")
    parser.add_argument("--runs", type=int, default=10, help="runs per scenario (10)")
    parser.add_argument("--load", type=int, default=1,
                        help="busy loops beside the runs (1: one core kept busy)")
    args = parser.parse_args()
    env = confine_ros(91)
    print(f"replay_under_load: ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}, {args.runs} runs of "
          f"each of {', '.join(args.scenarios)}, {args.load} busy loops", flush=True)
    counts: dict[str, Counter] = {scenario: Counter() for scenario in args.scenarios}
    # A kill (SIGTERM) ends the runs as a Ctrl-C does: the busy loops and the run under
    # way with them, not left running.
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    load = start_load(args.load)
    print(f"replay_under_load: busy loops pids {[p.pid for p in load]}", flush=True)
    interrupted = False
    try:
        with tempfile.TemporaryDirectory(prefix="replay_under_load_") as folder:
            for scenario in args.scenarios:
                for index in range(1, args.runs + 1):
                    run = one_run(scenario, Path(folder), index)
                    tally = counts[scenario]
                    tally["runs"] += 1
                    tally["EQUAL"] += run["replay"] == "EQUAL"
                    tally["incomplete"] += run["recording"] == "incomplete"
                    tally["demo failed"] += run["demo"] != "0"
                    print(f"{scenario} {index}/{args.runs}: demo exit {run['demo']}, recording "
                          f"{run['recording']}, replay {run['replay']} ({run['seconds']} s)"
                          + (f"  [{run['detail']}]" if run["replay"] != "EQUAL" else ""),
                          flush=True)
    except KeyboardInterrupt:
        # The run under way is ended with its demo (subprocess.run kills it; its nodes end
        # with it); what was counted so far is still printed.
        interrupted = True
    finally:
        stop_load(load)
    print("\nreplay_under_load: interrupted; the runs so far:" if interrupted else "")
    print(table(["scenario", "replayed EQUAL", "recording incomplete", "demo failed"],
                [[scenario, f"{c['EQUAL']} of {c['runs']}", str(c["incomplete"]),
                  str(c["demo failed"])] for scenario, c in counts.items() if c["runs"]]))
    if interrupted:
        sys.exit(130)


if __name__ == "__main__":
    main()
