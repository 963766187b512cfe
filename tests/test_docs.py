"""Every ```bash and ```python block of README.md and docs/*.md runs as written.

Blocks run in order (README.md, then docs/*.md by name) in one scratch directory (``.venv`` there
links to the installed environment, whose bin/ is first on PATH), as for a user who follows the
README after its install and then the docs: the README's quickstart builds the small suite
(``suite/``) and runs (``runs/``) that later pages use. Python blocks run each in a fresh interpreter
(a block must import what it uses); bash blocks with ``set -e`` and ``pipefail``. Blocks that
cannot run here (real datasets, Claude Code, Codex, a GPU, the install itself) are fenced
```bash notest; output and layouts are ```text. Other shell fences (sh, console, shell) are
refused, so that no command escapes the test by its fence.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
RUN = {"bash", "python"}
NOT_RUN = {"text", "json", "jsonl", "toml", "yaml", "csv", "ini", "diff", "markdown", "md"}
REFUSED = {"sh", "shell", "console", "zsh", "py", "python3", "shell-session", "bash-session"}
BLOCK_TIMEOUT_S = 600
FENCE = re.compile(r"^(`{3,})(.*)$")


@dataclass
class Block:
    page: Path
    line: int
    lang: str
    notest: bool
    code: str

    @property
    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def blocks(page: Path) -> list[Block]:
    """The fenced blocks of ``page`` in order (nested fences are not used in the docs)."""
    out: list[Block] = []
    lines = page.read_text().splitlines()
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i].strip()) if not lines[i].startswith("    ") else None
        if not m:
            i += 1
            continue
        ticks, info = m.group(1), m.group(2).strip().split()
        start, body = i + 1, []
        i += 1
        while i < len(lines) and lines[i].strip() != ticks:
            body.append(lines[i])
            i += 1
        i += 1
        lang = info[0].lower() if info else ""
        out.append(Block(page, start, lang, "notest" in info[1:], "\n".join(body) + "\n"))
    return out


def test_every_fence_is_run_or_marked():
    bad = [
        f"{b.where}: ```{b.lang}"
        for p in PAGES
        for b in blocks(p)
        if b.lang in REFUSED or (b.lang not in RUN and b.lang not in NOT_RUN)
    ]
    assert not bad, (
        "fence these as ```bash / ```python (run), ```bash notest (cannot run here) or ```text:\n" + "\n".join(bad)
    )


def _env(scratch: Path) -> dict[str, str]:
    venv_bin = Path(sys.executable).parent
    env = dict(os.environ)
    env["PATH"] = f"{venv_bin}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = str(ROOT)  # the tree under test, also where the venv's editable install points elsewhere
    env["HOME"] = str(scratch / "home")  # caches and logins of the docs' commands stay in the scratch dir
    env["AW_CACHE_DIR"] = str(scratch / "home" / "aw-cache")
    env.pop("PYTEST_XDIST_WORKER", None)
    env["MPLBACKEND"] = "Agg"
    return env


def _scratch(tmp_path: Path) -> Path:
    (tmp_path / "home").mkdir()
    venv = Path(sys.executable).parent.parent
    (tmp_path / ".venv").symlink_to(venv)
    return tmp_path


def test_blocks_run_in_order(tmp_path):
    scratch = _scratch(tmp_path)
    env = _env(scratch)
    for page in PAGES:
        for b in blocks(page):
            if b.lang not in RUN or b.notest:
                continue
            if b.lang == "bash":
                cmd = ["bash", "-c", "set -eo pipefail\n" + b.code]
            else:
                cmd = [sys.executable, "-c", b.code]
            proc = subprocess.run(
                cmd,
                cwd=scratch,
                env=env,
                capture_output=True,
                text=True,
                timeout=BLOCK_TIMEOUT_S,
                stdin=subprocess.DEVNULL,
            )
            assert proc.returncode == 0, (
                f"{b.where}: the ```{b.lang} block failed (exit {proc.returncode})\n{b.code}\n"
                f"--- stdout ---\n{proc.stdout[-3000:]}\n--- stderr ---\n{proc.stderr[-3000:]}"
            )


# The docs describe the present; how things changed, what a figure used to be and which issue
# asked for it belong in CHANGELOG.md and the commit log.
HISTORY = re.compile(r"\b(?:was|were)\b|\bissues?\s*#?\d+|\b(?:the|this|that) issue\b|\bissue's\b", re.IGNORECASE)
BEFORE = re.compile(r"\bbefore\b", re.IGNORECASE)
# "before" in the sense of an order of steps, never of an earlier state of the project.
BEFORE_ALLOWED = (
    "before a batch",
    "before any ",
    "before anything",
    "before and after",
    "before composing",
    "before drawing",
    "before each ",
    "before it ",
    "before registration",
    "before scoring",
    "before the clock",
    "before the episode",
    "before the first",
    "before the reply",
    "before writing",
)
# Messages of the programs themselves, quoted as they read.
QUOTED = ("this call was not carried out",)
PERFORMANCE_MAX_LINES = 250


def history_words(text: str) -> list[str]:
    """The places in ``text`` that speak of the project's past (was, were, an issue, "before"
    outside ``BEFORE_ALLOWED``), each with 40 characters of context on either side."""
    flat = re.sub(r"\s+", " ", text)
    for quote in QUOTED:
        flat = flat.replace(quote, "")
    spots = [m.start() for m in HISTORY.finditer(flat)]
    spots += [m.start() for m in BEFORE.finditer(flat) if not flat[m.start() :].lower().startswith(BEFORE_ALLOWED)]
    return [flat[max(0, i - 40) : i + 40] for i in sorted(spots)]


def test_history_words_are_found():
    assert history_words("exact is 14x (was 31x against\nthe old reference)") == [
        "exact is 14x (was 31x against the old reference)"
    ]
    assert len(history_words("Targets of issue 24: not met. The issue's target; the issue measured it.")) == 3
    assert len(history_words("9.3 s before: the graph is built once (as before). Before these fixes it hung.")) == 3
    assert len(history_words("Workers were killed. Issues #12 and 13.")) == 2
    assert (
        history_words("checked before anything runs, before the first episode; commands only a human may issue") == []
    )
    assert history_words("its reply says `recording failed: this call was not carried out`") == []


def test_docs_state_the_present():
    bad = [f"{p.relative_to(ROOT)}: ...{spot}..." for p in PAGES for spot in history_words(p.read_text())]
    assert not bad, "the docs describe the present (history goes to CHANGELOG.md):\n" + "\n".join(bad)


def test_every_page_opens_with_what_it_gives():
    """After the title comes a paragraph of prose (what a user gets, how to use it), not a
    table, a list, a code block or another heading. The README opens with its two set-up
    commands (the project's rule), and then such a paragraph."""
    bad = []
    for page in PAGES:
        lines = [line for line in page.read_text().splitlines() if line.strip()]
        if page.name == "README.md" and lines[1].startswith("`" * 3):
            end = lines.index("`" * 3, 2)
            assert end == 4, "README.md opens with exactly two commands"
            lines = lines[:1] + lines[end + 1 :]
        if not lines[0].startswith("# ") or lines[1].lstrip().startswith(("#", "|", "`" * 3, "- ", "* ", ">")):
            bad.append(f"{page.relative_to(ROOT)}: {lines[1][:60]}")
    assert not bad, "open each page with a title and a paragraph:\n" + "\n".join(bad)


def test_performance_page_answers_first_and_stays_short():
    lines = (ROOT / "docs" / "performance.md").read_text().splitlines()
    assert len(lines) <= PERFORMANCE_MAX_LINES, (
        f"docs/performance.md has {len(lines)} lines (at most {PERFORMANCE_MAX_LINES})"
    )
    first_screen = lines[:30]
    for mode in ("| `exact` (numba", "| `fast` (numba", '| `exact`, `backend="jax"`'):
        assert any(line.startswith(mode) for line in first_screen), f"the first screen gives no row for {mode}"
