"""The README's commands work as written, and the documentation's links resolve.

Every shell command in README.md's ``bash`` blocks is either run here (from the repository
root, as a user types it) or named in ``SKIPPED`` with the reason: a command added to the README
is run by this test until it is consciously skipped. Commands that run the pipeline are skipped
(the face end-to-end tests in tests/face_pipeline/ run them on a coarse demo).
"""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from tests.commands import ROOT, invoke, physanim_env

README = ROOT / "README.md"
DOCS = [README, ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").glob("*.md"))]
#: a fenced code block, also one indented in a list item
FENCED = r"^[ \t]*```.*?^[ \t]*```"

#: README commands not run here, and why (the text as in the README, comments dropped)
SKIPPED = {
    "make pipeline": "the whole face pipeline (tests/face_pipeline/ runs it on a coarse demo)",
    "make test": "the whole test suite",
    "make pipeline CONFIG=configs/models/model2.yaml": "a pipeline run",
    "make pipeline ARGS='--set materials.model.default.E_kPa=300'": "a pipeline run",
    "make stage STAGE=simulate": "needs the upstream stages in the store",
    "physanim run -c configs/models/model3.yaml": "a pipeline run",
    "physanim run --from simulate --force simulate": "a pipeline run",
    "physanim show simulate": "needs a simulate output in the store",
    "physanim check data/mine": "data/mine is the reader's own recording",
    "physanim check data/mine --set track.backend=markerless": "the reader's own recording",
    "physanim run --dataset data/mine --set track.backend=markerless": "a pipeline run",
    "physanim sweep configs/sweeps/stiffness.yaml": "a sweep of three pipeline runs",
    "physanim sweep configs/sweeps/models.yaml --workers 2": "a sweep of four pipeline runs",
    "physanim sweep configs/sweeps/stiffness.yaml --serial": "a sweep of three pipeline runs",
    "physanim serve data --interval 3600": "runs until stopped",
    'physanim serve data --cron "0 2 * * *"': "runs until stopped",
    "physanim run -p keyframe -c configs/keyframe_walk.yaml": "a keyframe pipeline run",
    "make arm": "the arm pipeline (tests/muscle/test_arm_pipeline.py runs it)",
    "make lint": "ruff over the whole repository (CI runs it)",
    'make test ARGS="-k store"': "a part of the test suite",
    "make docs": "rewrites the generated docs (test_stage_docs.py checks STAGES.md)",
    "make bench": "every benchmark, minutes",
}


def readme_commands(text: str) -> list[str]:
    """The shell commands of the ``bash``/``sh``/``shell`` blocks of ``text``, one per line
    (backslash continuations joined), as written but without comments and repeated blanks."""
    commands = []
    for block in re.findall(r"^[ \t]*```(?:bash|sh|shell)\n(.*?)^[ \t]*```", text, re.M | re.S):
        for line in block.replace("\\\n", " ").splitlines():
            command = " ".join(_uncommented(line).split())
            if command:
                commands.append(command)
    return commands


def _uncommented(line: str) -> str:
    """``line`` up to its comment: the first ``#`` outside quotes that starts a word."""
    quote = None
    for i, ch in enumerate(line):
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i]
    return line


COMMANDS = readme_commands(README.read_text(encoding="utf-8"))
RUN = [c for c in COMMANDS if c not in SKIPPED]


def test_every_skipped_command_is_in_the_readme() -> None:
    """SKIPPED names exactly the README commands this test does not run."""
    assert COMMANDS, "no bash blocks found in README.md"
    assert {c for c in COMMANDS if c in SKIPPED} == set(SKIPPED), (
        "SKIPPED names commands the README no longer has: "
        + ", ".join(sorted(set(SKIPPED) - set(COMMANDS)))
    )
    assert RUN, "the README has no command this test can run"


