"""The bidirectional refinement section of report.md (and so of report.html) and its paired
log-log scatter of shape CD; self-contained, fed by :mod:`aw_eval.analyses.refinement`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from aw.formats.io import atomic_path

__all__ = ["render_refinement", "write_refinement_plot"]

PLOT_NAME = "refinement_paired_cd.png"
CD_FLOOR = 1e-9  # a CD of exactly 0 is drawn at this value (log axes)


def write_refinement_plot(section: dict[str, Any], out_dir: Path) -> str | None:
    """``out_dir/refinement_paired_cd.png``: per-task shape CD after vs before, one panel per
    composition order; None when nothing is matched."""
    if not section.get("matched"):
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, len(section["scatter"]), figsize=(5.2 * len(section["scatter"]), 4.6), squeeze=False)
    labels = {a: v["label"] for a, v in section["arms"].items()}
    for ax, panel in zip(axes[0], section["scatter"], strict=True):
        x = np.maximum(np.asarray(panel["x"], float), CD_FLOOR)
        y = np.maximum(np.asarray(panel["y"], float), CD_FLOOR)
        lo, hi = float(min(x.min(), y.min())) / 2, float(max(x.max(), y.max())) * 2
        ax.plot([lo, hi], [lo, hi], color="#888888", lw=1, ls="--")
        better = np.asarray(panel["y"], float) < np.asarray(panel["x"], float) - section["tolerance"]
        ax.scatter(x[better], y[better], s=18, color="#55A868", label="improved (below the diagonal)")
        ax.scatter(x[~better], y[~better], s=18, color="#C44E52", label="unchanged or worse")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
        ax.set_xlabel(f"shape CD, {labels[panel['before']]}")
        ax.set_ylabel(f"shape CD, {labels[panel['after']]}")
        ax.set_title(f"{labels[panel['after']]} against {labels[panel['before']]}")
        ax.legend(loc="upper left", fontsize=8)
    path = out_dir / PLOT_NAME
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110, bbox_inches="tight")
    finally:
        plt.close(fig)
    return path.name


def _f(x: float | None, scale: float = 1.0, digits: int = 2) -> str:
    return "-" if x is None or not np.isfinite(x) else f"{scale * x:.{digits}f}"


def render_refinement(section: dict[str, Any], plot: str | None = None) -> str:
    """Markdown: the four-arm table (RE degrees, TE x100, PA %, CD x1000), the paired counts, the
    failures, and the scatter."""
    out = ["## Bidirectional refinement", ""]
    if "error" in section:
        return "\n".join(out + [f"Not scored: {section['error']}", ""])
    n = len(section["matched"])
    out.append(
        f"Agent `{section['agent']}`, refiner `{section['refiner']}`: fracture protocol (5000 shared "
        f"area-weighted samples, at least 20 a part; anchor-aligned), over the {n} of {section['tasks']} tasks "
        "where all four arms finished. Arrows give the order of execution."
    )
    out += [
        "",
        "| Method | System | RE (deg) | TE (x100) | PA (%) | CD (x1000) | failed runs |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for arm, row in section["table"].items():
        out.append(
            f"| {section['arms'][arm]['label']} | `{row['system']}` | {_f(row.get('re'))} | {_f(row.get('te'), 100)} | "
            f"{_f(row.get('pa'), 100)} | {_f(row.get('cd'), 1000, 3)} | {row['failed']} |"
        )
    out += [
        "",
        f"Paired per-task changes (unchanged: a difference within {section['tolerance']:g}):",
        "",
        "| Arm | Relative to | Metric | improved | degraded | unchanged |",
        "|---|---|---|---:|---:|---:|",
    ]
    names = {"pa": "PA", "cd": "shape CD"}
    for p in section["pairs"]:
        out.append(
            f"| {section['arms'][p['arm']]['label']} | {section['arms'][p['baseline']]['label']} | {names[p['metric']]} | "
            f"{p.get('improved', '-')} | {p.get('degraded', '-')} | {p.get('unchanged', '-')} |"
        )
    failed = {a: f for a, f in section["failures"].items() if f}
    if failed:
        out += ["", "Failed runs (left out of the table):", ""]
        for arm, tasks in failed.items():
            first = next(iter(tasks.items()))
            out.append(
                f"- {section['arms'][arm]['label']} (`{section['arms'][arm]['system']}`): {len(tasks)} "
                f"(first: {first[0]}: {first[1]})"
            )
    if plot:
        out += ["", f"![Paired shape CD, log-log; points below the diagonal improve]({plot})"]
    return "\n".join(out) + "\n"
