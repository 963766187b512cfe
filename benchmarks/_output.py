"""Where a benchmark writes: a file in the output folder the user names (``--out DIR``), never
over an existing file (the recorded results in ``benchmarks/results/`` included)."""

from __future__ import annotations

from pathlib import Path


def output_file(out_dir: str | Path, name: str) -> Path:
    """``out_dir/name`` (the folder is created); exits with a one-line error if it exists already."""
    path = Path(out_dir) / name
    if path.exists():
        raise SystemExit(f"{path}: exists already; name another --out folder (benchmarks never overwrite results)")
    path.parent.mkdir(parents=True, exist_ok=True)
    return path
