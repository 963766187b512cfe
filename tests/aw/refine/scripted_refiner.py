"""A small external refiner for tests: ``python scripted_refiner.py REQUEST RESULT``.

It reads the request file and answers as its ``options.behaviour`` says: ``shift`` (the
non-anchor parts moved by ``options.dx`` along x; on the task ``options.same_task``, the start
returned unchanged), ``short`` (one pose fewer), ``nan``,
``move_anchor``, ``sleep`` (never answers), ``fail`` (exits 3 with a message), ``silent``
(exits 0 without writing a result), or a hostile answer: ``far`` (a position of 1e300), ``huge``
(a number of 401 digits), ``deep`` (arrays 3,000 deep), ``big`` (a 300 MiB result file),
``loud`` (300 MiB of output, then a last line, exit 3; the two large files are sparse), ``setsid`` (starts a process that calls ``os.setsid()``,
leaves its parent's tree, writes its pid to ``options.pid_file`` and sleeps, then never answers)
or ``setsid_answer`` (the same process, then answers at once)."""

import json
import os
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
elif behaviour in ("setsid", "setsid_answer"):
    if os.fork() == 0:  # a child that leaves the refiner's session and, orphaned, its process tree
        os.setsid()
        if os.fork() == 0:
            with open(req["options"]["pid_file"] + ".tmp", "w") as fh:
                fh.write(str(os.getpid()))
            os.replace(req["options"]["pid_file"] + ".tmp", req["options"]["pid_file"])
            time.sleep(600)
        os._exit(0)
    while not os.path.exists(req["options"]["pid_file"]):
        time.sleep(0.01)
    if behaviour == "setsid":
        time.sleep(600)
elif behaviour == "fail":
    print("scripted refiner: model weights not found", file=sys.stderr)
    sys.exit(3)
elif behaviour == "silent":
    sys.exit(0)
elif behaviour == "far":
    poses[next(p for p in poses if p != anchor)][0] = 1e300
elif behaviour == "big":
    with open(result_path, "wb") as fh:
        fh.truncate(300 << 20)
    sys.exit(0)
elif behaviour == "loud":
    os.lseek(1, 300 << 20, os.SEEK_SET)  # stdout is the refiner.log file
    os.write(1, b"\nscripted refiner: out of patience\n")
    sys.exit(3)
doc = {"format": "assemblyworld.refine-result", "format_version": 1, "poses": poses}
text = json.dumps(doc)
if behaviour == "huge":
    text = text.replace(json.dumps(poses[anchor]), "[1" + "0" * 400 + ", 0, 0, 1, 0, 0, 0]", 1)
elif behaviour == "deep":
    text = text[:-1] + ', "notes": ' + "[" * 3000 + "]" * 3000 + "}"
with open(result_path, "w") as fh:
    fh.write(text)
