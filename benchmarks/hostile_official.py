"""Run ``aw-score PKG RUNS`` and ``aw-prepare official`` on every hostile official file of
``tests/aw/official/hostile.py`` (plus a 300 MiB array in one call's arguments) as real
commands, and record for each: exit status, the one error line (or the error row), whether a
traceback appeared, what was left in the output folders and the peak memory of the process::

    .venv/bin/python benchmarks/hostile_official.py --out OUT

Nothing here is timed against a limit; the figures are what docs/formats.md cites.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import psutil

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aw.official.package import OfficialPackage  # noqa: E402
from benchmarks._output import output_file  # noqa: E402
from tests.aw.official import hostile  # noqa: E402
from tests.aw.official.builders import write_package  # noqa: E402
from tests.aw.official.hostile import SAMPLE, VARIANTS, Variant, good_run  # noqa: E402

BIN = Path(sys.executable).parent


def _numbers(n_bytes: int, seed: int = 0) -> bytes:
    """A JSON array of about ``n_bytes``: random 8-digit numbers, so that it compresses as real
    numbers do (about 2.4:1) and passes the compression-ratio check."""
    n = n_bytes // 11
    text = np.empty((n, 11), dtype=np.uint8)
    text[:, 0], text[:, 1], text[:, 10] = ord("0"), ord("."), ord(",")
    text[:, 2:10] = np.random.default_rng(seed).integers(ord("0"), ord("9") + 1, size=(n, 8), dtype=np.uint8)
    return b"[" + text.tobytes() + b"0]"


def _big_arguments(name: str, n_bytes: int, calls: slice, message: str, archive: bool) -> Variant:
    """The arguments of the calls ``calls`` each hold an array of ``n_bytes`` of JSON text."""

    def damage(run: Path, scratch: Path) -> None:
        path = hostile._final(run)
        files = hostile._members(path)
        rows = files["calls.jsonl"].split(b"\n")
        for k in range(len(rows))[calls]:
            row = json.loads(rows[k])
            row["arguments"] = {"x": "@BIG@"}
            rows[k] = json.dumps(row).encode().replace(b'"@BIG@"', _numbers(n_bytes, k))
        files["calls.jsonl"] = b"\n".join(rows)
        hostile._rezip(path, files)
        hostile._rehash_result(run)

    return Variant(name, damage, message, archive)


def _run(cmd: list[str]) -> dict:
    """Run ``cmd``; its exit status, stderr, wall time and peak RSS (sampled every 20 ms)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    peak = [0]

    def sample() -> None:
        p = psutil.Process(proc.pid)
        while proc.poll() is None:
            try:
                peak[0] = max(peak[0], sum(x.memory_info().rss for x in [p, *p.children(recursive=True)]))
            except psutil.Error:
                pass
            time.sleep(0.02)

    watcher = threading.Thread(target=sample, daemon=True)
    watcher.start()
    out, err = proc.communicate()
    watcher.join()
    return {
        "code": proc.returncode,
        "stderr": err,
        "stdout": out,
        "seconds": round(time.perf_counter() - t0, 2),
        "peak_rss_mb": round(peak[0] / 1e6, 1),
    }


def _error_line(err: str, prog: str) -> str | None:
    lines = [x for x in err.splitlines() if x.startswith(f"{prog}: error:")]
    return lines[0] if len(lines) == 1 else None


def _row_error(out: Path) -> str | None:
    for metrics in out.glob("official/*/metrics.jsonl"):
        rows = [json.loads(x) for x in metrics.read_text().splitlines() if x.strip()]
        return rows[0].get("error") if rows else None
    return None


