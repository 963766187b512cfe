"""aw-serve latency over stdio, measured with the official MCP client as a harness would see it.

    .venv/bin/python benchmarks/bench_server.py [--parts 10] [--faces 500] [--trivial 200]
        [--edits 100] [--captures 20] --out DIR

Reports: server start to first tools/list answer; round trip of a trivial tool (``get_state``);
an edit (``translate_objects``, which appends and fsyncs one trajectory line); ``capture_scene``
(the first one starts the renderer; the warm ones render, encode the PNG, save it and send it
base64-encoded). The task is synthetic: ``--parts`` icospheres stretched into ellipsoids with about
``--faces`` triangles each, scattered on the XY plane.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import anyio
import numpy as np
import trimesh

ROOT = Path(__file__).resolve().parents[1]


def make_task(root: Path, n_parts: int, faces: int) -> Path:
    from aw.formats import Task, TaskPart, write_task
    from aw.prompt import task_prompt

    subdiv = max(0, int(round(np.log(max(faces, 20) / 20) / np.log(4))))
    rng = np.random.default_rng(0)
    task_dir = root / "bench_task"
    (task_dir / "parts").mkdir(parents=True)
    for i in range(n_parts):
        m = trimesh.creation.icosphere(subdivisions=subdiv)
        m.apply_scale(rng.uniform(0.05, 0.25, 3))
        m.apply_translation([0.6 * (i % 5), 0.6 * (i // 5), 0.0])
        m.export(task_dir / "parts" / f"p{i + 1:02d}.obj")
    task = Task(
        task_id="bench",
        source="custom",
        dataset="bench",
        object_id="bench",
        prompt=task_prompt("none"),
        parts=[TaskPart(id=f"p{i + 1:02d}", mesh=f"parts/p{i + 1:02d}.obj") for i in range(n_parts)],
    )
    write_task(task_dir, task)
    return task_dir


def stats_ms(samples: list[float]) -> dict:
    ms = sorted(1000 * s for s in samples)
    return {
        "n": len(ms),
        "median_ms": statistics.median(ms),
        "p90_ms": ms[min(len(ms) - 1, int(0.9 * len(ms)))],
        "min_ms": ms[0],
        "max_ms": ms[-1],
    }


async def run(task_dir: Path, run_dir: Path, args) -> dict:
    from mcp import Client, StdioServerParameters

    env = dict(os.environ)
    env.setdefault("PYOPENGL_PLATFORM", "egl")
    params = StdioServerParameters(
        command=sys.executable, args=["-m", "aw_server.cli", str(task_dir), "--record", str(run_dir)], env=env
    )
    out: dict = {}
    t0 = time.perf_counter()
    async with Client(params, mode="legacy") as c:
        await c.list_tools()
        out["start_to_tools_list_s"] = time.perf_counter() - t0
        await c.call_tool("start_episode", {})

        samples = []
        for _ in range(args.trivial):
            t = time.perf_counter()
            r = await c.call_tool("get_state", {})
            samples.append(time.perf_counter() - t)
            assert not r.is_error
        out["get_state"] = stats_ms(samples)

        samples = []
        for i in range(args.edits):
            t = time.perf_counter()
            r = await c.call_tool("translate_objects", {"ids": ["p01"], "delta": [0.001 * (-1) ** i, 0, 0]})
            samples.append(time.perf_counter() - t)
            assert not r.is_error
        out["translate_objects"] = stats_ms(samples)

        t = time.perf_counter()
        r = await c.call_tool("capture_scene", {})
        out["capture_first_s"] = time.perf_counter() - t
        assert not r.is_error
        samples, sizes = [], []
        for _ in range(args.captures):
            await c.call_tool("move_camera", {"yaw": 7})
            t = time.perf_counter()
            r = await c.call_tool("capture_scene", {})
            samples.append(time.perf_counter() - t)
            sizes.append(len(r.content[0].data) * 3 // 4)
        out["capture_scene"] = stats_ms(samples)
        out["png_kib_median"] = statistics.median(sizes) / 1024
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--parts", type=int, default=10)
    p.add_argument("--faces", type=int, default=500, help="about this many triangles per part")
    p.add_argument("--trivial", type=int, default=200)
    p.add_argument("--edits", type=int, default=100)
    p.add_argument("--captures", type=int, default=20)
    p.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="DIR",
        help="folder to write bench_server.json to (a new file; never overwritten)",
    )
    args = p.parse_args(argv)
    from _output import output_file

    out = output_file(args.out, "bench_server.json")  # refused before the run, not after it
    with tempfile.TemporaryDirectory() as tmp:
        task_dir = make_task(Path(tmp), args.parts, args.faces)
        from aw.meshes import load_mesh

        total_faces = sum(len(load_mesh(f).faces) for f in (task_dir / "parts").glob("*.obj"))
        res = anyio.run(run, task_dir, Path(tmp) / "run", args)
    res.update(
        parts=args.parts,
        total_faces=total_faces,
        python=platform.python_version(),
        machine=platform.machine(),
        cpus=os.cpu_count(),
        pyopengl_platform=os.environ.get("PYOPENGL_PLATFORM", "egl"),
        command=" ".join([Path(sys.executable).name, *sys.argv]),
    )
    print(f"aw-serve over stdio: {args.parts} parts, {total_faces} faces, {os.cpu_count()} CPUs")
    print(f"  start -> first tools/list    {res['start_to_tools_list_s']:8.2f} s")
    print(f"  first capture (renderer up)  {res['capture_first_s']:8.2f} s")
    print(f"  {'call':<28}{'median ms':>10}{'p90 ms':>10}{'n':>6}")
    for name in ("get_state", "translate_objects", "capture_scene"):
        s = res[name]
        print(f"  {name:<28}{s['median_ms']:>10.1f}{s['p90_ms']:>10.1f}{s['n']:>6}")
    print(f"  PNG size (median)            {res['png_kib_median']:8.0f} KiB")
    out.write_text(json.dumps(res, indent=2) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
