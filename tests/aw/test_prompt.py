"""The task text of Appendix A.2, exactly."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from aw.prompt import EXECUTION_INSTRUCTION, REFERENCE_LINES, task_prompt, task_text

PAPER = Path(__file__).resolve().parents[3] / "shared" / "spec" / "assemblyworld-paper.tex"

EXPECTED_NONE = (
    "Assemble the supplied parts into a coherent object.\n"
    "No manual or reference image is supplied. Infer the assembly from the part geometry alone.\n"
    "Inspect connections from multiple camera views using capture_scene, correct gaps, orientation and "
    "obvious interpenetration, and report uncertainties. Do not claim computed accuracy or physical stability "
    "without evidence.\n"
    "Before finishing, check whether all supplied parts have been incorporated into the assembly."
)


def test_exact_text():
    assert task_text("none") == EXPECTED_NONE
    image = task_text("image").splitlines()
    assert image[1] == (
        "One reference image of the finished assembly is attached. "
        "Assemble the parts so that the result matches that image."
    )
    manual = task_text("manual").splitlines()
    assert (
        manual[1]
        == "The attached images are the pages of the assembly manual, in order. Read them in order and follow them."
    )
    for cond in ("none", "image", "manual"):
        lines = task_text(cond).splitlines()
        assert (
            len(lines) == 4
            and lines[0] == EXPECTED_NONE.splitlines()[0]
            and lines[2:] == EXPECTED_NONE.splitlines()[2:]
        )
        assert task_prompt(cond) == task_text(cond) + "\n\n" + EXECUTION_INSTRUCTION


def test_execution_instruction_covers_the_paper():
    text = EXECUTION_INSTRUCTION.lower()
    for phrase in (
        "only through the supplied",
        "source geometry",
        "ground truth",
        "other experiments",
        "do not reset the scene",
        "do not spawn other agents",
        "reread the supplied references",
    ):
        assert phrase in text


def test_unknown_condition():
    with pytest.raises(ValueError, match="unknown reference condition 'video'"):
        task_prompt("video")


def _latex_plain(s: str) -> str:
    s = s.replace("\\_", "_").replace("``", '"').replace("''", '"')
    s = re.sub(r"\\\\", " ", s)
    s = re.sub(r"\\[a-zA-Z]+(\{[^}]*\})?", " ", s)
    return re.sub(r"\s+", " ", s)


@pytest.mark.skipif(not PAPER.is_file(), reason="the paper source is not beside the repository")
def test_matches_the_paper_source():
    paper = _latex_plain(PAPER.read_text())
    for line in EXPECTED_NONE.splitlines():
        assert line in paper, line
    for line in REFERENCE_LINES.values():
        assert f'"{line}"' in paper, line
