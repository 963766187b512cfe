"""The bidirectional refinement section of report.md (and so of report.html) and its paired
log-log scatter of shape CD; self-contained, fed by :mod:`aw_eval.analyses.refinement`.

When RUNS is a refinement study this section is the report's first, and its table the
headline (:func:`refinement_headline`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from aw.formats.io import atomic_path
from aw.runner.refinement_study import REFINER_ARMS

__all__ = ["REFINEMENT_TITLE", "refinement_headline", "render_refinement", "write_refinement_plot"]

__all__ = ["REFINEMENT_TITLE", "refinement_headline", "render_refinement", "write_refinement_plot"]

REFINEMENT_TITLE = "Bidirectional refinement"
PLOT_NAME = "refinement_paired_cd.png"
CD_FLOOR = 1e-9  # a CD of exactly 0 is drawn at this value (log axes)
IMPROVED, OTHER = "#55A868", "#C44E52"


def write_refinement_plot(section: dict[str, Any], out_dir: Path) -> str | None:
    """``out_dir/refinement_paired_cd.png``: per-task shape CD after vs before, one panel per
    composition order, the legend below the panels (never over a point); None when nothing is
    matched."""
    if not section.get("matched"):
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    out_dir.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, len(section["scatter"]), figsize=(5.2 * len(section["scatter"]), 4.6), squeeze=False)
    labels = {a: v["label"] for a, v in section["arms"].items()}
    for ax, panel in zip(axes[0], section["scatter"], strict=True):
        x = np.maximum(np.asarray(panel["x"], float), CD_FLOOR)
        y = np.maximum(np.asarray(panel["y"], float), CD_FLOOR)
        lo, hi = float(min(x.min(), y.min())) / 2, float(max(x.max(), y.max())) * 2
        ax.plot([lo, hi], [lo, hi], color="#888888", lw=1, ls="--")
        better = np.asarray(panel["y"], float) < np.asarray(panel["x"], float) - section["tolerance"]
        ax.scatter(x[better], y[better], s=18, color=IMPROVED)
        ax.scatter(x[~better], y[~better], s=18, color=OTHER)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
        ax.set_xlabel(f"shape CD, {labels[panel['before']]}")
        ax.set_ylabel(f"shape CD, {labels[panel['after']]}")
        ax.set_title(f"{labels[panel['after']]} against {labels[panel['before']]}")
    keys = [
        Line2D([], [], ls="", marker="o", color=IMPROVED, label="improved (below the diagonal)"),
        Line2D([], [], ls="", marker="o", color=OTHER, label="unchanged or worse"),
        Line2D([], [], color="#888888", lw=1, ls="--", label="no change"),
    ]
    fig.tight_layout()
    fig.legend(handles=keys, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=3, fontsize=8, frameon=False)
    path = out_dir / PLOT_NAME
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110, bbox_inches="tight")
    finally:
        plt.close(fig)
    return path.name


def _f(x: float | None, scale: float = 1.0, digits: int = 2) -> str:
    return "-" if x is None or not np.isfinite(x) else f"{scale * x:.{digits}f}"


def _returned_start(row: dict[str, Any], arm: str) -> str:
    """``"7 of 20"`` for an arm that ends with the refiner, ``-`` for the others."""
    if arm not in REFINER_ARMS or "returned_start" not in row:
        return "-"
    unknown = row.get("returned_start_unknown", 0)
    return f"{row['returned_start']} of {row['n']}" + (f" ({unknown} not recorded)" if unknown else "")


def refinement_headline(section: dict[str, Any]) -> str:
    """The report's headline bullet for a refinement study: each arm's PA and CD in the four-arm
    table ("" when the study could not be read)."""
    if "error" in section:
        return ""
    n = len(section["matched"])
    arms = "; ".join(
        f"{section['arms'][arm]['label']} `{row['system']}` PA {_f(row.get('pa'), 100)}%, CD "
        f"{_f(row.get('cd'), 1000, 3)}"
        for arm, row in section["table"].items()
    )
    return (
        f"- **Headline: the four-arm table** ({REFINEMENT_TITLE}, the first section; fracture protocol, the "
        f"{n} of {section['tasks']} tasks where every arm finished): {arms}. Table 1 and the sections after it "
        "score the same runs by the benchmark's protocol, which counts a part correct differently (see below the "
        "four-arm table)."
    )


def _why_table1_differs(section: dict[str, Any]) -> str:
    ratios = sorted(
        r["divisor"] / r["benchmark_divisor"] for r in section["per_task"].values() if "benchmark_divisor" in r
    )
    looser = (
        f" Here the fracture protocol's unit is a median {ratios[len(ratios) // 2]:.1f} times the benchmark's, so "
        "a part passes it that many times farther from its target."
        if ratios
        else ""
    )
    return (
        "**Why Table 1's PA differs from this table's.** Both count a part correct at a Chamfer distance of "
        "0.01, but in different units and after different alignments. Table 1 uses the benchmark's protocol: the "
        "whole assembly registered onto the target by one rigid transform, parts matched within equivalence "
        "groups, distances in units of the largest part's bounding-box diagonal. This table uses the fracture "
        "protocol: the anchor part put exactly on its target, part identities fixed, distances in units of "
        "max(1, e) times the task scale, e the object's extent in its source units (its divisor)." + looser
    )


def render_refinement(section: dict[str, Any], plot: str | None = None) -> str:
    """Markdown: the four-arm table (RE degrees, TE x100, PA %, CD x1000, refiner outputs equal to
    their start), why Table 1's PA differs, the paired counts, the failures, and the scatter."""
    out = [f"## {REFINEMENT_TITLE}", ""]
    if "error" in section:
        return "\n".join(out + [f"Not scored: {section['error']}", ""])
    n = len(section["matched"])
    out.append(
        f"Agent `{section['agent']}`, refiner `{section['refiner']}`: fracture protocol (5000 shared "
        f"area-weighted samples, at least 20 a part; anchor-aligned), over the {n} of {section['tasks']} tasks "
        "where all four arms finished. Arrows give the order of execution. 'Returned start': tasks on which the "
        f"refiner's answer equals its start within {section['same_as_start']:g} (it found nothing "
        "better, so the arm's state is its first stage's)."
    )
    out += [
        "",
        "| Method | System | RE (deg) | TE (x100) | PA (%) | CD (x1000) | returned start | failed runs |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for arm, row in section["table"].items():
        out.append(
            f"| {section['arms'][arm]['label']} | `{row['system']}` | {_f(row.get('re'))} | {_f(row.get('te'), 100)} | "
            f"{_f(row.get('pa'), 100)} | {_f(row.get('cd'), 1000, 3)} | {_returned_start(row, arm)} | "
            f"{row['failed']} |"
        )
    out += ["", _why_table1_differs(section)]
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
