"""The suite manifest: ``<suite>/manifest.json`` next to ``tasks/`` and ``targets/``."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from aw.formats.common import MAX_CATEGORY_CHARS, Condition, VariantKind
from aw.formats.errors import FormatError
from aw.formats.io import read_model, write_json_atomic


class SuiteEntry(BaseModel):
    model_config = ConfigDict(extra="forbid")
    task_id: str
    source: str
    condition: Condition
    object_id: str
    category: str = Field(default="", max_length=MAX_CATEGORY_CHARS)
    n_parts: int = Field(ge=1)
    weight: float = Field(default=1.0, gt=0)
    variant: VariantKind = "original"
    base_task_id: str | None = None


class SuiteManifest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    format: Literal["assemblyworld.suite"] = "assemblyworld.suite"
    format_version: Literal[1] = 1
    name: str
    generator: str = ""
    seed: int = 0
    tasks: list[SuiteEntry]

    @model_validator(mode="after")
    def _check(self) -> SuiteManifest:
        ids = [t.task_id for t in self.tasks]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"duplicate task ids {dup}")
        return self

    def select(self, wanted: list[str] | None) -> list[str]:
        """The task ids in suite order, or those of ``wanted`` (None or empty: every task);
        :class:`ValueError` naming the ids of ``wanted`` that the suite lacks."""
        ids = [t.task_id for t in self.tasks]
        if not wanted:
            return ids
        unknown = [t for t in wanted if t not in set(ids)]
        if unknown:
            raise ValueError(f"tasks not in the suite: {', '.join(unknown)}")
        return [t for t in ids if t in set(wanted)]

    def entry(self, task_id: str) -> SuiteEntry:
        for t in self.tasks:
            if t.task_id == task_id:
                return t
        raise KeyError(task_id)


def suite_paths(suite_dir: str | Path, task_id: str) -> tuple[Path, Path]:
    """(task directory, targets file) of one task in a suite."""
    suite_dir = Path(suite_dir)
    return suite_dir / "tasks" / task_id, suite_dir / "targets" / f"{task_id}.json"


def read_manifest(suite_dir: str | Path) -> SuiteManifest:
    suite_dir = Path(suite_dir)
    if not suite_dir.is_dir():
        raise FormatError(suite_dir, "suite directory not found")
    return read_model(SuiteManifest, suite_dir / "manifest.json")


def write_manifest(suite_dir: str | Path, manifest: SuiteManifest) -> None:
    write_json_atomic(Path(suite_dir) / "manifest.json", manifest)
