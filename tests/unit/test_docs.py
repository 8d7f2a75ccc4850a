"""The documentation agrees with the code: parameter tables, links, the README's size, its
library snippet, and a comment on every value of the scenario files."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest

from estimation_nodes.params.specs import NODE_SPECS
from estimation_nodes.tools import param_docs

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"
NODE_PAGES = DOCS / "nodes"
README = REPO / "README.md"
#: A Markdown link's target: [text](target); images too.
LINK = re.compile(r"\]\(([^)\s]+)\)")
CODE_BLOCK = re.compile(r"```python\n(.*?)```", re.DOTALL)
SCENARIOS = REPO / "msgs_config"
#: A line of a parameter file that gives a value: ``name: value``.
VALUE_LINE = re.compile(r"^\s*(?P<name>[\w.]+):\s*[^\s#]")


def markdown_files() -> list[Path]:
    return [README, REPO / "CHANGELOG.md", *sorted(DOCS.rglob("*.md"))]


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


def test_the_readme_is_a_short_guide():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 250, (f"README.md has {len(lines)} lines: at most 250; move the "
                               f"detail to a page in docs/")


@pytest.mark.parametrize("document", markdown_files(), ids=lambda p: str(p.relative_to(REPO)))
def test_every_relative_link_leads_to_a_file(document):
    missing = []
    for target in LINK.findall(document.read_text(encoding="utf-8")):
        path = target.split("#", 1)[0]
        if not path or re.match(r"[a-z]+:", path):
            continue
        if not (document.parent / path).exists():
            missing.append(target)
    assert not missing, f"{document.relative_to(REPO)} links to files that do not exist: {missing}"


def test_the_readme_links_every_page_of_docs():
    linked = {(REPO / target.split("#", 1)[0]).resolve()
              for target in LINK.findall(README.read_text(encoding="utf-8"))}
    pages = {page.resolve() for page in DOCS.rglob("*.md")}
    unlinked = sorted(str(page.relative_to(REPO)) for page in pages - linked)
    assert not unlinked, f"docs pages missing from the README's index: {unlinked}"


def python_blocks(document: Path) -> list[str]:
    return CODE_BLOCK.findall(document.read_text(encoding="utf-8"))


@pytest.mark.parametrize("document", [README, DOCS / "library.md"], ids=lambda p: p.name)
def test_the_python_snippets_run_and_print_what_their_comments_say(document):
    """Each ``print(...)  # output`` line of a snippet prints that output."""
    blocks = python_blocks(document)
    assert blocks, f"{document.name} shows no Python"
    for code in blocks:
        expected = [line.split("#", 1)[1].strip() for line in code.splitlines()
                    if line.lstrip().startswith("print(") and "#" in line]
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed):
            exec(compile(code, str(document), "exec"), {})
        shown = [line.strip() for line in printed.getvalue().splitlines()]
        assert shown == expected, (
            f"a snippet of {document.name} printed {shown}, its comments say {expected}")


def uncommented_values(text: str) -> list[str]:
    """The parameters of a file given without a comment on their line or just above it."""
    missing, previous = [], ""
    for line in text.splitlines():
        value = VALUE_LINE.match(line)
        if value and "#" not in line and not previous.lstrip().startswith("#"):
            missing.append(value["name"])
        if line.strip():
            previous = line
    return missing


def test_an_uncommented_value_is_found():
    assert uncommented_values("/**:\n  ros__parameters:\n    # Why.\n    a: 1\n    b: 2\n"
                              "    c: 3  # Why.\n") == ["b"]


@pytest.mark.parametrize("scenario", sorted(SCENARIOS.glob("*.yaml")), ids=lambda p: p.name)
def test_every_value_of_a_scenario_file_says_what_it_means(scenario):
    missing = uncommented_values(scenario.read_text(encoding="utf-8"))
    assert not missing, (f"msgs_config/{scenario.name}: say in a comment on the line above "
                         f"what each of these means: {missing}")
