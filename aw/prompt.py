"""The task text every agent receives (paper, Appendix A.2, Task Instructions).

``task_prompt(condition)`` is the exact quoted task text with the reference-specific line
substituted for the condition, followed by the execution instruction. The paper describes the
execution instruction without quoting it; :data:`EXECUTION_INSTRUCTION` states exactly the
restrictions it lists (environment tools only; no source geometry, ground truth or other
experiments; no scene reset; no other agents; references may be reread).
"""

from __future__ import annotations

CONDITIONS = ("none", "image", "manual")

OPENING = "Assemble the supplied parts into a coherent object."

REFERENCE_LINES: dict[str, str] = {
    "none": "No manual or reference image is supplied. Infer the assembly from the part geometry alone.",
    "image": "One reference image of the finished assembly is attached. "
    "Assemble the parts so that the result matches that image.",
    "manual": "The attached images are the pages of the assembly manual, in order. Read them in order and follow them.",
}

CLOSING = (
    "Inspect connections from multiple camera views using capture_scene, correct gaps, orientation and "
    "obvious interpenetration, and report uncertainties. Do not claim computed accuracy or physical "
    "stability without evidence.\n"
    "Before finishing, check whether all supplied parts have been incorporated into the assembly."
)

EXECUTION_INSTRUCTION = (
    "Interact with the scene only through the supplied AssemblyWorld environment tools. Do not access "
    "source geometry, ground truth or other experiments, and do not read or search files other than the "
    "supplied references. Do not reset the scene and do not spawn other agents. You may reread the "
    "supplied references at any time."
)


def _check(condition: str) -> None:
    if condition not in REFERENCE_LINES:
        raise ValueError(f"unknown reference condition {condition!r}; expected one of {CONDITIONS}")


def reference_line(condition: str) -> str:
    """The reference-specific line for ``condition`` (``none``, ``image`` or ``manual``)."""
    _check(condition)
    return REFERENCE_LINES[condition]


def task_text(condition: str) -> str:
    """The quoted task text of Appendix A.2 for ``condition``, without the execution instruction."""
    return f"{OPENING}\n{reference_line(condition)}\n{CLOSING}"


def task_prompt(condition: str) -> str:
    """Task text plus the execution instruction: what a harness gives the agent."""
    return f"{task_text(condition)}\n\n{EXECUTION_INSTRUCTION}"
