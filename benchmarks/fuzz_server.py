"""Fuzz aw-serve through the real MCP client over stdio, and its transport with raw lines.

    python benchmarks/fuzz_server.py [--surface default|official] [--calls 100000] [--raw-lines 2000]
                                     [--seed 0] [--out fuzz.json]

Tool calls mix valid arguments (real ids, numbers in range) with every kind of bad input (wrong
types, out-of-range and non-finite numbers, integers beyond 64 bits, JSON-looking strings, deep
nesting, unknown arguments and tools). With ``--surface official`` the calls go through the
official tools (``execute_webmcp_tool`` with the page tools' official ids and names, and the
other three meta-tools), and ``input`` is also hostile text: not JSON, not an object, nested
hundreds or thousands of levels deep, lone UTF-16 surrogates, integers of hundreds of digits,
NaN. Reported:

- crashes: the server process died or the session broke (it is restarted and the run goes on);
- hangs: no reply within ``--timeout`` seconds;
- state changes on error: an error reply after which ``get_state`` (poses, groups, camera)
  differs from before the call;
- unrecorded calls: trajectory lines missing against the calls made (on the official surface,
  every ``execute_webmcp_tool`` call; the other meta-tools do not reach the episode);
- leaks: a reply that contains an absolute path, a part file name, a target pose component or a
  mesh vertex (three consecutive numbers equal to one), i.e. hidden data;
- memory: the server's resident memory after warm-up and at the end;
- raw lines: undecodable JSON-RPC lines sent on the transport that got no error reply.

Exit status 1 if any crash, hang, state change, unrecorded call, leak or unanswered line.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import re
import select
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import anyio
import numpy as np
import psutil
import trimesh
from mcp import Client, StdioServerParameters

from aw.formats import read_manifest, read_targets
from aw.formats.suite import suite_paths
from aw_eval.study.fixtures import box_suite
from aw_server.tools import TOOL_SPECS

ABS_PATH = re.compile(r"(?:^|[\s\"'(=:,\[])/[A-Za-z0-9_.~-]+/")
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
SPECS = {s.name: s for s in TOOL_SPECS}
WARMUP_CALLS = 2000  # server memory is read after these and at the end: growth between them is a leak


class Hidden:
    """What no reply may contain: paths, file names, target pose numbers, mesh vertices."""

    def __init__(self, task_dir: Path, targets_path: Path):
        self.needles = [str(task_dir), str(task_dir.parent.parent), ".obj", "parts/", "targets"]
        self.vertices = np.concatenate(
            [trimesh.load(p, force="mesh", process=False).vertices for p in sorted((task_dir / "parts").glob("*.obj"))]
        )
        t = np.array([p.pose for p in read_targets(targets_path).parts.values()]).ravel()
        self.targets = t[~(np.isclose(np.abs(t), 0) | np.isclose(np.abs(t), 1))]

    def leaks(self, text: str) -> str | None:
        for n in self.needles:
            if n in text:
                return f"contains {n!r}"
        if ABS_PATH.search(text):
            return "contains an absolute path"
        nums = np.array([float(x) for x in NUMBER.findall(text[:200_000])] or [np.nan])
        if len(self.targets) and (np.abs(nums[:, None] - self.targets[None, :]) < 1e-9).any():
            return "contains a target pose number"
        if len(nums) >= 3:
            triples = np.lib.stride_tricks.sliding_window_view(nums, 3)
            for chunk in range(0, len(triples), 2000):
                d = np.abs(triples[chunk : chunk + 2000, None, :] - self.vertices[None, :, :]).max(axis=2)
                if (d < 1e-7).any():
                    return "contains a mesh vertex"
        return None


class ArgGen:
    """Random tool calls: about half valid, half bad in one of many ways."""

    def __init__(self, seed: int, ids: list[str]):
        self.r = random.Random(seed)
        self.ids = ids
        self.groups: list[str] = []

    def _id(self):
        return (
            self.r.choice(self.ids + self.groups + ["g1"])
            if self.r.random() < 0.95
            else self.r.choice(["p99", "", "x" * 200])
        )

    def _num(self, lo, hi):
        return self.r.uniform(lo, hi)

    def valid(self, tool: str) -> dict:
        r, ids = self.r, self.ids
        sel = r.sample(ids, r.randint(1, len(ids)))
        if tool == "get_object":
            return {"id": self._id()}
        if tool == "translate_objects":
            return {"ids": sel, "delta": [self._num(-1, 1) for _ in range(3)], "space": r.choice(["world", "camera"])}
        if tool == "rotate_objects":
            a = {"ids": sel, "angles": [self._num(-180, 180) for _ in range(3)], "space": r.choice(["world", "camera"])}
            if r.random() < 0.3:
                a["pivot"] = [self._num(-2, 2) for _ in range(3)]
            return a
        if tool == "set_object_pose":
            a = {"id": r.choice(ids)}
            if r.random() < 0.7:
                a["position"] = [self._num(-3, 3) for _ in range(3)]
            if r.random() < 0.7 or "position" not in a:
                a["quaternion"] = [self._num(-1, 1) for _ in range(4)]
            return a
        if tool == "group_objects":
            a = {"ids": sel}
            if r.random() < 0.5:
                a["name"] = r.choice(["legs", "null", "[1,2]", "top"])
            return a
        if tool == "ungroup_objects":
            return {"ids": [r.choice(self.groups or ["g1"])]}
        if tool == "move_camera":
            return {
                k: v
                for k, v in {
                    "yaw": self._num(-180, 180),
                    "pitch": self._num(-85, 85),
                    "zoom": self._num(0.25, 4),
                    "right": self._num(-1, 1),
                    "up": self._num(-1, 1),
                }.items()
                if r.random() < 0.5
            }
        if tool == "start_episode":
            return {"task": "fuzz"} if r.random() < 0.5 else {}
        return {}

    def bad_value(self, depth: int = 0):
        r = self.r
        kind = r.randrange(16)
        if kind == 0:
            return r.choice([10 ** r.randint(19, 400), -(10 ** r.randint(19, 400))])
        if kind == 1:
            return r.choice([1e308, -1e308, 5e-324, 1e5, -1e5])
        if kind == 2:
            return r.choice(["NaN", "Infinity", "-inf", "1e999"])
        if kind == 3:
            return r.choice(['["p01"]', "[1, 0, 0]", "null", "{}", "true", '{"a": 1}'])
        if kind == 4:
            return None
        if kind == 5:
            return r.choice([True, False])
        if kind == 6 and depth < 3:
            return [self.bad_value(depth + 1) for _ in range(r.randint(0, 6))]
        if kind == 7 and depth < 3:
            return {r.choice(["id", "ids", "x", ""]): self.bad_value(depth + 1) for _ in range(r.randint(0, 3))}
        if kind == 8:
            v = 0
            for _ in range(r.randint(10, 60)):
                v = [v]
            return v
        if kind == 9:
            return "".join(chr(r.randint(0, 0x2FFF)) for _ in range(r.randint(0, 30)))
        if kind == 10:
            return "x" * r.choice([201, 5000, 30000])
        if kind == 11:
            return [self._num(-1e4, 1e4) for _ in range(r.choice([0, 1, 2, 4, 5, 100]))]
        if kind == 12:
            return r.choice(self.ids) + r.choice(["", " ", "\x00"])
        if kind == 13:
            return r.randint(-5, 5)
        if kind == 14:
            return [r.choice(self.ids)] * r.randint(2, 4)
        return self._num(-1e6, 1e6)

    def bad(self, tool: str) -> dict:
        r = self.r
        args = self.valid(tool) if tool in SPECS else {}
        fields = (list(SPECS[tool].args.model_fields) if tool in SPECS else []) or ["x"]
        for _ in range(r.randint(1, 3)):
            how = r.randrange(4)
            if how == 0 and args:
                args.pop(r.choice(list(args)))
            elif how == 1:
                args[r.choice(["extra", "speed", "roll", "verbose", "_raw"])] = self.bad_value()
            else:
                args[r.choice(fields)] = self.bad_value()
        return args

    def next(self) -> tuple[str, dict]:
        r = self.r
        names = [s.name for s in TOOL_SPECS if s.kind != "capture"]
        if r.random() < 0.004:
            return "capture_scene", {}
        if r.random() < 0.01:
            return r.choice(["reset", "capture", "", "list_objects "]), {}
        tool = r.choice(names)
        return (tool, self.valid(tool)) if r.random() < 0.5 else (tool, self.bad(tool))


OFFICIAL_IDS = ["part-0001", "part-0002", "part-0003"]
OFFICIAL_MUTATIONS = {
    "translate_objects",
    "rotate_objects",
    "set_object_pose",
    "group_objects",
    "ungroup_objects",
    "move_camera",
}
OFFICIAL_NAMES = {
    "translate_objects": "translate_objects",
    "rotate_objects": "rotate_objects",
    "set_object_pose": "set_object_pose",
    "group_objects": "group_objects",
    "ungroup_objects": "ungroup_objects",
    "move_camera": "move_camera",
    "get_object": "get_object",
    "start_episode": "start_episode",
    "list_objects": "list_objects",
    "get_scene": "get_scene",
    "get_state": "get_state",
}


class OfficialGen(ArgGen):
    """Random official-surface calls: page tools through execute_webmcp_tool with official ids and
    JSON-text input (valid, bad values, or hostile text), and the other meta-tools."""

    def _id(self):
        if self.r.random() < 0.95:
            return self.r.choice(self.ids + self.groups + ["group-x-1"])
        return self.r.choice(["p01", "", "part-0009", "x" * 300])

    def valid(self, tool: str) -> dict:
        a = super().valid(tool)
        if tool == "group_objects" and len(a["ids"]) < 2:
            a["ids"] = self.r.sample(self.ids, 2)
        if tool == "ungroup_objects":
            a = {"ids": [self.r.choice(self.groups or ["group-x-1"])]}
        if tool == "get_object":
            a = {"id": self._id()}
        return a

    def hostile_text(self, tool: str) -> str:
        r = self.r
        valid = json.dumps(self.valid(tool))
        kind = r.randrange(9)
        if kind == 0:  # deep nesting: past orjson's and Python's limits
            d = r.choice([33, 253, 254, 300, 1000, 5000, 20000])
            return '{"ids": ' + "[" * d + "]" * d + ', "delta": [0, 0, 0]}'
        if kind == 1:  # lone UTF-16 surrogates, in a value or a key
            sur = f"\\u{r.choice([0xD800, 0xDBFF, 0xDC00, 0xDFFF]):04x}"
            return r.choice(
                [
                    '{"ids": ' + json.dumps(self.r.sample(self.ids, 2)) + ', "name": "a' + sur + 'b"}',
                    '{"' + sur + '": 1}',
                    '{"id": "' + sur + '"}',
                ]
            )
        if kind == 2:  # integers beyond float range, or beyond Python's 4300-digit text limit
            digits = "9" * r.choice([309, 400, 4300, 4301, 6000])
            return r.choice(
                [
                    '{"ids": ["part-0001"], "delta": [' + digits + ", 0, 0]}",
                    '{"yaw": -' + digits + "}",
                    '{"id": "part-0001", "position": [0, 0, ' + digits + "]}",
                ]
            )
        if kind == 3:
            return r.choice(["NaN", '{"yaw": NaN}', '{"zoom": Infinity}', '{"pitch": -Infinity}'])
        if kind == 4:
            return r.choice(["", "{", "[]", "null", "1", '"{}"', "{ids: 1}", "{}{}", valid[: r.randint(0, len(valid))]])
        if kind == 5:
            return valid + r.choice(["", " ", "\n", "x"])
        if kind == 6:
            return json.dumps({"x" * r.randint(1, 3): self.bad_value()}, default=str)
        if kind == 7:
            return "".join(chr(r.randint(1, 0x2FFF)) for _ in range(r.randint(0, 40)))
        return json.dumps(self.valid(tool), ensure_ascii=r.random() < 0.5)

    def next(self) -> tuple[str, dict]:
        r = self.r
        x = r.random()
        if x < 0.004:
            return "execute_webmcp_tool", {"pageId": 1, "toolName": "capture_scene", "input": "{}"}
        if x < 0.014:
            return r.choice(["reset", "capture", "", "list_objects"]), {}
        if x < 0.06:
            meta = r.choice(["list_pages", "list_webmcp_tools", "read_manual_page"])
            a = {"list_pages": {}, "list_webmcp_tools": {"pageId": 1}, "read_manual_page": {"page": 1}}[meta]
            if r.random() < 0.6:
                a[r.choice(["pageId", "page", "x"])] = self.bad_value()
            return meta, a
        tool = r.choice(list(OFFICIAL_NAMES) + ["apply_force", "advance_simulation", "end_episode", "nope"])
        call = {"pageId": 1, "toolName": tool}
        y = r.random()
        if y < 0.45:
            call["input"] = json.dumps(self.valid(tool))
        elif y < 0.75:
            call["input"] = json.dumps(self.bad(tool) if tool in SPECS else {"x": 1}, default=str)
        else:
            call["input"] = self.hostile_text(tool)
        if r.random() < 0.03:  # a bad meta-call: page id, tool name, input type, extra argument
            k = r.choice(["pageId", "toolName", "input", "extra"])
            call[k] = self.bad_value()
        elif r.random() < 0.02:
            call.pop("input")
        return "execute_webmcp_tool", call


class DefaultDriver:
    """The project's own tools."""

    server_args: list[str] = []
    tools = frozenset(SPECS)

    def __init__(self, seed: int):
        self.gen = ArgGen(seed, ["p01", "p02", "p03"])

    async def state(self, c) -> dict:
        return _state(await c.call_tool("get_state", {}))

    def recorded(self, tool: str, args: dict) -> int:
        return int(tool in SPECS)  # unknown tools are refused by the SDK before the episode

    def failed(self, res) -> bool:
        return bool(res.is_error)

    def succeeded(self, tool: str, args: dict, res) -> bool:
        """Note a successful call; whether it may have changed the state."""
        if tool == "group_objects":
            self.gen.groups.append(res.structured_content["group"]["id"])
        if tool == "ungroup_objects":
            self.gen.groups = [g for g in self.gen.groups if g not in res.structured_content["removed"]]
        return tool in OFFICIAL_MUTATIONS


