"""Statistics of Appendix B.1: the benchmark design and eq.-3 weights, the object bootstrap,
paired randomization tests with Holm's correction, and paired reference effects. NumPy only."""

from aw_eval.stats.bootstrap import (
    DEFAULT_DRAWS,
    BootstrapResult,
    bootstrap_overall,
    draw_weights,
    object_counts,
    paired_object_bootstrap,
    percentile_interval,
)
from aw_eval.stats.design import CONDITION_ORDER, SOURCE_ORDER, Design, TaskMeta, ordered_sources
from aw_eval.stats.randomization import (
    DEFAULT_PERMUTATIONS,
    PairTest,
    holm,
    object_contributions,
    pairwise_tests,
    randomization_pvalues,
    smallest_pvalue,
)
from aw_eval.stats.reference import ReferenceEffect, paired_objects, reference_effects
from aw_eval.stats.weighted import weighted_mean, weighted_median

__all__ = [
    "DEFAULT_DRAWS",
    "DEFAULT_PERMUTATIONS",
    "BootstrapResult",
    "CONDITION_ORDER",
    "Design",
    "PairTest",
    "ReferenceEffect",
    "SOURCE_ORDER",
    "TaskMeta",
    "bootstrap_overall",
    "draw_weights",
    "holm",
    "object_contributions",
    "object_counts",
    "ordered_sources",
    "paired_object_bootstrap",
    "paired_objects",
    "pairwise_tests",
    "percentile_interval",
    "randomization_pvalues",
    "reference_effects",
    "smallest_pvalue",
    "weighted_mean",
    "weighted_median",
]
