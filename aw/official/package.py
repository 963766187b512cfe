"""The official benchmark package (a local copy or Hugging Face snapshot of
``AssemblyWorld/AssemblyWorldBench``), read as assembly-world-bench ``data.py`` reads it::

    PKG/benchmark.json                 version 1, evaluation protocol, five blocks, sources
    PKG/<block.prompt_file>            the block's task text (SHA-256 in prompt_sha256)
    PKG/<data>/<repo name>/<config_id>/config.json                identity + samples
    PKG/<data>/<repo name>/<config_id>/<sample.episode>           initial episode archive
    PKG/<data>/<repo name>/<config_id>/cache/<slug>/evaluation.json
    PKG/<data>/<repo name>/<config_id>/cache/<slug>/reference/<mode>/pages.json (+ page images)

``<data>``, ``<repo name>`` (the last component of the block's ``repo_id``) and ``<config_id>``
come from the block. A sample is named by the pair (block, sample id): the two PartNet blocks
hold the same ids. :class:`OfficialPackage` also offers what rescoring an official run needs
(``evaluation_inputs``, ``final_state``, ``check_run``, ``check_attempt``).
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from aw.formats import Condition
from aw.formats.strict_json import read_json
from aw.official.archive import EpisodeArchive, read_archive
from aw.official.episode import read_part_episode
from aw.official.errors import MissingPackageFileError, PackageError
from aw.official.evaluation_cache import (
    CACHE_FILE,
    EVALUATION_PROTOCOL,
    SIMILARITY_POLICY,
    SIMILARITY_THRESHOLD,
    EvaluationInputs,
    read_evaluation,
)
from aw.official.ids import sample_slug

__all__ = [
    "REPO",
    "REVISION",
    "BENCHMARK_SHA256",
    "EXPECTED_SAMPLES",
    "BLOCKS",
    "BENCHMARK_EVALUATION",
    "REFERENCE_CONDITIONS",
    "Sample",
    "OfficialPackage",
    "file_sha256",
]

REPO = "AssemblyWorld/AssemblyWorldBench"
REVISION = "f351f0f6e9f8a314ec7593e847d07a45b776481e"  # the pinned dataset revision (data.py)
# The official benchmark's identity: the SHA-256 the official loader pins benchmark.json to
# (assembly-world-bench frozen.json at 22646c9).
BENCHMARK_SHA256 = "2e45070ffa1d3eafe4f1a127d0df96feda0244c00ea77e2e260b249b551b06c3"
BLOCKS = ("partnet-none", "partnet-final-image", "ikea-manualbook", "assemblybench-manualbook", "fantastic-breaks-none")
BENCHMARK_EVALUATION = {
    "protocol": EVALUATION_PROTOCOL,
    "similarity_policy": SIMILARITY_POLICY,
    "similarity_threshold": SIMILARITY_THRESHOLD,
}
EXPECTED_SAMPLES = 100
# A block's reference_mode as this project's task condition.
REFERENCE_CONDITIONS: dict[str, Condition] = {"none": "none", "final-image": "image", "manualbook": "manual"}
_HF_SNAPSHOT = re.compile(r"[0-9a-f]{40}")


def file_sha256(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


@dataclass
class Sample:
    """One (block, sample id) of the package and its files."""

    block: str
    sample_id: str
    expected: dict[str, Any]  # config.json sample entry: episode, episode_id, sha256, parts
    initial_path: Path
    evaluation_path: Path
    reference: dict[str, Any] | None  # pages.json, or None for reference_mode none
    pages: list[Path]

    @property
    def slug(self) -> str:
        return sample_slug(self.sample_id)

    @property
    def parts(self) -> int:
        return int(self.expected["parts"])


class OfficialPackage:
    """A benchmark package; with ``strict`` (default) exactly the five frozen blocks and 100
    samples, as the official loader demands, else any of the blocks in their order."""

    def __init__(self, root: str | Path, *, strict: bool = True):
        self.root = Path(root).resolve()
        path = self.root / "benchmark.json"
        if not path.is_file():
            raise PackageError(path, "benchmark.json not found (is this an official benchmark package?)")
        self.benchmark = self._json("benchmark.json")
        b = self.benchmark
        if not isinstance(b, dict) or b.get("version") != 1 or b.get("evaluation") != BENCHMARK_EVALUATION:
            raise PackageError(path, f"expected version 1 and evaluation {BENCHMARK_EVALUATION}")
        if not isinstance(b.get("blocks"), list) or not all(
            isinstance(x, dict) and isinstance(x.get("name"), str) for x in b["blocks"]
        ):
            raise PackageError(path, "blocks: expected a list of block objects with a name")
        names = tuple(x["name"] for x in b["blocks"])
        order_ok = names == BLOCKS if strict else (names and names == tuple(n for n in BLOCKS if n in names))
        if not order_ok:
            raise PackageError(
                path,
                f"blocks {list(names)}: expected {'exactly' if strict else 'some of'} {list(BLOCKS)} in that order",
            )
        if strict and sum(len(x.get("samples", {})) for x in b["blocks"]) != EXPECTED_SAMPLES:
            raise PackageError(path, f"expected {EXPECTED_SAMPLES} samples over the five blocks")
        need = (
            "source",
            "repo_id",
            "revision",
            "config_id",
            "data",
            "samples",
            "reference_mode",
            "prompt_file",
            "prompt_sha256",
        )
        for block in b["blocks"]:
            missing = [k for k in need if k not in block]
            if missing:
                raise PackageError(path, f"block {block['name']!r}: missing {missing}")
            if (
                not isinstance(block["reference_mode"], str)
                or block["reference_mode"] not in REFERENCE_CONDITIONS
                or not isinstance(block["samples"], dict)
                or not all(isinstance(v, dict) for v in block["samples"].values())
            ):
                raise PackageError(
                    path, f"block {block['name']!r}: reference_mode {block['reference_mode']!r} or samples malformed"
                )
            if block["source"] not in b.get("sources", []):
                raise PackageError(path, f"block {block['name']!r}: source {block['source']!r} is not one of sources")
        self.blocks: dict[str, dict[str, Any]] = {x["name"]: x for x in b["blocks"]}
        self._configs: dict[str, tuple[str, dict[str, Any], str]] = {}
        self._samples: dict[tuple[str, str], Sample] = {}
        self._inputs: dict[tuple[str, str], EvaluationInputs] = {}
        self._initials: dict[tuple[str, str], EpisodeArchive] = {}

    # --- files --------------------------------------------------------------------------------

    def path(self, relative: str) -> Path:
        """``relative`` inside the package; links may lead only into the package (or into a
        Hugging Face cache's blob store when the package is a snapshot)."""
        rel = Path(relative)
        if rel.is_absolute() or ".." in rel.parts:
            raise PackageError(self.root / "benchmark.json", f"path {relative!r} escapes the package")
        path = self.root / rel
        allowed = [self.root]
        repo = self.root.parent.parent
        if (
            self.root.parent.name == "snapshots"
            and _HF_SNAPSHOT.fullmatch(self.root.name)
            and repo.name.startswith("datasets--")
        ):
            allowed += [(repo / "blobs").resolve(), (repo.parent / "blobs").resolve()]
        if not any(path.resolve().is_relative_to(a) for a in allowed):
            raise PackageError(path, "links outside the package")
        if not path.is_file():
            raise MissingPackageFileError(path, "package file not found")
        return path

    def _json(self, relative: str) -> Any:
        return read_json(self.path(relative), error=PackageError)

    # --- blocks and samples -------------------------------------------------------------------

    def configuration(self, block: str) -> tuple[str, dict[str, Any], str]:
        """``(config folder, config.json, task text)`` of a block, checked against benchmark.json."""
        if block not in self.blocks:
            raise PackageError(self.root / "benchmark.json", f"unknown block {block!r} (blocks: {list(self.blocks)})")
        if block not in self._configs:
            b = self.blocks[block]
            folder = f"{b['data']}/{b['repo_id'].split('/')[-1]}/{b['config_id']}"
            cfg = self._json(f"{folder}/config.json")
            where = self.root / folder / "config.json"
            identity = cfg.get("identity") if isinstance(cfg, dict) else None
            samples = cfg.get("samples") if isinstance(cfg, dict) else None
            if not isinstance(identity, dict) or not isinstance(samples, dict):
                raise PackageError(where, "expected identity and samples objects")
            if (
                cfg.get("config_id") != b["config_id"]
                or identity.get("dataset") != b["repo_id"]
                or identity.get("revision") != b["revision"]
            ):
                raise PackageError(where, f"config_id / identity differ from block {block!r} in benchmark.json")
            if set(samples) != set(b["samples"]):
                raise PackageError(where, f"samples differ from block {block!r} in benchmark.json")
            for sid, entry in samples.items():
                if not isinstance(entry, dict) or any(
                    entry.get(k) != b["samples"][sid].get(k) for k in ("sha256", "parts", "episode_id")
                ):
                    raise PackageError(where, f"sample {sid!r}: sha256, parts or episode_id differ from benchmark.json")
            task_path = self.path(b["prompt_file"])
            task = task_path.read_bytes()
            if hashlib.sha256(task).hexdigest() != b["prompt_sha256"]:
                raise PackageError(task_path, f"task text differs from block {block!r} prompt_sha256")
            self._configs[block] = (folder, cfg, task.decode("utf-8"))
        return self._configs[block]

    def sample_ids(self, block: str) -> list[str]:
        """The block's sample ids in config.json order."""
        return list(self.configuration(block)[1]["samples"])

    def samples(self) -> list[tuple[str, str]]:
        """Every (block, sample id), blocks in benchmark order."""
        return [(block, sid) for block in self.blocks for sid in self.sample_ids(block)]

    def missing_files(self, samples: Iterable[tuple[str, str]]) -> list[Path]:
        """The files that the given (block, sample id) pairs need and the package lacks (a partly
        downloaded package), in sample order: a block's ``config.json``, each sample's initial
        archive (or the first missing reference page) and its ``evaluation.json``. Files that
        are there are checked as :meth:`configuration` and :meth:`sample` check them."""
        out: list[Path] = []
        lacking: set[str] = set()  # blocks whose config.json is missing: their samples cannot be checked
        for block, sid in samples:
            if block in lacking:
                continue
            try:
                folder, _, _ = self.configuration(block)
            except MissingPackageFileError as exc:
                out.append(exc.path)
                lacking.add(block)
                continue
            try:
                self.sample(block, sid)
            except MissingPackageFileError as exc:
                out.append(exc.path)
            evaluation = self.root / folder / "cache" / sample_slug(sid) / CACHE_FILE
            if not evaluation.is_file():
                out.append(evaluation)
        return out

    def require(self, samples: Iterable[tuple[str, str]], what: str = "the conversion") -> None:
        """:class:`MissingPackageFileError` naming every file of :meth:`missing_files`, if any."""
        missing = self.missing_files(samples)
        if missing:
            names = ", ".join(str(p.relative_to(self.root)) if p.is_relative_to(self.root) else str(p) for p in missing)
            raise MissingPackageFileError(
                self.root, f"{len(missing)} files {what} needs are not in the package (partly downloaded?): {names}"
            )

    def listed_samples(self) -> list[tuple[str, str]]:
        """Every (block, sample id) as ``benchmark.json`` lists them (no ``config.json`` read)."""
        return [(name, sid) for name, block in self.blocks.items() for sid in block["samples"]]

    def task_text(self, block: str) -> str:
        return self.configuration(block)[2]

    def sample(self, block: str, sample_id: str) -> Sample:
        """A sample's files; its initial archive's digest and reference pages are checked."""
        key = (block, sample_id)
        if key in self._samples:
            return self._samples[key]
        folder, cfg, _ = self.configuration(block)
        if sample_id not in cfg["samples"]:
            raise PackageError(self.root / folder / "config.json", f"block {block!r} has no sample {sample_id!r}")
        expected = cfg["samples"][sample_id]
        slug = sample_slug(sample_id, str(self.root / folder / "config.json"))
        initial = self.path(f"{folder}/{expected['episode']}")
        if file_sha256(initial) != expected["sha256"]:
            raise PackageError(initial, f"initial episode's SHA-256 differs from config.json ({block}/{sample_id})")
        b = self.blocks[block]
        reference, pages = None, []
        if b["reference_mode"] != "none":
            refdir = f"{folder}/cache/{slug}/reference/{b['reference_mode']}"
            reference = self._json(f"{refdir}/pages.json")
            where = self.root / refdir / "pages.json"
            if (
                not isinstance(reference, dict)
                or reference.get("dataset") != b["repo_id"]
                or reference.get("revision") != b["revision"]
                or reference.get("reference_mode") != b["reference_mode"]
                or not reference.get("pages")
            ):
                raise PackageError(where, "dataset, revision or reference_mode differ from the block, or no pages")
            for index, page in enumerate(reference["pages"], start=1):
                if not isinstance(page, dict) or not isinstance(page.get("file"), str):
                    raise PackageError(where, f"page {index}: expected an object with a file name")
                image = self.path(f"{refdir}/{page['file']}")
                if page.get("page") != index or file_sha256(image) != page.get("source_sha256"):
                    raise PackageError(where, f"page {index}: out of order or its SHA-256 differs")
                pages.append(image)
        sample = Sample(
            block, sample_id, expected, initial, self.root / folder / "cache" / slug / CACHE_FILE, reference, pages
        )
        self._samples[key] = sample
        return sample

    def evaluation_inputs(self, block: str, sample_id: str) -> EvaluationInputs:
        """The sample's checked ``evaluation.json``."""
        key = (block, sample_id)
        if key not in self._inputs:
            s = self.sample(block, sample_id)
            self.path(str(s.evaluation_path.relative_to(self.root)))
            _, cfg, _ = self.configuration(block)
            self._inputs[key] = read_evaluation(
                s.evaluation_path,
                sample_id=sample_id,
                identity=cfg["identity"],
                initial_sha256=s.expected["sha256"],
                parts=s.parts,
            )
        return self._inputs[key]

    def initial_archive(self, block: str, sample_id: str) -> EpisodeArchive:
        key = (block, sample_id)
        if key not in self._initials:
            s = self.sample(block, sample_id)
            arc = read_archive(s.initial_path)
            if arc.manifest["id"] != s.expected["episode_id"]:
                raise PackageError(
                    s.initial_path, f"manifest id {arc.manifest['id']!r} differs from config.json episode_id"
                )
            self._initials[key] = arc
        return self._initials[key]

    def final_state(self, block: str, sample_id: str, archive: str | Path) -> tuple[np.ndarray, int]:
        """``(poses (P, 7) in part_ids order, state index)`` of a final archive's last state,
        checked as a continuation of the sample's initial archive."""
        inputs = self.evaluation_inputs(block, sample_id)
        ep = read_part_episode(archive, self.initial_archive(block, sample_id), inputs.part_ids)
        return ep.final_poses(), ep.final_index

    # --- run logs -----------------------------------------------------------------------------

    def check_run(self, run) -> None:
        """A run's ``run.json`` (``aw.official.runlog.RunLog``) must use this package's task texts,
        reference modes and samples."""
        where = Path(run.path) / "run.json"
        for block, ids in run.selection.items():
            if block not in self.blocks:
                raise PackageError(where, f"selection names block {block!r}, which the package lacks")
            if (run.meta.get("tasks") or {}).get(block) != self.task_text(block):
                raise PackageError(where, f"tasks[{block!r}] differs from the package's task text")
            if (run.meta.get("reference_modes") or {}).get(block) != self.blocks[block]["reference_mode"]:
                raise PackageError(where, f"reference_modes[{block!r}] differs from the package's")
            unknown = sorted(set(ids) - set(self.blocks[block]["samples"]))
            if unknown:
                raise PackageError(where, f"block {block!r}: samples {unknown} are not in the package")

    def check_attempt(self, attempt) -> None:
        """A sample's ``input.json`` (``aw.official.runlog.SampleAttempt``) must name this
        package's sample: id, block, identity, initial digest, episode id and part count."""
        where = Path(attempt.directory) / "input.json"
        inputs = attempt.inputs
        _, cfg, _ = self.configuration(attempt.block)
        expected = cfg["samples"].get(attempt.sample_id)
        if (
            expected is None
            or inputs.get("sample_id") != attempt.sample_id
            or inputs.get("block") != attempt.block
            or inputs.get("identity") != cfg["identity"]
            or any(inputs.get(k) != expected.get(k) for k in ("sha256", "episode_id", "parts"))
        ):
            raise PackageError(where, "the run's input identity differs from the package's sample")
