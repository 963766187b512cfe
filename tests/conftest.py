"""Test-wide settings: offscreen GL platform, JAX on CPU with a persistent compilation cache; the
browser of the page tests (Debian's Chromium through playwright, installed by scripts/install.sh)."""

import os
from pathlib import Path

import pytest

_ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(_ROOT / ".jax_cache"))

CHROMIUM = "/usr/bin/chromium"


@pytest.fixture(scope="module")
def browser():
    """Debian's Chromium (no browser download), software WebGL for the 3D views. One per test
    module: playwright's sync API keeps an event loop in the thread while it is open, which the
    anyio tests that run after a module in the same worker must not find."""
    if not Path(CHROMIUM).is_file():
        pytest.fail(f"{CHROMIUM} not found: run scripts/install.sh as root (it installs Debian's chromium)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=["--enable-unsafe-swiftshader", "--use-angle=swiftshader"])
        yield b
        b.close()
