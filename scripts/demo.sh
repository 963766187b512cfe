#!/usr/bin/env bash
# One command from a fresh clone: install (if needed), then the whole loop of the paper on the
# embedded synthetic benchmark (suite, agents through MCP, rescoring, summary). Arguments go
# to aw-demo (see .venv/bin/aw-demo --help).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
exec .venv/bin/aw-demo "$@"
