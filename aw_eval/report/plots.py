"""PNG plots of a ``scores.json`` document (matplotlib, Agg backend): quality over normalized
time and over absolute budgets, threshold sensitivity, activity shares, manipulation magnitudes,
reference-effect intervals. Each function returns the written path or None when the study has
no data for it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from aw.formats.io import atomic_path

matplotlib.use("Agg")  # files only: no display is needed or wanted, even where one exists

__all__ = ["write_plots"]

_DPI = 110
_KIND_COLORS = {"inspect": "#4C72B0", "observe": "#55A868", "manipulate": "#C44E52", "other": "#8C8C8C"}


def _systems(doc: dict[str, Any]) -> list[str]:
    return doc["uncertainty"].get("order") or list(doc["systems"])


def _colors(n: int):
    cmap = plt.get_cmap("tab10" if n <= 10 else "tab20")
    return [cmap(i % cmap.N) for i in range(n)]


def _save(fig, path: Path) -> str:
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=_DPI, bbox_inches="tight")
    finally:
        plt.close(fig)
    return path.name


def _quality_normalized(doc, path: Path) -> str | None:
    cv = doc["curves"]
    if not cv["systems"]:
        return None
    x = np.array(cv["points"])
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharex=True)
    for s, c in zip(_systems(doc), _colors(len(doc["systems"])), strict=True):
        v = cv["systems"][s]
        axes[0].plot(x, v["pa"]["normalized"], marker="o", ms=3, color=c, label=s)
        axes[1].plot(x, v["sr"]["normalized"], marker="o", ms=3, color=c, label=s)
    for ax, name in zip(axes, ("PA (%)", "SR (%)"), strict=True):
        ax.set_xlabel("normalized time (0 = first call, 1 = final state)")
        ax.set_ylabel(name)
        ax.set_ylim(-2, 102)
        ax.grid(alpha=0.3)
    axes[0].set_title("Part accuracy over normalized time")
    axes[1].set_title("Success rate over normalized time")
    axes[1].legend(fontsize=8, loc="best")
    return _save(fig, path)


def _quality_budget(doc, path: Path) -> str | None:
    cv = doc["curves"]
    if not cv["systems"]:
        return None
    minutes = np.array(cv["budget_minutes"], dtype=float)
    pos = np.arange(len(minutes))
    final_x = len(minutes) + 0.5
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for s, c in zip(_systems(doc), _colors(len(doc["systems"])), strict=True):
        v = cv["systems"][s]
        for ax, m in zip(axes, ("pa", "sr"), strict=True):
            ax.plot(pos, v[m]["budget"], marker="o", ms=3, color=c, label=s)
            ax.plot([final_x], [v[m]["final"]], marker="D", ms=6, color=c, linestyle="none")
    for ax, name in zip(axes, ("PA (%)", "SR (%)"), strict=True):
        ax.axvspan(len(minutes) - 0.25, len(minutes) + 1.25, color="0.9", zorder=0)
        ax.set_xticks(list(pos) + [final_x], [f"{m:g}" for m in minutes] + ["Final"])
        ax.set_xlabel("time budget (minutes since start_episode)")
        ax.set_ylabel(name)
        ax.set_ylim(-2, 102)
        ax.grid(alpha=0.3)
    axes[0].set_title("PA at absolute budgets (diamonds: untruncated)")
    axes[1].set_title("SR at absolute budgets (diamonds: untruncated)")
    axes[1].legend(fontsize=8, loc="best")
    return _save(fig, path)


def _thresholds(doc, path: Path) -> str | None:
    th = doc["thresholds"]
    if not th["systems"]:
        return None
    x = np.array(th["thresholds"])
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharex=True)
    for s, c in zip(_systems(doc), _colors(len(doc["systems"])), strict=True):
        v = th["systems"][s]
        axes[0].plot(x, v["pa"], color=c, label=s)
        axes[1].plot(x, v["sr"], color=c, label=s)
    for ax, name in zip(axes, ("PA (%)", "SR (%)"), strict=True):
        ax.set_xscale("log")
        ax.axvline(0.01, color="k", ls="--", lw=0.8, label="protocol cutoff 0.01")
        ax.set_xlabel("part CD threshold (normalized units²)")
        ax.set_ylabel(name)
        ax.set_ylim(-2, 102)
        ax.grid(alpha=0.3, which="both")
    axes[0].set_title("PA vs correctness threshold")
    axes[1].set_title("SR vs correctness threshold")
    fig.suptitle("Saved registration and Hungarian matching held fixed; benchmark weights (eq. 3)", fontsize=10)
    fig.tight_layout()
    axes[1].legend(fontsize=8, loc="best")
    return _save(fig, path)


def _activity(doc, path: Path) -> str | None:
    dy = doc["dynamics"]
    systems = [s for s in _systems(doc) if any(a > 0 for a in dy["systems"].get(s, {}).get("active", []))]
    if not systems:
        return None
    n = len(systems)
    cols = min(4, n)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.0 * rows), squeeze=False, sharey=True)
    centers = (np.arange(dy["n_bins"]) + 0.5) / dy["n_bins"]
    for ax, s in zip(axes.ravel()[:n], systems, strict=True):  # the grid's spare cells are hidden below
        sh = np.array([[np.nan if x is None else x for x in row] for row in dy["systems"][s]["shares"]], dtype=float)
        for k, kind in enumerate(dy["kinds"]):
            ax.plot(centers, 100 * sh[:, k], marker="o", ms=3, color=_KIND_COLORS.get(kind), label=kind.capitalize())
        ax.set_title(f"{s} activity")
        ax.set_xlabel("normalized interaction time")
        ax.set_xlim(0, 1)
        ax.set_ylim(-2, 102)
        ax.grid(alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("share of calls in bin (%)")
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    axes.ravel()[0].legend(fontsize=8, loc="best")
    fig.suptitle("Mean call shares within active evaluation-bins (benchmark weights)", y=1.06)
    return _save(fig, path)


def _magnitudes(doc, path: Path) -> str | None:
    dy = doc["dynamics"]
    systems = [s for s in _systems(doc) if s in dy["systems"]]
    if not systems:
        return None
    have = any(
        x is not None
        for s in systems
        for x in dy["systems"][s]["magnitudes"]["translation"] + dy["systems"][s]["magnitudes"]["rotation_deg"]
    )
    if not have:
        return None
    centers = (np.arange(dy["n_bins"]) + 0.5) / dy["n_bins"]
    fig, ax = plt.subplots(figsize=(7, 4))
    ax2 = ax.twinx()
    for s, c in zip(systems, _colors(len(doc["systems"])), strict=True):
        mg = dy["systems"][s]["magnitudes"]
        t = np.array([np.nan if x is None else x for x in mg["translation"]], dtype=float)
        r = np.array([np.nan if x is None else x for x in mg["rotation_deg"]], dtype=float)
        ax.plot(centers, t, color=c, marker="o", ms=3, label=f"{s} translation")
        ax2.plot(centers, r, color=c, marker="s", ms=3, ls="--", label=f"{s} rotation")
    ax.set_xlabel("normalized interaction time")
    ax.set_ylabel("translation (largest-part diagonals), solid")
    ax2.set_ylabel("rotation (degrees), dashed")
    ax.set_xlim(0, 1)
    ax.grid(alpha=0.3)
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="upper left", bbox_to_anchor=(1.15, 1.0), borderaxespad=0)
    ax.set_title("Median manipulation magnitudes per bin\n(weighted median of per-evaluation medians)", fontsize=10)
    return _save(fig, path)


def _reference(doc, path: Path) -> str | None:
    ref = doc["uncertainty"]["reference"]
    if not ref:
        return None
    fig, axes = plt.subplots(1, 2, figsize=(10, 0.55 * len(ref) + 1.8), sharey=True)
    labels = [f"{r['system']} ({r['source']})" if len({x["source"] for x in ref}) > 1 else r["system"] for r in ref]
    y = np.arange(len(ref))[::-1]
    for ax, m, name in zip(axes, ("sr", "pa"), ("ΔSR (percentage points)", "ΔPA (percentage points)"), strict=True):
        d = np.array([r[m]["diff"] for r in ref])
        lo = np.array([r[m]["ci"][0] for r in ref])
        hi = np.array([r[m]["ci"][1] for r in ref])
        ax.errorbar(d, y, xerr=[d - lo, hi - d], fmt="o", color="#4C72B0", ecolor="0.4", capsize=3)
        for yi, di in zip(y, d, strict=True):
            ax.annotate(f"{di:+.1f}", (di, yi), textcoords="offset points", xytext=(0, 7), ha="center", fontsize=8)
        ax.axvline(0, color="k", lw=0.8)
        ax.set_xlabel(name)
        ax.set_ylim(-0.7, len(ref) - 0.3)
        ax.grid(alpha=0.3, axis="x")
        ax.set_title(f"{m.upper()} gain")
    axes[0].set_yticks(y, labels)
    fig.suptitle(
        "Reference-image effect (image minus no reference, same objects): mean and paired 95% bootstrap interval",
        fontsize=10,
    )
    fig.tight_layout()
    return _save(fig, path)


def write_plots(doc: dict[str, Any], out_dir: Path) -> dict[str, str]:
    """Write every plot the study has data for; returns ``{name: file name}``."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    made = {}
    for name, fn in (
        ("quality_normalized", _quality_normalized),
        ("quality_budget", _quality_budget),
        ("thresholds", _thresholds),
        ("activity", _activity),
        ("magnitudes", _magnitudes),
        ("reference", _reference),
    ):
        p = fn(doc, out_dir / f"{name}.png")
        if p is not None:
            made[name] = p
    return made
