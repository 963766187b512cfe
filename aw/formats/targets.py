"""The hidden targets file, one per task (``<suite>/targets/<task_id>.json``). Only scoring reads it."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from aw.formats.common import PoseList, VariantKind
from aw.formats.io import read_model, write_json_atomic


class PartTarget(BaseModel):
    model_config = ConfigDict(extra="forbid")
    pose: PoseList = Field(description="maps the baked part mesh onto the assembled object")
    source_name: str = Field(default="", description="the part's name in the source dataset")
    distractor: bool = Field(default=False, description="added from another object; excluded from scoring")


class Variant(BaseModel):
    """Robustness variant of Appendix E (none for the original task)."""

    model_config = ConfigDict(extra="forbid")
    kind: VariantKind = "original"
    base_task_id: str | None = None
    layout_seed: int | None = None
    removed_source_names: list[str] = Field(default_factory=list)
    distractor_from: str | None = None


class Targets(BaseModel):
    model_config = ConfigDict(extra="forbid")
    format: Literal["assemblyworld.targets"] = "assemblyworld.targets"
    format_version: Literal[1] = 1
    task_id: str
    parts: dict[str, PartTarget] = Field(min_length=1)
    equivalence_hint: list[list[str]] | None = Field(
        default=None, description="dataset-provided groups of interchangeable parts (informational)"
    )
    scale: float = Field(gt=0, description="normalization scale applied to the source geometry")
    eval_divisor: float | None = Field(
        default=None,
        gt=0,
        description="evaluation scale divisor in baked-mesh units; set when it must not be recomputed "
        "from the task's parts (missing-part variants keep the original object's scale)",
    )
    seed: int = 0
    variant: Variant = Field(default_factory=Variant)

    @model_validator(mode="after")
    def _check(self) -> Targets:
        if self.equivalence_hint:
            for group in self.equivalence_hint:
                unknown = [p for p in group if p not in self.parts]
                if unknown:
                    raise ValueError(f"equivalence_hint names unknown parts {unknown}")
        return self

    @property
    def scored_part_ids(self) -> list[str]:
        return [pid for pid, t in self.parts.items() if not t.distractor]


def read_targets(path: str | Path) -> Targets:
    return read_model(Targets, path)


def write_targets(path: str | Path, targets: Targets) -> None:
    write_json_atomic(path, targets)
