"""The kernel tests share tests/aw_eval's helpers (``eval_helpers``)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
