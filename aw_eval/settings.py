"""Protocol settings: every number of the geometric evaluation protocol (Appendix A.3) in one place.

The defaults are the paper's. Tests may shrink ``n_surface``/``n_fps`` for speed; every derived
quantity (geometry cache keys included) depends on the whole settings object.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass
from typing import Any

__all__ = ["ProtocolSettings", "PROTOCOL_VERSION"]

# Bumped whenever a change to the code changes any computed number for the same settings;
# part of every geometry cache key.
PROTOCOL_VERSION = 1


@dataclass(frozen=True)
class ProtocolSettings:
    """Numbers of the evaluation protocol.

    - ``n_surface``: area-weighted surface candidates per part (4096).
    - ``n_fps``: farthest-point samples kept per part (1000).
    - ``seed``: base seed; part ``i`` (index among the scored parts) samples with
      ``SeedSequence([seed, i])`` (see :func:`aw_eval.sampling.part_seed`).
    - ``max_iters``: ICP iterations per start (100); ``tol``: improvement tolerance (1e-9).
    - ``equiv_cd``: pairwise CD at or below which two parts are equivalent (1e-4).
    - ``threshold``: part-correct CD threshold, inclusive (0.01).
    - ``sra_threshold``: SR^a holds when SCD is strictly below it (0.02).
    """

    n_surface: int = 4096
    n_fps: int = 1000
    seed: int = 0
    max_iters: int = 100
    tol: float = 1e-9
    equiv_cd: float = 1e-4
    threshold: float = 0.01
    sra_threshold: float = 0.02

    def __post_init__(self) -> None:
        if not (isinstance(self.n_surface, int) and isinstance(self.n_fps, int)):
            raise ValueError("n_surface and n_fps must be integers")
        if self.n_fps < 1 or self.n_surface < self.n_fps:
            raise ValueError(f"need 1 <= n_fps <= n_surface, got n_fps={self.n_fps}, n_surface={self.n_surface}")
        if not isinstance(self.max_iters, int) or self.max_iters < 0:
            raise ValueError(f"max_iters must be a non-negative integer, got {self.max_iters!r}")
        if not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {self.seed!r}")
        for name in ("tol", "equiv_cd", "threshold", "sra_threshold"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and v >= 0 and v == v and v != float("inf")):
                raise ValueError(f"{name} must be a finite non-negative number, got {v!r}")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def fingerprint(self) -> str:
        """Stable hash of the settings (and the protocol version) for cache keys."""
        blob = json.dumps({"v": PROTOCOL_VERSION, **self.to_dict()}, sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:16]
