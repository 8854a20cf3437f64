"""The documentation's promises (issue 33): every relative link in README.md and docs/*.md
points to a file or folder that exists, every anchor into a markdown file names one of its
headings, and every command their code blocks quote runs (``--help`` exits 0).

A command is quoted when a code block (fenced, or indented by four spaces or more after a
blank line) holds ``python -m fem_ade.<module>``, ``python -m sharp_ref`` or
``python studies/<script>.py``, with any prefix (``.venv/bin/python``, ``mpirun -n 2 ...``);
each module or script is run once, from the repository's root, with this interpreter.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

LINK = re.compile(r"!?\[([^\]]*)\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
FENCE = re.compile(r"^\s*(```|~~~)")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
MODULE = re.compile(r"(?:^|[\s;&|(])(?:\S*/)?python3?\s+-m\s+"
                    r"(fem_ade\.[A-Za-z_][\w.]*|sharp_ref)\b")
SCRIPT = re.compile(r"(?:^|[\s;&|(])(?:\S*/)?python3?\s+(studies/[\w./-]+\.py)\b")


def split_code(text: str) -> tuple[list[str], list[str]]:
    """(the prose lines, the code-block lines) of a markdown page: fenced blocks, and lines
    indented by four spaces or more that follow a blank line or another such line."""
    prose, code = [], []
    fenced = False
    in_indented = False
    previous_blank = True
    for line in text.splitlines():
        if FENCE.match(line):
            fenced = not fenced
            previous_blank, in_indented = False, False
            continue
        if fenced:
            code.append(line)
            continue
        blank = not line.strip()
        indented = line.startswith("    ") and not blank
        if indented and (previous_blank or in_indented):
            code.append(line)
            in_indented = True
        else:
            if not blank:
                in_indented = False
            prose.append(line)
        previous_blank = blank
    return prose, code


def links(page: Path) -> list[str]:
    """The link targets of a page's prose (inline code and code blocks left out)."""
    prose, _ = split_code(page.read_text())
    text = re.sub(r"`[^`\n]*`", "", "\n".join(prose))
    return [m.group(2) for m in LINK.finditer(text)]


def relative_links() -> list[tuple[Path, str]]:
    return [(page, target) for page in PAGES for target in links(page)
            if not re.match(r"^[a-z][a-z0-9+.-]*:", target)]  # http:, https:, mailto: ...


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, markup and punctuation dropped, spaces to
    hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link: its text
    text = re.sub(r"[^\w\- ]", "", text.strip().lower())
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """The anchors of a markdown page's headings (a repeated one gets -1, -2, ...)."""
    prose, _ = split_code(page.read_text())
    seen: dict[str, int] = {}
    out = set()
    for line in prose:
        m = HEADING.match(line)
        if not m:
            continue
        base = slug(m.group(2))
        k = seen.get(base, 0)
        seen[base] = k + 1
        out.add(base if k == 0 else f"{base}-{k}")
    return out


def quoted_commands() -> dict[str, list[str]]:
    """Each module (``-m NAME``) or script (``studies/....py``) quoted in a code block → the
    pages that quote it."""
    found: dict[str, list[str]] = {}
    for page in PAGES:
        _, code = split_code(page.read_text())
        for line in code:
            for m in MODULE.finditer(line):
                found.setdefault(f"-m {m.group(1)}", []).append(page.name)
            for m in SCRIPT.finditer(line):
                found.setdefault(m.group(1), []).append(page.name)
    return {k: sorted(set(v)) for k, v in sorted(found.items())}


COMMANDS = quoted_commands()


@pytest.mark.parametrize("page, target", relative_links(),
                         ids=[f"{p.name}:{t}" for p, t in relative_links()])
def test_relative_links_point_to_what_exists(page, target):
    path = target.split("#", 1)[0].split("?", 1)[0]
    if not path:  # an anchor into the page itself
        return
    where = (page.parent / path).resolve()
    assert where.exists(), f"{page.relative_to(ROOT)} links to {target}: {where} is missing"


@pytest.mark.parametrize("page, target",
                         [(p, t) for p, t in relative_links() if "#" in t],
                         ids=[f"{p.name}:{t}" for p, t in relative_links() if "#" in t])
def test_anchors_name_a_heading(page, target):
    path, anchor = target.split("#", 1)
    where = (page.parent / path).resolve() if path else page
    if where.suffix != ".md" or not where.is_file():
        return  # an anchor into something else (or a missing file: the test above says so)
    assert anchor in anchors(where), (
        f"{page.relative_to(ROOT)} links to {target}: {where.name} has no heading with "
        f"that anchor")


def test_the_docs_quote_the_main_commands():
    """The scan finds what the pages quote (a scan that found nothing would pass vacuously)."""
    for name in ("-m fem_ade.run", "-m fem_ade.sweep", "-m fem_ade.branch", "-m fem_ade.stability",
                 "-m fem_ade.render", "-m sharp_ref"):
        assert name in COMMANDS, (name, sorted(COMMANDS))
    assert any(name.startswith("studies/") for name in COMMANDS), sorted(COMMANDS)


@pytest.mark.parametrize("command", list(COMMANDS))
def test_quoted_command_runs(command):
    """``--help`` of each quoted module or script exits 0, from the repository's root."""
    args = command.split() if command.startswith("-m ") else [command]
    proc = subprocess.run([sys.executable, *args, "--help"], cwd=ROOT,
                          env={**os.environ, "MPLBACKEND": "Agg"}, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, (
        f"`python {command} --help` (quoted in {', '.join(COMMANDS[command])}) exited "
        f"{proc.returncode}:\n{proc.stderr[-2000:]}")


@pytest.mark.parametrize("text, expected", [
    ("The axisymmetric geometry (`--geometry axisymmetric`)",
     "the-axisymmetric-geometry---geometry-axisymmetric"),
    ("The paper's gallery: what the model makes", "the-papers-gallery-what-the-model-makes"),
    ("`python -m fem_ade.branch`: a branch by continuation",
     "python--m-fem_adebranch-a-branch-by-continuation"),
])
def test_slug_is_githubs(text, expected):
    assert slug(text) == expected


def test_the_scans_see_code_blocks_and_links():
    """What the scans take for prose, code and links, on a page made for it."""
    page = ("Prose with [a link](docs/x.md#top) and `[not](a-link.md)`.\n\n"
            "    .venv/bin/python -m fem_ade.run torus\n"
            "    mpirun -n 2 python studies/bench.py --quick\n\n"
            "```toml\n[x](inside-a-fence.md)\n```\n"
            "- a list item\n  continued, [an image](!.png)\n")
    prose, code = split_code(page)
    assert code == ["    .venv/bin/python -m fem_ade.run torus",
                    "    mpirun -n 2 python studies/bench.py --quick", "[x](inside-a-fence.md)"]
    text = re.sub(r"`[^`\n]*`", "", "\n".join(prose))
    assert [m.group(2) for m in LINK.finditer(text)] == ["docs/x.md#top", "!.png"]
    assert [m.group(1) for line in code for m in MODULE.finditer(line)] == ["fem_ade.run"]
    assert [m.group(1) for line in code for m in SCRIPT.finditer(line)] == ["studies/bench.py"]
