"""JAX setup for the evaluator: float64 on (by default) the CPU, persistent compilation cache.

Import JAX through :func:`jax_modules` so that x64 is enabled before any array is made. The
protocol's numbers (squared distances of normalized points, improvements of 1e-9) need float64.
"""

from __future__ import annotations

import os
from pathlib import Path
from types import ModuleType

_READY = False


def jax_modules() -> tuple[ModuleType, ModuleType]:
    """``(jax, jax.numpy)`` with float64 enabled and the compilation cache configured once."""
    global _READY
    import jax
    import jax.numpy as jnp

    if not _READY:
        jax.config.update("jax_enable_x64", True)
        cache = os.environ.get("JAX_COMPILATION_CACHE_DIR")
        if cache is None:
            cache = str(Path.home() / ".cache" / "assemblyworld" / "jax")
        try:
            jax.config.update("jax_compilation_cache_dir", cache)
            # Cache even quick compilations: a study compiles a handful of bucketed shapes.
            jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
            jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
        except Exception:  # an older/newer JAX without these options still works, uncached
            pass
        _READY = True
    return jax, jnp
