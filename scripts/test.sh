#!/usr/bin/env bash
# Installs AssemblyWorld into .venv/ (if needed) and runs the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
export PYOPENGL_PLATFORM="${PYOPENGL_PLATFORM:-egl}"
exec .venv/bin/python -m pytest -q -p no:cacheprovider -n "${AW_TEST_JOBS:-2}" "$@"
