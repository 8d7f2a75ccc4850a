"""The parameter tables of the node pages (docs/nodes/*.md), written from the spec table.

    python -m estimation_nodes.tools.param_docs [--docs-dir docs/nodes] [--check]

Each page holds its tables between marker comments::

    <!-- parameters: estimator -->
    (the generated table)
    <!-- end parameters -->

and this rewrites what is between them from ``NODE_SPECS`` (params/specs.py): name,
type, default, range, read-only and description, as ``ros2 param describe`` shows
them. With ``--check`` nothing is written; the exit code is 1 when a page differs.
tests/unit/test_docs.py fails when a page and the code disagree.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from estimation_nodes.params.specs import NODE_SPECS, UNSET, ParamSpec

MARKERS = re.compile(r"(?P<start><!-- parameters: (?P<node>[a-z_]+) -->\n)(?P<table>.*?)"
                     r"(?P<end><!-- end parameters -->)", re.DOTALL)
COMMAND = "python -m estimation_nodes.tools.param_docs"

_ARRAY_TYPES = {"string_array": "string array", "double_array": "double array"}


def _number(value: float | int) -> str:
    """A number as a parameter file would hold it: ints as they are, doubles with a point."""
    if isinstance(value, int):
        return str(value)
    if value.is_integer() and abs(value) < 1e6:
        return f"{value:.1f}"
    return re.sub(r"e([+-])0*(\d)", lambda m: f"e{'-' if m[1] == '-' else ''}{m[2]}",
                  f"{value:.6g}")


def _scalar(value: Any) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, (int, float)):
        return _number(value)
    return str(value)


def type_name(spec: ParamSpec) -> str:
    """The parameter's ROS type, as ``ros2 param describe`` names it."""
    if spec.default is UNSET:
        return _ARRAY_TYPES[spec.type_name]
    value = spec.default
    if isinstance(value, list):
        element = {bool: "boolean", int: "integer", float: "double", str: "string"}[
            type(value[0])]
        return f"{element} array"
    return {bool: "boolean", int: "integer", float: "double", str: "string"}[type(value)]


def default_text(spec: ParamSpec) -> str:
    if spec.default is UNSET:
        return "unset"
    if isinstance(spec.default, list):
        return f"`[{', '.join(_scalar(v) for v in spec.default)}]`"
    if spec.default == "":
        return '`""`'
    return f"`{_scalar(spec.default)}`"


def range_text(spec: ParamSpec) -> str:
    if spec.min_value is None or spec.max_value is None:
        return ""
    kind = int if isinstance(spec.default, int) and not isinstance(spec.default, bool) else float
    return f"{_number(kind(spec.min_value))} .. {_number(kind(spec.max_value))}"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def parameter_table(node: str) -> str:
    """The Markdown table of ``node``'s parameters, in the order the node declares them."""
    rows = ["| parameter | type | default | range | read-only | description |",
            "|---|---|---|---|---|---|"]
    for spec in NODE_SPECS[node]:
        rows.append("| " + " | ".join(_cell(text) for text in (
            f"`{spec.name}`", type_name(spec), default_text(spec), range_text(spec),
            "yes" if spec.read_only else "", spec.description)) + " |")
    return "\n".join(rows) + "\n"


class PageError(ValueError):
    """A page whose markers name no node or are not closed."""


def render_page(text: str, page: str = "page") -> str:
    """``text`` with every marked table written anew from the spec table."""
    opened = text.count("<!-- parameters:")
    found = list(MARKERS.finditer(text))
    if len(found) != opened:
        raise PageError(f"{page}: a '<!-- parameters: NODE -->' marker without its "
                        f"'<!-- end parameters -->'")
    for match in found:
        if match["node"] not in NODE_SPECS:
            raise PageError(f"{page}: no node named {match['node']!r} in NODE_SPECS "
                            f"(known: {', '.join(NODE_SPECS)})")
    return MARKERS.sub(lambda m: m["start"] + "\n" + parameter_table(m["node"]) + "\n"
                       + m["end"], text)


def tabled_nodes(text: str) -> list[str]:
    """The nodes whose tables a page holds."""
    return [match["node"] for match in MARKERS.finditer(text)]


def stale_pages(docs_dir: Path) -> dict[Path, str]:
    """Each page whose tables differ from the spec table, with its text as it should be."""
    stale = {}
    for path in sorted(docs_dir.glob("*.md")):
        text = path.read_text(encoding="utf-8")
        expected = render_page(text, str(path))
        if expected != text:
            stale[path] = expected
    return stale


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="param_docs", description=__doc__.split("\n")[0])
    parser.add_argument("--docs-dir", type=Path, default=Path("docs") / "nodes",
                        help="the node pages (default: %(default)s, from the repository root)")
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 when a page differs from the spec table")
    args = parser.parse_args(argv)
    if not args.docs_dir.is_dir():
        print(f"param_docs: {args.docs_dir} is not a folder (run from the repository root or "
              f"give --docs-dir)", file=sys.stderr)
        sys.exit(2)
    try:
        stale = stale_pages(args.docs_dir)
    except PageError as error:
        print(f"param_docs: {error}", file=sys.stderr)
        sys.exit(2)
    for path, text in stale.items():
        if args.check:
            print(f"param_docs: {path} differs from the spec table (run {COMMAND})")
        else:
            path.write_text(text, encoding="utf-8")
            print(f"param_docs: rewrote the tables of {path}")
    if not stale:
        print(f"param_docs: every page in {args.docs_dir} agrees with the spec table")
    sys.exit(1 if stale and args.check else 0)


if __name__ == "__main__":
    main()
