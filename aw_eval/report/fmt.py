"""Number formatting for the Markdown report, following the paper's tables."""

from __future__ import annotations

import math
from decimal import ROUND_HALF_UP, Decimal

__all__ = ["paper", "fixed", "ci", "pval", "signed", "md_table", "bold_best", "threshold_label"]

DASH = "–"


def _missing(x) -> bool:
    return x is None or (isinstance(x, float) and math.isnan(x))


def paper(x) -> str:
    """A percentage as the paper's tables print PA and SR: two decimals, one value everywhere
    (59.375 -> ``59.38``, 7.5 -> ``7.50``, 0 -> ``0.00``, 100 -> ``100.00``), halves rounded up
    after dropping float noise beyond 12 significant digits (a mean of 59.375 may be 59.37499999...)."""
    if _missing(x):
        return DASH
    return str(Decimal(f"{float(x):.12g}").quantize(Decimal("0.01"), rounding=ROUND_HALF_UP))


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
    """A GitHub Markdown table; ``align`` is one character per column (l or r), default l then r.
    A ``|`` inside a cell (a system named after its run directory) is escaped as ``\\|``."""
    align = align or ("l" + "r" * (len(header) - 1))
    sep = ["---" if a == "l" else "---:" for a in align]

    def line(cells: list[str]) -> str:
        return "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"

    return "\n".join([line(header), "| " + " | ".join(sep) + " |", *(line(r) for r in rows)])


def bold_best(cells: list[str], values: list, higher: bool = True, eligible: list[bool] | None = None) -> list[str]:
    """Bold the best numeric entries (ties included) among the ``eligible`` ones (default all),
    only when it is a real best: at least two eligible values, and not all equal."""
    ok = [not _missing(v) and (eligible is None or eligible[i]) for i, v in enumerate(values)]
    vals = [float(v) for v, o in zip(values, ok, strict=True) if o]
    if len(vals) < 2 or max(vals) - min(vals) < 1e-9:
        return cells
    best = max(vals) if higher else min(vals)
    return [f"**{c}**" if o and abs(float(v) - best) < 1e-9 else c for c, v, o in zip(cells, values, ok, strict=True)]


def threshold_label(t: float) -> str:
    """A correctness threshold for a header: two significant digits (0.00316228 -> ``0.0032``)."""
    return f"{t:.2g}"
