#!/usr/bin/env bash
# Installs AssemblyWorld into .venv/ (if needed), checks format, lint and types, and runs the
# whole test suite. Any finding fails the run before the tests start.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh

# ruff formats and lints every Python folder; mypy checks the packages ([tool.mypy] in
# pyproject.toml; its cache is .mypy_cache/, so a second run takes seconds).
lint_paths=(aw aw_eval aw_server aw_view assemblyworld tests benchmarks scripts)
.venv/bin/ruff format --check -q "${lint_paths[@]}" || {
  echo "test.sh: error: ruff format: the files above are not formatted (run .venv/bin/ruff format FILES)" >&2; exit 1; }
.venv/bin/ruff check -q "${lint_paths[@]}" || {
  echo "test.sh: error: ruff check: the findings above (fix them; .venv/bin/ruff check --fix applies the safe ones)" >&2; exit 1; }
.venv/bin/mypy || { echo "test.sh: error: mypy: the type errors above" >&2; exit 1; }
echo "[test] ruff format, ruff check and mypy: clean"

export PYOPENGL_PLATFORM="${PYOPENGL_PLATFORM:-egl}"
exec .venv/bin/python -m pytest -q -p no:cacheprovider -n "${AW_TEST_JOBS:-2}" "$@"
