"""A small external refiner for tests: ``python scripted_refiner.py REQUEST RESULT``.

It reads the request file and answers as its ``options.behaviour`` says: ``shift`` (the
non-anchor parts moved by ``options.dx`` along x; on the task ``options.same_task``, the start
returned unchanged), ``short`` (one pose fewer), ``nan``,
``move_anchor``, ``sleep`` (never answers), ``fail`` (exits 3 with a message) or ``silent``
(exits 0 without writing a result)."""

import json
import sys
import time

request_path, result_path = sys.argv[1], sys.argv[2]
req = json.load(open(request_path))
assert req["format"] == "assemblyworld.refine-request"
behaviour = req["options"].get("behaviour", "shift")
poses = {pid: list(p) for pid, p in req["initial_poses"].items()}
anchor = req["anchor"]
for pid in poses:
    if pid != anchor and req["task_id"] != req["options"].get("same_task"):
        poses[pid][0] += float(req["options"].get("dx", 0.25))
if behaviour == "short":
    poses.pop(next(p for p in poses if p != anchor))
elif behaviour == "nan":
    poses[next(p for p in poses if p != anchor)][1] = float("nan")
elif behaviour == "move_anchor":
    poses[anchor][2] += 0.5
elif behaviour == "sleep":
    time.sleep(600)
elif behaviour == "fail":
    print("scripted refiner: model weights not found", file=sys.stderr)
    sys.exit(3)
elif behaviour == "silent":
    sys.exit(0)
with open(result_path, "w") as fh:
    json.dump({"format": "assemblyworld.refine-result", "format_version": 1, "poses": poses}, fh)
