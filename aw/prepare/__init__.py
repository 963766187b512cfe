"""Standardized task construction (Appendix A.1) and the robustness variants (Appendix E).

``standardize`` turns an :class:`~aw.assembly.AssembledObject` into baked part meshes, anonymized
ids and hidden target poses; ``prepare_object`` writes its tasks (every condition, optional
variants) into a suite; ``build_suite`` does that for many objects and writes the manifest.
"""

from aw.prepare.build import CONDITIONS, VariantPlan, prepare_object
from aw.prepare.geometry import eval_divisor, part_size_ratio, pca_bbox_diagonal, unique_vertices
from aw.prepare.layout import MIN_GAP, box_gap
from aw.prepare.standardize import PreparedObject, PreparedPart, normalization_divisor, standardize
from aw.prepare.suite import ObjectError, ObjectSpec, SuiteExistsError, build_suite, format_summary, summarize
from aw.prepare.variants import add_distractor, layout_variant, remove_part
from aw.prepare.writer import task_id_for, write_prepared

__all__ = [
    "CONDITIONS",
    "MIN_GAP",
    "ObjectError",
    "ObjectSpec",
    "PreparedObject",
    "PreparedPart",
    "SuiteExistsError",
    "VariantPlan",
    "add_distractor",
    "box_gap",
    "build_suite",
    "eval_divisor",
    "format_summary",
    "layout_variant",
    "normalization_divisor",
    "part_size_ratio",
    "pca_bbox_diagonal",
    "prepare_object",
    "remove_part",
    "standardize",
    "summarize",
    "task_id_for",
    "unique_vertices",
    "write_prepared",
]
