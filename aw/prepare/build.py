"""Turning assembled objects into tasks: one object (all its conditions and variants) at a time."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from aw.assembly import AssembledObject
from aw.formats import CONDITIONS, SuiteEntry, as_condition
from aw.prepare.references import IMAGE_SIZE, MANUAL_SIZE, reference_images
from aw.prepare.standardize import PreparedObject, assembled_at_start, standardize
from aw.prepare.variants import add_distractor, layout_variant, remove_part
from aw.prepare.writer import task_id_for, write_prepared

__all__ = ["VariantPlan", "prepare_object", "CONDITIONS", "PROTOCOLS"]

PROTOCOLS = ("official", "native")


@dataclass(frozen=True)
class VariantPlan:
    """Which robustness variants (Appendix E) to add next to the original tasks.

    ``layout_seeds``: one alternative layout per seed. ``missing_seed``: remove one part
    (objects with at least 3 parts). ``distractor_seed``: add one part of the ``donor`` object
    given to :func:`prepare_object`. Every condition of the object gets the same variants.
    """

    layout_seeds: tuple[int, ...] = ()
    missing_seed: int | None = None
    distractor_seed: int | None = None

    @classmethod
    def appendix_e(cls, seed: int = 0) -> VariantPlan:
        """The paper's set: two alternative layouts, one removed part, one distractor."""
        return cls(layout_seeds=(seed + 1001, seed + 1002), missing_seed=seed + 2001, distractor_seed=seed + 3001)


def _check_assessable(prep: PreparedObject) -> None:
    """Refuse a layout in which parts are already assembled: they would score without a move."""
    together = assembled_at_start(prep)
    if not together:
        return
    n = len(prep.scored_parts)
    what = (
        f"its one part {together[0]} is on its target after the registration"
        if n == 1
        else f"{len(together)} of its {n} parts ({', '.join(together)}) are already assembled in the initial layout"
    )
    raise ValueError(
        f"object {prep.obj.object_id} cannot be assessed: {what}, so an agent that never moves scores them as placed"
    )


def prepare_object(
    obj: AssembledObject,
    suite_dir: str | Path,
    conditions: Sequence[str] = ("none",),
    seed: int = 0,
    *,
    variants: VariantPlan | None = None,
    donor: AssembledObject | None = None,
    image_size: tuple[int, int] = IMAGE_SIZE,
    manual_size: tuple[int, int] = MANUAL_SIZE,
    protocol: str = "native",
) -> list[SuiteEntry]:
    """Write every task of ``obj`` into ``suite_dir`` and return their manifest entries.

    All conditions share the standardized geometry, layout, ids and targets (seed ``seed``);
    references are rendered (or copied from the source) once per condition and shared by the
    condition's variants. Task ids: ``<source>-<object>-<condition>[-<variant>]``.

    ``protocol``: ``native`` (this project's standardization, :func:`standardize`) or
    ``official`` (the official preparation, :mod:`aw.prepare.official_task`: its layout, part ids,
    and ``eval_points/<task_id>.npz`` with its points, divisor and groups; no variants).
    """
    asked = list(dict.fromkeys(conditions))
    bad = [c for c in asked if c not in CONDITIONS]
    if bad or not asked:
        raise ValueError(f"conditions must be a non-empty subset of {CONDITIONS}, got {asked}")
    checked = [as_condition(c) for c in asked]
    if protocol not in PROTOCOLS:
        raise ValueError(f"protocol must be one of {PROTOCOLS}, got {protocol!r}")
    official = None
    if protocol == "official":
        if variants is not None:
            raise ValueError("the robustness variants are built by the native protocol only")
        from aw.prepare.official_task import prepare_official_object

        prep, official = prepare_official_object(obj, seed)
    else:
        prep = standardize(obj, seed)
    _check_assessable(prep)
    refs = {c: reference_images(prep, c, image_size, manual_size) for c in checked}

    derived: list[tuple[str, PreparedObject]] = []
    if variants is not None:
        for k, layout_seed in enumerate(variants.layout_seeds, start=1):
            derived.append((f"layout{k}", layout_variant(obj, layout_seed)))
            _check_assessable(derived[-1][1])
        if variants.missing_seed is not None and obj.n_parts >= 3:
            derived.append(("missing", remove_part(prep, variants.missing_seed)))
        if variants.distractor_seed is not None:
            if donor is None:
                raise ValueError(f"object {obj.object_id}: a distractor variant needs a donor object")
            derived.append(("distractor", add_distractor(prep, donor, variants.distractor_seed)))

    entries = []
    for cond in checked:
        base_id = task_id_for(obj.source, obj.object_id, cond)
        entries.append(write_prepared(prep, suite_dir, base_id, cond, refs[cond]))
        if official is not None:
            from aw.prepare.official_task import write_eval_points

            write_eval_points(suite_dir, base_id, official)
        for suffix, vprep in derived:
            vid = task_id_for(obj.source, obj.object_id, cond, suffix)
            entries.append(write_prepared(vprep, suite_dir, vid, cond, refs[cond], base_task_id=base_id))
    return entries