class OfficialDriver(DefaultDriver):
    """``aw-serve --surface official``: page tools through execute_webmcp_tool."""

    server_args = ["--surface", "official"]

    def __init__(self, seed: int):
        self.gen = OfficialGen(seed, list(OFFICIAL_IDS))

    async def state(self, c) -> dict:
        res = await c.call_tool("execute_webmcp_tool", {"pageId": 1, "toolName": "get_state", "input": "{}"})
        out = json.loads(json.loads(_text(res))["output"])
        return {k: out.get(k) for k in ("index", "objects", "groups", "camera")}

    def recorded(self, tool: str, args: dict) -> int:
        return int(tool == "execute_webmcp_tool")  # every one, refused or not; the other meta-tools never

    def _output(self, res) -> dict | None:
        try:
            return json.loads(json.loads(_text(res))["output"])
        except (ValueError, KeyError, TypeError):
            return None

    def failed(self, res) -> bool:
        if res.is_error:
            return True
        out = self._output(res)
        return isinstance(out, dict) and "error" in out

    def succeeded(self, tool: str, args: dict, res) -> bool:
        if tool != "execute_webmcp_tool":
            return False
        page_tool = args.get("toolName")
        out = self._output(res) or {}
        if page_tool == "group_objects" and "result" in out:
            # groups sharing a member were dissolved: their ids stay as calls the page must refuse
            self.gen.groups = [*self.gen.groups[-20:], out["result"]["id"]]
        if page_tool == "ungroup_objects":
            try:
                gone = set(json.loads(args["input"])["ids"])
            except (ValueError, KeyError, TypeError):
                gone = set()
            self.gen.groups = [g for g in self.gen.groups if g not in gone]
        return page_tool in OFFICIAL_MUTATIONS


