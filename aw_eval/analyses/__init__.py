"""The paper's analyses, one module each, all reading a scored :class:`aw_eval.study.Study`.

=================  ===========================================================================
module             what
=================  ===========================================================================
benchmark          Table 1: per-cell/source/Overall quality, resource means, run outcomes
uncertainty        bootstrap intervals, pairwise tests with Holm, paired reference effects
thresholds         correctness-threshold sweep with registration and matching fixed
failures           geometric failure classes and their sensitivity grid (Appendix C.2)
dynamics           activity shares, manipulation magnitudes, early/late stages, revisits (C.1)
curves             quality over normalized time and absolute budgets; PA decreases
scd_tail           SCD concentration of the top ceil(0.05 N)
part_scale         part-size ratios per source
part_count         part-count bands
categories         results per category
completion         declared completion vs geometric success
robustness         layout / distractor / missing-part variants paired with originals
roles              which systems are real, calibration (read the targets) or floor (no attempt)
=================  ===========================================================================
"""

from aw_eval.analyses.benchmark import outcomes, quality, resources
from aw_eval.analyses.categories import category_results
from aw_eval.analyses.completion import completion_reports
from aw_eval.analyses.curves import pa_decreases, quality_curves
from aw_eval.analyses.dynamics import dynamics
from aw_eval.analyses.failures import failure_analysis
from aw_eval.analyses.part_count import part_count_bands
from aw_eval.analyses.part_scale import part_scale
from aw_eval.analyses.robustness import robustness
from aw_eval.analyses.roles import system_roles
from aw_eval.analyses.scd_tail import scd_tail
from aw_eval.analyses.thresholds import threshold_sweep
from aw_eval.analyses.uncertainty import system_order, uncertainty

__all__ = [
    "category_results",
    "completion_reports",
    "dynamics",
    "failure_analysis",
    "outcomes",
    "pa_decreases",
    "part_count_bands",
    "part_scale",
    "quality",
    "quality_curves",
    "resources",
    "robustness",
    "scd_tail",
    "system_order",
    "system_roles",
    "threshold_sweep",
    "uncertainty",
]
