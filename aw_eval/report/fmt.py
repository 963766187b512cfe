"""Number formatting for the Markdown report, following the paper's tables."""

from __future__ import annotations

import math

__all__ = ["paper", "fixed", "ci", "pval", "signed", "md_table", "bold_best"]

DASH = "–"


def _missing(x) -> bool:
    return x is None or (isinstance(x, float) and math.isnan(x))


def paper(x) -> str:
    """Table 1 style: rounded to one decimal, shown with four significant digits
    (59.375 -> ``59.40``, 7.5 -> ``7.500``, 0 -> ``0.000``, 100 -> ``100.0``)."""
    if _missing(x):
        return DASH
    r = round(float(x), 1)
    if r == 0:
        return "0.000"
    return f"{r:#.4g}"


def fixed(x, digits: int = 1) -> str:
    return DASH if _missing(x) else f"{float(x):.{digits}f}"


def signed(x, digits: int = 1) -> str:
    return DASH if _missing(x) else f"{float(x):+.{digits}f}"


def ci(pair, digits: int = 1) -> str:
    if pair is None or any(_missing(v) for v in pair):
        return DASH
    return f"[{float(pair[0]):.{digits}f}, {float(pair[1]):.{digits}f}]"


def pval(p, floor: float = 0.001) -> str:
    if _missing(p):
        return DASH
    return f"<{floor:g}" if p < floor else f"{p:.3f}"


def md_table(header: list[str], rows: list[list[str]], align: str | None = None) -> str:
    """A GitHub Markdown table; ``align`` is one character per column (l or r), default l then r."""
    align = align or ("l" + "r" * (len(header) - 1))
    sep = ["---" if a == "l" else "---:" for a in align]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(sep) + " |"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def bold_best(cells: list[str], values: list, higher: bool = True) -> list[str]:
    """Bold the best numeric entries (ties included)."""
    vals = [v for v in values if not _missing(v)]
    if not vals:
        return cells
    best = max(vals) if higher else min(vals)
    return [f"**{c}**" if not _missing(v) and abs(v - best) < 1e-9 else c for c, v in zip(cells, values)]
