"""Price schedule for estimating Codex cost (Codex does not report cost; Claude Code does).

USD per million tokens: (input, cached input, output), from OpenAI's public API price list as
of 2025 (standard tier). Prices change: pass ``--price-table FILE`` (JSON
``{"model": [input, cached_input, output], ...}``) to use the schedule of your runs. Every cost
computed from this table is marked ``cost_estimated`` in ``run.json``.
"""

from __future__ import annotations

from pathlib import Path

from aw.formats import FormatError
from aw.formats.strict_json import read_json_object

PRICES_USD_PER_MTOK: dict[str, tuple[float, float, float]] = {
    "gpt-5": (1.25, 0.125, 10.0),
    "gpt-5-codex": (1.25, 0.125, 10.0),
    "gpt-5.1": (1.25, 0.125, 10.0),
    "gpt-5.1-codex": (1.25, 0.125, 10.0),
    "gpt-5-mini": (0.25, 0.025, 2.0),
    "gpt-5-nano": (0.05, 0.005, 0.4),
    "gpt-4.1": (2.0, 0.5, 8.0),
    "gpt-4.1-mini": (0.4, 0.1, 1.6),
    "o3": (2.0, 0.5, 8.0),
    "o4-mini": (1.1, 0.275, 4.4),
}
PRICE_SOURCE = "OpenAI API list prices (standard tier), 2025; built into aw.runner.harness.prices"


def load_price_table(path: Path | None) -> tuple[dict[str, tuple[float, float, float]], str]:
    if path is None:
        return dict(PRICES_USD_PER_MTOK), PRICE_SOURCE
    try:
        raw = read_json_object(path)
        table = {str(k): (float(v[0]), float(v[1]), float(v[2])) for k, v in raw.items()}
    except FormatError as exc:
        raise ValueError(
            f"{path}: not a price table {{model: [input, cached_input, output]}} ({exc.problem})"
        ) from None
    except (ValueError, TypeError, IndexError, KeyError) as exc:
        raise ValueError(f"{path}: not a price table {{model: [input, cached_input, output]}} ({exc})") from None
    return table, str(path)


def estimate_cost(model: str | None, input_tokens: int, cached_tokens: int, output_tokens: int, table) -> float | None:
    """USD; ``input_tokens`` includes ``cached_tokens`` (OpenAI's accounting). None if unpriced."""
    if not model or model not in table:
        return None
    p_in, p_cached, p_out = table[model]
    fresh = max(0, input_tokens - cached_tokens)
    return (fresh * p_in + cached_tokens * p_cached + output_tokens * p_out) / 1e6
