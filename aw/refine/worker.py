"""``python -m aw.refine.worker NAME REQUEST.json RESULT.json``: run the Python refiner ``NAME``
(built in or an ``assemblyworld.refiners`` entry point) on a request file and write its answer.
The runner starts it as a child process so that time limits and crashes stay contained."""

from __future__ import annotations

import sys

import numpy as np

from aw.refine.base import RefinerError, check_poses
from aw.refine.exchange import read_request, write_result
from aw.refine.plugins import load_refiner


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 3:
        print("usage: python -m aw.refine.worker NAME REQUEST.json RESULT.json", file=sys.stderr)
        return 2
    name, req_path, res_path = argv
    request = read_request(req_path)
    try:
        poses = check_poses(name, request, load_refiner(name)(request))
    except RefinerError as exc:  # the parent shows this line as the refiner's failure
        print(exc, file=sys.stderr)
        return 1
    except Exception as exc:  # the refiner's own failure, in one line (the traceback above it in the log)
        import traceback

        traceback.print_exc()
        print(f"refiner {name}: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    write_result(res_path, request.part_ids, np.asarray(poses))
    return 0


if __name__ == "__main__":
    sys.exit(main())