def trial(variant: Variant, pkg: OfficialPackage, pristine: Path, work: Path) -> dict:
    logs = work / "logs"
    shutil.copytree(pristine.parent, logs, symlinks=True)
    (work / "scratch").mkdir()
    variant.damage(logs / pristine.name, work / "scratch")
    archive = logs / pristine.name / "blocks" / SAMPLE[0] / "samples" / SAMPLE[1] / "final.episode.zip"
    rec = {
        "variant": variant.name,
        "expected": variant.message,
        "archive_mb": round(archive.stat().st_size / 1e6, 2) if archive.exists() else None,
    }
    out = work / "out"
    s = _run([str(BIN / "aw-score"), str(pkg.root), str(logs), "--out", str(out), "--jobs", "1"])
    said = _row_error(out) if variant.archive else _error_line(s["stderr"], "aw-score")
    try:
        rec["calls_jsonl_mb"] = round(len(hostile._members(archive)["calls.jsonl"]) / 1e6, 1)
    except Exception:  # a damaged archive
        rec["calls_jsonl_mb"] = None
    rec["aw_score"] = {
        "code": s["code"],
        "said": said,
        "traceback": "Traceback" in s["stderr"],
        "named": bool(said) and variant.message in said,
        "seconds": s["seconds"],
        "peak_rss_mb": s["peak_rss_mb"],
        "left_partial": bool(list(out.glob(".official*"))),
    }
    suite, runs = work / "suite", work / "runs"
    p = _run(
        [
            str(BIN / "aw-prepare"),
            "official",
            str(pkg.root),
            "--episodes",
            str(logs),
            "--out",
            str(suite),
            "--runs",
            str(runs),
        ]
    )
    said = _error_line(p["stderr"], "aw-prepare")
    rec["aw_prepare"] = {
        "code": p["code"],
        "said": said,
        "traceback": "Traceback" in p["stderr"],
        "named": bool(said) and variant.message in said,
        "seconds": p["seconds"],
        "peak_rss_mb": p["peak_rss_mb"],
        "left_suite": (suite / "manifest.json").exists(),
        "left_runs": runs.exists() and any(runs.iterdir()),
    }
    return rec


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="folder for hostile_official.json")
    ap.add_argument("--huge-mib", type=int, default=300, help="size of the array in one call's arguments (MiB of JSON)")
    args = ap.parse_args()
    target = output_file(args.out, "hostile_official.json")
    root = Path(tempfile.mkdtemp(prefix="aw-hostile-"))
    try:
        pkg = OfficialPackage(write_package(root / "pkg", {SAMPLE[0]: [SAMPLE[1]]}), strict=False)
        pristine = good_run(pkg, root / "good" / "logs")
        trials = []
        huge = _big_arguments(
            f"arguments-{args.huge_mib}MiB-array", args.huge_mib << 20, slice(0, 1), "over the limit of 67108864", True
        )
        # the most the limits let through: every call's arguments just under the row limit
        largest = _big_arguments("largest-accepted", (4 << 20) - 4096, slice(None), "", True)
        for k, variant in enumerate([*VARIANTS, huge, largest]):
            rec = trial(variant, pkg, pristine, root / f"t{k:02d}")
            trials.append(rec)
            print(
                json.dumps(
                    {k: rec[k] for k in ("variant", "archive_mb")}
                    | {
                        c: {x: rec[c][x] for x in ("code", "named", "traceback", "peak_rss_mb")}
                        for c in ("aw_score", "aw_prepare")
                    }
                ),
                flush=True,
            )
            shutil.rmtree(root / f"t{k:02d}", ignore_errors=True)
        hostile_trials = trials[:-1]
        ok = sum(r[c]["named"] and not r[c]["traceback"] for r in hostile_trials for c in ("aw_score", "aw_prepare"))
        doc = {
            "command": " ".join(["benchmarks/hostile_official.py", *sys.argv[1:]]),
            "variants": len(hostile_trials),
            "named_one_line_errors": ok,
            "of": 2 * len(hostile_trials),
            "trials": hostile_trials,
            "largest_accepted": trials[-1],
        }
        target.write_text(json.dumps(doc, indent=1) + "\n")
        print(f"{len(hostile_trials)} variants: {ok}/{2 * len(hostile_trials)} named one-line errors; wrote {target}")
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