def _text(res) -> str:
    return "\n".join(getattr(b, "text", "") for b in res.content)


RAW_INIT = {
    "jsonrpc": "2.0",
    "id": 0,
    "method": "initialize",
    "params": {"protocolVersion": "2025-06-18", "capabilities": {}, "clientInfo": {"name": "fuzz", "version": "0"}},
}


def raw_lines(n: int, seed: int, cmd: list[str]) -> dict:
    """Send ``n`` undecodable or non-JSON-RPC lines; each must get an error reply."""
    r = random.Random(seed)
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    unanswered = 0

    def send(line: str):
        proc.stdin.write(line.encode("utf-8", "surrogatepass") + b"\n")
        proc.stdin.flush()

    def reply(timeout=30.0):
        ready, _, _ = select.select([proc.stdout], [], [], timeout)
        return json.loads(proc.stdout.readline()) if ready else None

    send(json.dumps(RAW_INIT))
    reply(120)
    send(json.dumps({"jsonrpc": "2.0", "method": "notifications/initialized"}))
    call = '{"jsonrpc":"2.0","id":%d,"method":"tools/call","params":{"name":"get_object","arguments":{"id":%s}}}'
    for i in range(1, n + 1):
        kind = i % 6
        if kind == 0:
            line = call % (i, "1" * r.randint(4301, 6000))
        elif kind == 1:
            d = r.randint(300, 6000)
            line = call % (i, "[" * d + "]" * d)
        elif kind == 2:
            line = (call % (i, '"p01"'))[: r.randint(5, 80)]
        elif kind == 3:
            line = json.dumps({"jsonrpc": "2.0", "id": i, "params": {}})
        elif kind == 4:
            line = "".join(r.choice('{}[]",:0123456789abc \\') for _ in range(r.randint(1, 60)))
            line = line.replace("\n", " ")
        else:
            line = json.dumps([1, {"id": i}])
        send(line)
        msg = reply()
        if msg is None or "error" not in msg:
            unanswered += 1
            if proc.poll() is not None:
                break
    send(json.dumps({"jsonrpc": "2.0", "id": n + 1, "method": "tools/list"}))
    alive = reply(60) is not None
    proc.stdin.close()
    proc.wait(60)
    return {"lines": n, "unanswered": unanswered, "server_alive_after": alive}


