"""Where the demo and the live view start: a Ctrl-C ends them quietly from their first line on
(nodes/start.py says why).

The demo's Ctrl-C code is 130, the shell's for an end by SIGINT; foxglove_view ends with 0,
as the nodes do.
"""

from __future__ import annotations

from estimation_nodes.nodes.start import run_main


def estimation_demo() -> None:
    run_main("estimation_nodes.tools.demo.cli", 130)


def foxglove_view() -> None:
    run_main("estimation_nodes.tools.live_view.foxglove_view", 0)
