"""Where the demo, the play and the live view start: a Ctrl-C ends them quietly from their
first line on (nodes/start.py says why).

The Ctrl-C code of the demo and the play is 130, the shell's for an end by SIGINT;
foxglove_view ends with 0, as the nodes do.
"""

from __future__ import annotations

from estimation_nodes.nodes.start import run_main


def estimation_demo() -> None:
    run_main("estimation_nodes.tools.demo.cli", 130)


def estimation_play() -> None:
    run_main("estimation_nodes.tools.recording.play", 130)


def foxglove_view() -> None:
    run_main("estimation_nodes.tools.live_view.foxglove_view", 0)