def _describe(exc: BaseException) -> str:
    """The innermost exceptions of a (nested) exception group, one line."""
    if isinstance(exc, BaseExceptionGroup):
        return "; ".join(_describe(e) for e in exc.exceptions)
    return f"{type(exc).__name__}: {exc}"


def _state(result) -> dict:
    s = result.structured_content or {}
    return {k: s.get(k) for k in ("poses", "groups", "camera")}


async def fuzz_calls(
    n: int,
    seed: int,
    timeout: float,
    task_dir: Path,
    run_root: Path,
    hidden: Hidden,
    log_every: int,
    max_seconds: float = math.inf,
    surface: str = "default",
) -> dict:
    driver = (OfficialDriver if surface == "official" else DefaultDriver)(seed)
    gen = driver.gen
    stats = {
        "surface": surface,
        "calls": 0,
        "ok": 0,
        "errors": 0,
        "crashes": 0,
        "hangs": 0,
        "state_changes_on_error": 0,
        "unrecorded_calls": 0,
        "leaks": 0,
        "examples": [],
        "servers": 0,
        "rss_mb": {},
    }
    t_start = time.perf_counter()
    deadline = t_start + max_seconds
    while stats["calls"] < n and time.perf_counter() < deadline:
        stats["servers"] += 1
        run = run_root / f"run{stats['servers']}"
        params = StdioServerParameters(
            command=sys.executable,
            args=[
                "-m",
                "aw_server.cli",
                str(task_dir),
                "--record",
                str(run),
                "--budget-minutes",
                "100000",
                *driver.server_args,
            ],
            env=dict(os.environ),
        )
        made = 0
        try:
            async with Client(params) as c:
                server = next(
                    p
                    for p in psutil.Process().children(recursive=True)
                    if "aw_server.cli" in " ".join(p.cmdline()) and str(run) in " ".join(p.cmdline())
                )
                before = await driver.state(c)
                made += 1
                while stats["calls"] < n and time.perf_counter() < deadline:
                    tool, args = gen.next()
                    try:
                        with anyio.fail_after(timeout):
                            res = await c.call_tool(tool, args)
                    except TimeoutError:
                        stats["hangs"] += 1
                        stats["examples"].append({"hang": tool, "args": repr(args)[:300]})
                        break
                    made += driver.recorded(tool, args)
                    stats["calls"] += 1
                    text = _text(res)
                    if res.structured_content is not None:
                        text += json.dumps(res.structured_content)
                    leak = hidden.leaks(text)
                    if leak:
                        stats["leaks"] += 1
                        stats["examples"].append({"leak": leak, "tool": tool, "args": repr(args)[:300]})
                    if driver.failed(res):
                        stats["errors"] += 1
                        after = await driver.state(c)
                        made += 1
                        if after != before:
                            stats["state_changes_on_error"] += 1
                            stats["examples"].append(
                                {"state_change": tool, "args": repr(args)[:300], "reply": text[:300]}
                            )
                        before = after
                    else:
                        stats["ok"] += 1
                        if driver.succeeded(tool, args, res):
                            before = await driver.state(c)
                            made += 1
                    if stats["calls"] == WARMUP_CALLS:
                        stats["rss_mb"][f"after_{WARMUP_CALLS}_calls"] = round(server.memory_info().rss / 2**20, 1)
                    if log_every and stats["calls"] % log_every == 0:
                        rate = stats["calls"] / (time.perf_counter() - t_start)
                        print(
                            f"fuzz: {stats['calls']} calls ({rate:.0f}/s), {stats['errors']} errors, "
                            f"crashes {stats['crashes']}, hangs {stats['hangs']}, state changes "
                            f"{stats['state_changes_on_error']}, leaks {stats['leaks']}",
                            file=sys.stderr,
                            flush=True,
                        )
                stats["rss_mb"]["end"] = round(server.memory_info().rss / 2**20, 1)
        except Exception as exc:  # the session broke: the server died or answered garbage
            stats["crashes"] += 1
            last = locals().get("tool"), repr(locals().get("args"))[:300]
            stats["examples"].append({"crash": _describe(exc)[:300], "last_call": last})
            print(f"fuzz: session broke after {last}: {_describe(exc)}"[:600], file=sys.stderr, flush=True)
        traj = run / "trajectory.jsonl"
        if traj.exists():
            recorded = sum(1 for line in traj.read_bytes().splitlines() if line.startswith(b'{"type":"call"'))
            if made != recorded:
                stats["examples"].append({"recorded": recorded, "calls_to_record": made})
            stats["unrecorded_calls"] += max(0, made - recorded)
    stats["seconds"] = round(time.perf_counter() - t_start, 1)
    stats["calls_requested"] = n
    return stats


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--surface",
        choices=("default", "official"),
        default="default",
        help="the tools fuzzed: aw-serve's own (default) or the official surface's",
    )
    p.add_argument("--calls", type=int, default=100_000, help="fuzzed tool calls (default 100000)")
    p.add_argument("--raw-lines", type=int, default=2000, help="undecodable transport lines (default 2000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--timeout", type=float, default=60.0, help="seconds without a reply that count as a hang")
    p.add_argument("--out", type=Path, help="write the summary JSON here")
    p.add_argument("--log-every", type=int, default=5000)
    p.add_argument(
        "--max-seconds",
        type=float,
        default=math.inf,
        help="stop the tool calls after this long (the summary says how many were made)",
    )
    args = p.parse_args(argv)
    if args.out is not None and args.out.exists():
        p.error(f"--out {args.out} already exists (results are never overwritten)")
    with tempfile.TemporaryDirectory(prefix="aw-fuzz-") as tmp:
        root = Path(tmp)
        suite = box_suite(root / "suite", objects_per_source=1, n_parts=3, blocks=(("partnet", ("none",)),))
        task_id = read_manifest(suite).tasks[0].task_id
        task_dir, targets = suite_paths(suite, task_id)
        hidden = Hidden(Path(task_dir), Path(targets))
        stats = anyio.run(
            fuzz_calls,
            args.calls,
            args.seed,
            args.timeout,
            Path(task_dir),
            root / "runs",
            hidden,
            args.log_every,
            args.max_seconds,
            args.surface,
        )
        if args.raw_lines:
            cmd = [
                sys.executable,
                "-m",
                "aw_server.cli",
                str(task_dir),
                "--record",
                str(root / "raw"),
                "--surface",
                args.surface,
            ]
            stats["raw"] = raw_lines(args.raw_lines, args.seed, cmd)
    stats["command"] = "python benchmarks/fuzz_server.py " + " ".join(argv if argv is not None else sys.argv[1:])
    stats["examples"] = stats["examples"][:20]
    text = json.dumps(stats, indent=2)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    bad = (
        stats["crashes"]
        + stats["hangs"]
        + stats["state_changes_on_error"]
        + stats["unrecorded_calls"]
        + stats["leaks"]
        + stats.get("raw", {}).get("unanswered", 0)
    )
    return 1 if bad or not stats.get("raw", {"server_alive_after": True})["server_alive_after"] else 0


if __name__ == "__main__":
    sys.exit(main())
