"""Completion reports against geometric success (Appendix C.1, Completion Reports): declared
completions (``run.json`` ``declared_complete``) and how many succeed, and the median
incorrect-part fraction among unsuccessful claims. Missing reports are excluded."""

from __future__ import annotations

from typing import Any

import numpy as np

from aw_eval.study.table import Study

__all__ = ["completion_reports"]


def completion_reports(study: Study) -> dict[str, Any]:
    out = {}
    for s in study.systems:
        declared = successes = not_declared = missing = 0
        wrong_fracs = []
        for t in study.original_ids:
            rec = study.record(s, t)
            flag = rec.info.declared_complete if rec.info is not None else None
            if flag is None:
                missing += 1
                continue
            if not flag:
                not_declared += 1
                continue
            declared += 1
            if rec.score.sr == 1.0:
                successes += 1
            else:
                wrong_fracs.append(1.0 - rec.score.pa)
        out[s] = {
            "declared": declared,
            "declared_successful": successes,
            "not_declared": not_declared,
            "no_report": missing,
            "median_incorrect_fraction_of_failed_claims": 100 * float(np.median(wrong_fracs)) if wrong_fracs else None,
        }
    return out
