"""The README and docs/ tell the truth: every `onebox ...` command line names a real command and
flags its --help lists, every ONEBOX_ variable is one onebox reads, every benchmark named exists
with its flags, every relative link and picture points at a file (and heading) that exists, and
the README's Python reads detections off a real bus."""

from __future__ import annotations

import argparse
import functools
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from onebox.testing.processes import wait_for_output
from services import cli

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

FENCED = re.compile(r"^```[^\n]*\n(.*?)^```", re.M | re.S)
INLINE = re.compile(r"`([^`\n]+)`")
# A command starts a line or follows a shell separator, after any VAR=value assignments.
COMMAND = re.compile(
    r"(?:^|&&|\|\||[;|(]|\$ )\s*(?:sudo\s+)?(?:[A-Z_]+=\S*\s+)*onebox((?:\s+\S+)+)"
)
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
SCRIPT = re.compile(r"\b((?:benchmarks|docs)/\w+\.py)((?:\s+\[?-{1,2}[\w-]+)*)")
VARIABLE = re.compile(r"\bONEBOX_[A-Z_]+\b")


def _code(page: Path) -> list[str]:
    """The lines of every fenced block and every inline code span, comments cut off."""
    text = page.read_text()
    lines = [line for block in FENCED.findall(text) for line in block.splitlines()]
    lines += INLINE.findall(FENCED.sub("", text))
    return [line.split(" # ")[0] for line in lines]


def _commands() -> list[tuple[str, str]]:
    """(page, command line after `onebox`) for every onebox command the pages show."""
    return [
        (page.name, match.group(1).strip())
        for page in PAGES
        for line in _code(page)
        for match in COMMAND.finditer(line)
    ]


@functools.cache
def _parser(name: str) -> argparse.ArgumentParser:
    return cli.command_parser(name)[0]


def _flags(words: str) -> list[str]:
    try:
        tokens = shlex.split(words)
    except ValueError:  # a quote left open in a table cell's example
        tokens = words.split()
    stripped = (token.strip("[]()") for token in tokens)
    return [
        token.split("=")[0] for token in stripped if re.fullmatch(r"--?[a-z][\w-]*(=.*)?", token)
    ]


def test_the_pages_show_commands_to_check():
    """The checker finds the README's commands at all (its patterns have not gone stale)."""
    names = {line.split()[0] for page, line in _commands() if page == "README.md"}
    assert {"sim", "locator", "record", "replay", "import", "export", "certs"} <= names


@pytest.mark.parametrize(("page", "line"), _commands(), ids=lambda value: str(value)[:60])
def test_every_onebox_command_line_is_real(page, line):
    """`onebox NAME --flag ...` in a code block or span: NAME is a command, each flag is one its
    --help lists (or, for `onebox --version`, the top parser's)."""
    name, *_ = line.split()
    if name.startswith("-"):
        assert set(_flags(line)) <= {"--help", "-h", "--version"}, f"{page}: onebox {line}"
        return
    assert name in cli.COMMANDS, f"{page}: `onebox {line}`: no command {name!r}"
    known = set(_parser(name)._option_string_actions)
    unknown = [flag for flag in _flags(line.removeprefix(name)) if flag not in known]
    assert not unknown, f"{page}: `onebox {line}`: {unknown} not in `onebox {name} --help`"


def test_every_flag_on_its_own_is_one_some_command_or_benchmark_has():
    """A code span that starts with a flag (`--slop-ms MS`, in a table of a command's flags) is a
    flag some onebox command's --help lists, or one a benchmark defines."""
    known = {flag for name in cli.COMMANDS for flag in _parser(name)._option_string_actions}
    scripts = " ".join(p.read_text() for p in (ROOT / "benchmarks").glob("*.py"))
    known |= set(re.findall(r"\"(--[\w-]+)\"", scripts))
    alone = {
        (page.name, flag)
        for page in PAGES
        for span in INLINE.findall(FENCED.sub("", page.read_text()))
        if span.startswith("-")
        for flag in _flags(span)[:1]
    }
    assert not {(page, flag) for page, flag in alone if flag not in known}


def test_every_command_is_in_the_readme():
    """Each command `onebox --help` lists is named in the README as `onebox NAME`."""
    named = {line.split()[0] for page, line in _commands() if page == "README.md"}
    missing = sorted(set(cli.COMMANDS) - named)
    assert not missing, f"commands the README does not name: {missing}"


def test_every_onebox_variable_is_one_onebox_reads():
    """ONEBOX_X named anywhere in the pages is a setting some command's --help lists, or a
    variable the code names outright ("ONEBOX_LOG")."""
    helps = " ".join(
        action.help or "" for name in cli.COMMANDS for action in _parser(name)._actions
    )
    code = " ".join(p.read_text() for d in ("services", "onebox") for p in (ROOT / d).rglob("*.py"))
    known = set(VARIABLE.findall(helps)) | set(re.findall(r"\"(ONEBOX_\w+)\"", code))
    named = {(page.name, v) for page in PAGES for v in VARIABLE.findall(page.read_text())}
    assert not {(page, v) for page, v in named if v not in known}


def test_every_script_named_exists_with_its_flags():
    """`python benchmarks/x.py --flag` and `python docs/x.py`: the file exists and defines
    each flag."""
    wrong = []
    for page in PAGES:
        for line in _code(page):
            for script, flags in SCRIPT.findall(line):
                path = ROOT / script
                if not path.is_file():
                    wrong.append(f"{page.name}: {script} does not exist")
                    continue
                source = path.read_text()
                wrong += [
                    f"{page.name}: {script} has no {f}"
                    for f in _flags(flags)
                    if f'"{f}"' not in source
                ]
    assert not wrong


def _anchor(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation but - and _ dropped, spaces to -."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    text = FENCED.sub("", page.read_text())
    return {_anchor(h) for h in re.findall(r"^#+\s+(.*)$", text, re.M)}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_relative_link_and_picture_exists(page):
    """Each [text](path) and ![alt](path) that is not a web address points at a file that
    exists, and a #anchor at a heading of that file."""
    broken = []
    for target in LINK.findall(FENCED.sub("", page.read_text())):
        if re.match(r"[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        where = (page.parent / path).resolve() if path else page
        if not where.exists():
            broken.append(target)
        elif anchor and where.suffix == ".md" and anchor not in _anchors(where):
            broken.append(target)
    assert not broken, f"{page.name}: {broken}"


def test_the_readmes_python_prints_the_boxes_on_detections(processes, tmp_path):
    """The README's Python subscriber, pointed at a private router, prints the box that
    `onebox pub` puts on `detections`."""
    found = re.search(r"^```python\n(.*?)^```", (ROOT / "README.md").read_text(), re.M | re.S)
    assert found and "tcp/127.0.0.1:7447" in found.group(1)
    script = tmp_path / "detections.py"
    script.write_text(found.group(1).replace("tcp/127.0.0.1:7447", processes.endpoint))
    reader = subprocess.Popen(
        [sys.executable, "-u", str(script)],
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    processes.started.append(reader)
    box = {
        "id": "7",
        "results": [{"class_id": "box", "score": 0.5}],
        "bbox": {"center": {"position": {"x": 0.25}}, "size": {"x": 0.2, "y": 0.1, "z": 0.06}},
    }
    processes.start("pub", "detections", "Detection3DArray", json.dumps({"detections": [box]}))
    line = wait_for_output(reader, "0.5\n", timeout_s=30)
    assert "7 Vector3(x=0.25, y=0.0, z=0.0) Vector3(x=0.2, y=0.1, z=0.06) 0.5" in line