@pytest.mark.parametrize("command", RUN)
def test_readme_command_runs(command: str) -> None:
    """Run as typed from the repository root: ``physanim`` in this process, ``make`` and
    ``.venv/bin/python`` as subprocesses (with this interpreter)."""
    words = shlex.split(command)
    program, args = words[0], words[1:]
    if program == "physanim":
        result = invoke(*args)
    elif program == "make":
        result = subprocess.run(
            ["make", "--no-print-directory", *args], cwd=ROOT, capture_output=True, text=True,
            timeout=120, env=physanim_env(),
        )  # fmt: skip
    elif program in ("python", "python3", ".venv/bin/python"):
        result = subprocess.run(
            [sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=300,
            env=physanim_env(),
        )  # fmt: skip
    else:
        pytest.fail(f"README command {command!r}: run it here or add it to SKIPPED")
    assert result.returncode == 0, f"{command}: exit {result.returncode}\n{result.stderr[-2000:]}"
    assert result.stdout.strip() or result.stderr.strip(), f"{command}: printed nothing"


def test_readme_is_a_guide() -> None:
    """At most 250 lines; its first screen names the two commands, the report and the edit
    gesture; a decimal number in its prose links to the page holding the command behind it."""
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 250
    first = "\n".join(text.splitlines()[:40])
    for needed in ("make pipeline", "make test", "data/demo/runs/report/index.html", "--set"):
        assert needed in first, needed
    prose = _without_code(text)
    prose = re.sub(r"\[[^\]]*\]\([^)]*\)", "", prose)  # links, their text included
    assert not re.findall(r"\d+\.\d+", prose), "a number without a link to its command"


def _without_code(text: str) -> str:
    """``text`` without fenced code blocks, indented code lines and inline code spans."""
    text = re.sub(FENCED, "", text, flags=re.M | re.S)
    text = re.sub(r"^    .*$", "", text, flags=re.M)
    return re.sub(r"`[^`\n]*`", "", text)


def github_anchor(heading: str) -> str:
    """The anchor GitHub gives a Markdown heading: link text kept, lower case, punctuation
    other than ``-`` and ``_`` dropped, spaces to hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip())
    text = re.sub(r"[^\w\- ]", "", text.replace("`", "").lower())
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """The anchors of a Markdown file: its headings' (numbered as GitHub numbers repeats) and
    explicit ``<a id=...>`` / ``<a name=...>``."""
    text = path.read_text(encoding="utf-8")
    found: set[str] = set(re.findall(r"<a\s+(?:id|name)=\"([^\"]+)\"", text))
    seen: dict[str, int] = {}
    text = re.sub(FENCED, "", text, flags=re.M | re.S)
    for heading in re.findall(r"^#{1,6}\s+(.+?)\s*#*$", text, re.M):
        slug = github_anchor(heading)
        n = seen.get(slug, 0)
        found.add(slug if n == 0 else f"{slug}-{n}")
        seen[slug] = n + 1
    return found


def links(path: Path) -> list[str]:
    """The targets of the Markdown links and images of ``path`` (outside code)."""
    text = re.sub(FENCED, "", path.read_text(encoding="utf-8"), flags=re.M | re.S)
    text = re.sub(r"`[^`\n]*`", "", text)
    return re.findall(r"\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)", text)


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_relative_links_resolve(doc: Path) -> None:
    """Every relative link of README.md, CHANGELOG.md and docs/*.md names an existing file,
    and an anchor into a Markdown file names one of its headings."""
    broken = []
    for target in links(doc):
        if re.match(r"^[a-z][a-z+.-]*:", target):  # http:, https:, mailto:
            continue
        file, _, anchor = target.partition("#")
        path = (doc.parent / file).resolve() if file else doc
        if not path.exists():
            broken.append(f"{target}: no such file")
        elif anchor and path.suffix == ".md" and anchor not in anchors(path):
            broken.append(f"{target}: no heading with that anchor in {path.name}")
    assert not broken, f"{doc.relative_to(ROOT)}: " + "; ".join(broken)
