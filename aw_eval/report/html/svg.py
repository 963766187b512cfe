"""Small inline SVG step curves (a run's PA or SCD over normalized interaction time)."""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from dataclasses import dataclass

__all__ = ["Series", "step_chart"]


@dataclass
class Series:
    """One line: ``xs``/``ys`` of equal length, ``xs`` in [0, 1] ascending; the value holds until
    the next point (scores change only when an operation completes)."""

    label: str
    color: str
    xs: Sequence[float]
    ys: Sequence[float]


def _ticks(lo: float, hi: float) -> list[float]:
    return [lo, 0.5 * (lo + hi), hi]


def step_chart(
    series: list[Series],
    title: str,
    y_range: tuple[float, float] | None = None,
    width: int = 260,
    height: int = 120,
    fmt=lambda v: f"{v:g}",
) -> str:
    """An SVG step chart; ``y_range`` None fits the data (from 0)."""
    left, right, top, bottom = 34, 6, 16, 18
    finite = [y for s in series for y in s.ys if y is not None and math.isfinite(y)]
    lo, hi = y_range if y_range else (0.0, max(finite, default=1.0) or 1.0)
    if hi <= lo:
        hi = lo + 1.0
    pw, ph = width - left - right, height - top - bottom

    def px(x: float) -> float:
        return left + pw * min(max(x, 0.0), 1.0)

    def py(y: float) -> float:
        return top + ph * (1 - (min(max(y, lo), hi) - lo) / (hi - lo))

    parts = [
        f'<svg class="chart" xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
        f'viewBox="0 0 {width} {height}" role="img" aria-label="{html.escape(title)}">',
        f'<text x="{left}" y="11" class="t">{html.escape(title)}</text>',
        f'<rect x="{left}" y="{top}" width="{pw}" height="{ph}" class="frame"/>',
    ]
    for v in _ticks(lo, hi):
        parts.append(
            f'<line x1="{left}" x2="{left + pw}" y1="{py(v):.1f}" y2="{py(v):.1f}" class="grid"/>'
            f'<text x="{left - 3}" y="{py(v) + 3:.1f}" class="yl">{html.escape(fmt(v))}</text>'
        )
    parts.append(
        f'<text x="{left}" y="{height - 4}" class="xl">0</text>'
        f'<text x="{left + pw}" y="{height - 4}" class="xl" text-anchor="end">1 (final)</text>'
    )
    for s in series:
        pts, last = [], None
        for x, y in zip(s.xs, s.ys, strict=True):
            if y is None or not math.isfinite(y):
                continue
            if last is not None:
                pts.append(f"{px(x):.1f},{py(last):.1f}")
            pts.append(f"{px(x):.1f},{py(y):.1f}")
            last = y
        if pts:
            parts.append(
                f'<polyline points="{" ".join(pts)}" fill="none" stroke="{s.color}" stroke-width="1.6">'
                f"<title>{html.escape(s.label)}</title></polyline>"
            )
    parts.append("</svg>")
    return "".join(parts)
