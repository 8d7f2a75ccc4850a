"""The documentation agrees with the code: the node pages' parameter tables."""

from __future__ import annotations

from pathlib import Path

import pytest

from estimation_nodes.params.specs import NODE_SPECS
from estimation_nodes.tools import param_docs

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"
NODE_PAGES = DOCS / "nodes"


@pytest.mark.parametrize("page", sorted(NODE_PAGES.glob("*.md")), ids=lambda p: p.name)
def test_each_node_page_agrees_with_the_spec_table(page):
    text = page.read_text(encoding="utf-8")
    expected = param_docs.render_page(text, str(page.relative_to(REPO)))
    assert text == expected, (
        f"{page.relative_to(REPO)} and estimation_nodes/params/specs.py disagree: run "
        f"`{param_docs.COMMAND}` from the repository root and commit the page")


@pytest.mark.parametrize("node", sorted(NODE_SPECS))
def test_every_node_has_a_page_with_its_parameter_table(node):
    page = NODE_PAGES / f"{node}.md"
    assert page.is_file(), f"{node} has no page: write docs/nodes/{node}.md"
    assert node in param_docs.tabled_nodes(page.read_text(encoding="utf-8")), (
        f"docs/nodes/{node}.md has no '<!-- parameters: {node} -->' ... "
        f"'<!-- end parameters -->' table")


def test_a_table_that_differs_from_the_spec_table_is_found():
    page = param_docs.render_page((NODE_PAGES / "estimator.md").read_text(encoding="utf-8"))
    stale = page.replace("<!-- end parameters -->",
                         "| `gone` | double | `1.0` |  |  | A parameter no longer declared. |\n"
                         "<!-- end parameters -->")
    assert stale != page
    assert param_docs.render_page(stale) == page


def test_a_marker_for_an_unknown_node_or_without_its_end_is_refused():
    with pytest.raises(param_docs.PageError, match="no node named 'estimater'"):
        param_docs.render_page("<!-- parameters: estimater -->\n<!-- end parameters -->\n")
    with pytest.raises(param_docs.PageError, match="without its"):
        param_docs.render_page("<!-- parameters: estimator -->\n| stale |\n")
