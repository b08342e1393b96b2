"""Every ```python block of README.md and docs/*.md runs as written.

The rule: each block is a whole script on its own. It runs in a fresh interpreter (this test's
``sys.executable``, the worktree's ``.venv``), with the repository root as the working directory and a
timeout; blocks of one page share nothing, so a reader can copy any one block and run it. A block
fails the test when it exits with a non-zero status (an exception, a failed ``assert``); its stderr
is the failure message.

Blocks that need ROS (nodes, DDS) are written as ```bash or ```console blocks and are not run here;
every block runs in an interpreter of its own (and some start more: the recorder's writer process, a
process pool), so the blocks are marked ``slow`` like the other tests that start processes
(``pytest -m "not slow"`` leaves them out and keeps the checks of the links).
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
TIMEOUT_S = 60
# A fence opens with ```python at the start of a line (indented fences, inside list items, too)
# and closes with ``` at the same indentation.
FENCE = re.compile(r"^(?P<indent>[ \t]*)```python[ \t]*\n(?P<body>.*?)^(?P=indent)```[ \t]*$", re.M | re.S)


def python_blocks(page: Path):
    """(line number of the fence, the block's code without the fence's indentation)."""
    text = page.read_text()
    for match in FENCE.finditer(text):
        yield text.count("\n", 0, match.start()) + 1, textwrap.dedent(match["body"])


def _cases():
    for page in PAGES:
        for line, code in python_blocks(page):
            yield pytest.param(code, id=f"{page.relative_to(ROOT)}:{line}", marks=[pytest.mark.slow])


def test_the_pages_have_python_blocks():
    assert any(True for page in PAGES for _ in python_blocks(page)), "no ```python block found"


@pytest.mark.parametrize("code", list(_cases()))
def test_python_block_runs(code):
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONDONTWRITEBYTECODE="1")
    try:
        proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True,
                              text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the block did not finish in {TIMEOUT_S} s")
    assert proc.returncode == 0, f"the block stopped (exit code {proc.returncode}):\n{proc.stderr[-3000:]}"


LINK = re.compile(r"\[[^\]]*\]\((?P<target>[^)\s]+)\)")


def _anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation other than - and _ dropped, spaces to -."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(page: Path) -> set:
    text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.M | re.S)   # no headings in code blocks
    return {_anchor(m[1]) for m in re.finditer(r"^#+ (.*)$", text, re.M)}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_links_stay_inside_the_repository_and_resolve(page):
    for match in LINK.finditer(page.read_text()):
        target = match["target"]
        if target.startswith(("http://", "https://")):
            continue
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        assert ROOT in file.parents or file == ROOT, f"{target}: outside the repository"
        assert file.exists(), f"{target}: no such file"
        if anchor and file.suffix == ".md":
            assert anchor in _anchors(file), f"{target}: no heading with that anchor in {file.name}"


def test_the_node_page_lists_every_parameter():
    from biped_sim.config.parameters import PARAMETERS
    text = (ROOT / "docs" / "node.md").read_text()
    section = text[text.index("\n## Parameters"):text.index("\n## Topics")]
    listed = re.findall(r"^\| `([\w.]+)` \|", section, re.M)
    assert listed == [p.name for p in PARAMETERS], "docs/node.md's parameter table differs from PARAMETERS"


def _rendering_problems(text: str) -> list:
    """What a CommonMark renderer (GitHub's is one) would do wrong with the page's fences.

    A fence closes only on a line of its own marker with nothing after it: a closing line with an
    info string (```` ```console ````) is code, and the block runs on to the next bare marker or to
    the end of the page, swallowing the headings and tables between. markdown-it-py parses the
    page as CommonMark does (with GitHub's tables); a code block then holds a line that starts with
    its own marker, or a table's delimiter row, and the page shows one long code block.
    """
    from markdown_it import MarkdownIt

    problems = []
    lines = text.splitlines()
    for token in MarkdownIt("commonmark").enable("table").parse(text):
        if token.type == "tr_open" and not lines[token.map[0]].lstrip().startswith("|"):
            # GitHub's table goes on until a blank line: a paragraph right under it becomes a row
            problems.append(f"line {token.map[0] + 1} ({lines[token.map[0]][:40]!r}...) is a row of the "
                            "table above it: leave a blank line after a table")
        if token.type != "fence":
            continue
        first, end = token.map
        where = f"the code block opened at line {first + 1} ({lines[first].strip()!r})"
        for offset, line in enumerate(token.content.splitlines()):
            if line.lstrip().startswith(token.markup):
                problems.append(f"{where} holds the fence line {first + 2 + offset} ({line.strip()!r}): "
                                "a closing fence has nothing after its marker")
        if re.search(r"^ *\|? *:?-{3,}:? *\|", token.content, re.M):
            problems.append(f"{where} holds a table (its delimiter row): a fence before it is not closed")
        if end >= len(lines) and lines[-1].strip() != token.markup:
            problems.append(f"{where} is never closed: it runs to the end of the page")
    return problems


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_the_page_renders_as_written(page):
    assert _rendering_problems(page.read_text()) == []


def test_a_fence_closed_with_an_info_string_is_found():
    page = "# A\n\n```console\n$ ls\n```console\n\n## B\n\n| a | b |\n| --- | --- |\n| 1 | 2 |\n"
    problems = _rendering_problems(page)
    assert len(problems) == 3 and "line 5" in problems[0], problems
    assert _rendering_problems(page.replace("```console\n\n", "```\n\n")) == []


def test_a_paragraph_glued_to_a_table_is_found():
    page = "| a | b |\n| --- | --- |\n| 1 | 2 |\nThe text under it.\n"
    assert "line 4" in " ".join(_rendering_problems(page))
    assert _rendering_problems(page.replace("|\nThe", "|\n\nThe")) == []


def test_the_node_page_lists_every_key_of_the_impact_message():
    import numpy as np

    from biped_sim.engine.results import Event
    from biped_sim.recording.messages import event_status
    zeros = np.zeros(5)
    touchdown = Event(time=0.5, kind="touchdown", leg=2, q=zeros, dq_minus=zeros, dq_plus=zeros,
                      impulse=np.zeros(2), stance_leg_before=1, stance_leg_after=2, energy_loss=1.0)
    keys = [kv.key for kv in event_status(touchdown).values]
    text = (ROOT / "docs" / "node.md").read_text()
    section = text[text.index("\n### The `impact` message"):text.index("\n### The `diagnostics` topic")]
    listed = re.findall(r'`values\["(\w+)"\]`', section)
    assert sorted(set(listed)) == sorted(keys), "docs/node.md's impact table differs from event_status's keys"


# A ```console block right under the line CHECKED quotes what its "$ " commands print: the test runs
# each command and compares the lines. In the quote "..." stands for any text (a line cut short);
# wall times and UTC stamps differ from run to run, so both sides are compared with them masked.
CHECKED = "<!-- test_docs: the output below is checked -->"
MASKS = [(re.compile(r"\d{8}T\d{6}Z"), "<UTC time>"), (re.compile(r"\[\d+\.\d+ s\]"), "[<wall s>]"),
         (re.compile(r" in \d+\.\d+ s$"), " in <wall s>"),
         # biped-sim simulate's rows of the machine's speed
         (re.compile(r"^( +wall time  )\S+ s$"), r"\1<wall s>"),
         (re.compile(r"^( +real-time factor  )\S+$"), r"\1<factor>")]


def _masked(line: str) -> str:
    for pattern, stand_in in MASKS:
        line = pattern.sub(stand_in, line)
    return line.rstrip()


def checked_quotes(page: Path):
    """(line number, [(command, [quoted lines])]) of each checked console block of the page."""
    text = page.read_text()
    for match in re.finditer(re.escape(CHECKED) + r"\n```console\n(?P<body>.*?)^```$", text, re.M | re.S):
        commands = []
        for line in match["body"].splitlines():
            if line.startswith("$ "):
                commands.append((line[2:].split("  #")[0].strip(), []))
            else:
                commands[-1][1].append(line)
        yield text.count("\n", 0, match.start()) + 2, commands


def _quote_cases():
    for page in PAGES:
        for line, commands in checked_quotes(page):
            yield pytest.param(commands, id=f"{page.relative_to(ROOT)}:{line}")


def test_some_quotes_are_checked():
    assert len(list(_quote_cases())) >= 2


@pytest.mark.parametrize("commands", list(_quote_cases()))
def test_a_quoted_output_is_what_the_command_prints(commands):
    import shlex
    for command, quoted in commands:
        argv = shlex.split(command)
        assert argv[0].startswith(".venv/bin/"), f"{command}: a checked command is one of .venv/bin"
        argv[0] = str(Path(sys.executable).parent / Path(argv[0]).name)
        proc = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=TIMEOUT_S,
                              env=dict(os.environ, MPLBACKEND="Agg"))
        printed = [_masked(line) for line in (proc.stdout + proc.stderr).splitlines()]
        assert len(printed) == len(quoted), f"{command} printed {len(printed)} lines, the page quotes {len(quoted)}"
        for got, want in zip(printed, quoted):
            pattern = ".*".join(re.escape(part) for part in _masked(want).split("..."))
            assert re.fullmatch(pattern, got), f"{command}:\n the page quotes {want!r}\n the command prints {got!r}"
