"""The note on a run that scores well on a final state far from assembled (a heap of parts):
which parts passed and by what margin, and that SR^a is shape-level. The same words on the
task's card in report.html and in report.md's Runs section; the data come from
:func:`aw_eval.analyses.failures.far_from_assembled` (``scores.json`` runs
``far_from_assembled``)."""

from __future__ import annotations

from typing import Any

from aw.cli.common import plural

__all__ = ["far_from_assembled_note"]

SHOWN = 6  # parts named per list


def _names(items: list[str]) -> str:
    more = f" and {len(items) - SHOWN} more" if len(items) > SHOWN else ""
    return ", ".join(items[:SHOWN]) + more


def far_from_assembled_note(label: str, note: dict[str, Any]) -> str:
    """One paragraph, opening with ``label`` (the system, or ``system / task``): the run's PA and
    SR^a, how far its parts are, which passed and by what margin."""
    n, displaced, passed = note["n_parts"], note["displaced"], note["passed"]
    threshold, cutoff = note["threshold"], note["offset_cutoff"]
    score = f"PA {100 * note['pa']:.1f}%" + (" and SR^a 1" if note["sra"] else "")
    out = [
        f"{label}: {score} on a state far from assembled: {len(displaced)} of {plural(n, 'part')} "
        f"({_names(displaced)}) lie more than {cutoff:g} largest-part diagonals from their targets after the "
        "registration."
    ]
    if passed:
        shown = [
            f"{p['part']} (CD {1000 * p['cd']:.2f}, {p['offset']:.2f} diagonals off)"
            for p in sorted(passed, key=lambda p: p["cd"])
        ]
        out.append(
            f"PA counts a part correct when its Chamfer distance to its matched target part is at most {threshold:g} "
            f"(x1000: {1000 * threshold:g}) after ONE rigid registration of the whole state onto the target; "
            f"{len(passed)} {'part passes' if len(passed) == 1 else 'parts pass'}: {_names(shown)}. The "
            "registration fits the whole state as well as it can, so parts near where their targets lie pass "
            "although the object is not assembled."
        )
    if note["sra"]:
        out.append(
            f"SR^a is shape-level: it holds when the whole state's Chamfer distance to the target is below "
            f"{note['sra_threshold']:g} (here SCD x1000 {1000 * note['scd']:.2f}), which parts piled within the target's "
            "outline can reach without being in place; SR, part by part, is 0."
        )
    return " ".join(out)
