"""aw-view's update delay and its cost to an episode, measured as a user would meet them.

    .venv/bin/python benchmarks/bench_view.py [--calls 40] [--pause 0.7] [--rounds 2] --out DIR

A real ``aw-serve`` is driven over MCP (stdio) by a scripted client on a synthetic task; ``aw-view``
runs as its own process on the runs folder; Debian's Chromium (playwright) shows its runs page
and the episode's page, following the episode.

1. **Update delay**: for each recorded call (``translate_objects`` / ``capture_scene`` in turn,
   ``--pause`` seconds apart), the time from the client having the reply (its line is on disk
   before the reply is sent) to each page showing it (a MutationObserver in the page notes the
   time the call count changes; one clock: this machine's).
2. **Call latency** with nobody watching against the viewer and both pages watching:
   ``--calls`` calls of each kind, timed by the client, in ``--rounds`` alternating rounds.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CHROMIUM = "/usr/bin/chromium"
OBSERVE_RUNS = """() => { window.awSeen = []; new MutationObserver(() => {
    const td = document.querySelector('#runs tbody td.calls');
    if (td) window.awSeen.push([Date.now() / 1000, parseInt(td.textContent, 10)]);
  }).observe(document.querySelector('#runs tbody'), {subtree: true, childList: true, characterData: true}); }"""
OBSERVE_EPISODE = """() => { window.awSeen = []; new MutationObserver(() => {
    window.awSeen.push([Date.now() / 1000, parseInt(document.body.dataset.calls || '0', 10)]);
  }).observe(document.body, {attributes: true, attributeFilter: ['data-calls']}); }"""


def stats_ms(samples: list[float]) -> dict:
    ms = sorted(1000 * s for s in samples)
    return {
        "n": len(ms),
        "median_ms": statistics.median(ms),
        "p90_ms": ms[min(len(ms) - 1, int(0.9 * len(ms)))],
        "max_ms": ms[-1],
    }


class Agent:
    """An MCP client on a real aw-serve, in a thread of its own (anyio's blocking portal)."""

    def __init__(self, task_dir: Path, run_dir: Path):
        from anyio.from_thread import start_blocking_portal
        from mcp import Client, StdioServerParameters

        env = {**os.environ, "PYOPENGL_PLATFORM": os.environ.get("PYOPENGL_PLATFORM", "egl")}
        params = StdioServerParameters(
            command=sys.executable, args=["-m", "aw_server.cli", str(task_dir), "--record", str(run_dir)], env=env
        )
        self._portal_cm = start_blocking_portal()
        self.portal = self._portal_cm.__enter__()
        self._client_cm = self.portal.wrap_async_context_manager(Client(params))  # entered and left in one task
        self.client = self._client_cm.__enter__()

    def call(self, tool: str, args: dict) -> float:
        """Seconds the call took; returns once its reply is here."""
        t = time.perf_counter()
        r = self.portal.call(self.client.call_tool, tool, args)
        assert not r.is_error, r
        return time.perf_counter() - t

    def close(self) -> None:
        self._client_cm.__exit__(None, None, None)
        self._portal_cm.__exit__(None, None, None)


def _step(agent: Agent, k: int) -> tuple[str, float]:
    if k % 2 == 0:
        return "translate_objects", agent.call("translate_objects", {"ids": ["p01"], "delta": [0.01 * (-1) ** k, 0, 0]})
    return "capture_scene", agent.call("capture_scene", {})


def _latencies(agent: Agent, n: int) -> dict[str, list[float]]:
    out: dict[str, list[float]] = {"translate_objects": [], "capture_scene": []}
    for k in range(2 * n):
        tool, s = _step(agent, k)
        out[tool].append(s)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--calls", type=int, default=40, help="calls of each kind per round (latency)")
    p.add_argument("--rounds", type=int, default=2, help="rounds without and with the viewer, alternating")
    p.add_argument("--pause", type=float, default=0.7, help="seconds between calls while the delay is measured")
    p.add_argument("--delay-calls", type=int, default=20, help="calls whose update delay is measured")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder to write bench_view.json to")
    args = p.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _output import output_file

    out = output_file(args.out, "bench_view.json")
    from playwright.sync_api import sync_playwright

    from aw.formats import read_manifest
    from aw.formats.suite import suite_paths
    from aw_eval.study.fixtures import box_suite

    res: dict = {"load_before": os.getloadavg()}
    with tempfile.TemporaryDirectory() as tmp:
        suite = box_suite(Path(tmp) / "suite", objects_per_source=1, n_parts=5, blocks=(("partnet", ("none",)),))
        (task_id,) = [t.task_id for t in read_manifest(suite).tasks]
        task_dir = suite_paths(suite, task_id)[0]
        runs = Path(tmp) / "runs"
        runs.mkdir()
        view_bin = Path(sys.executable).with_name("aw-view")
        viewer = subprocess.Popen(
            [str(view_bin), str(runs), "--port", "0", "--tasks", str(suite / "tasks")],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )
        url = viewer.stdout.readline().strip().rsplit(" at ", 1)[1]
        agent = Agent(task_dir, runs / "bench" / task_id)
        agent.call("start_episode", {})
        try:
            with sync_playwright() as pw:
                browser = pw.chromium.launch(
                    executable_path=CHROMIUM, args=["--enable-unsafe-swiftshader", "--use-angle=swiftshader"]
                )
                runs_page = browser.new_page(viewport={"width": 1300, "height": 900})
                runs_page.goto(url)
                runs_page.wait_for_selector("#runs tbody td.calls", timeout=300_000)
                episode = browser.new_page(viewport={"width": 1300, "height": 900})
                episode.goto(f"{url}episode/bench/{task_id}")
                episode.wait_for_selector("#plot[data-ready='1']", timeout=300_000)
                runs_page.evaluate(OBSERVE_RUNS)
                episode.evaluate(OBSERVE_EPISODE)

                # 1. update delay
                done = {}
                n0 = 1
                for k in range(args.delay_calls):
                    time.sleep(args.pause)
                    _step(agent, k)
                    done[n0 + k + 1] = time.time()
                time.sleep(3.0)
                delays = {}
                for name, page in (("runs_page", runs_page), ("episode_page", episode)):
                    seen = page.evaluate("() => window.awSeen")
                    d = []
                    for count, t_done in done.items():
                        shown = [t for t, c in seen if c >= count]
                        if shown:
                            d.append(max(0.0, min(shown) - t_done))
                    delays[name] = stats_ms(d) | {"missed": len(done) - len(d)}
                res["update_delay"] = delays

                # 2. call latency, nobody watching vs the viewer and both pages watching
                watched: dict[str, list[float]] = {"translate_objects": [], "capture_scene": []}
                alone: dict[str, list[float]] = {"translate_objects": [], "capture_scene": []}
                for r in range(args.rounds):
                    for mode in ("alone", "watched") if r % 2 == 0 else ("watched", "alone"):
                        if mode == "alone":
                            runs_page.goto("about:blank")
                            episode.goto("about:blank")
                            viewer.send_signal(19)  # SIGSTOP: the viewer takes no CPU at all
                            got = _latencies(agent, args.calls)
                            viewer.send_signal(18)  # SIGCONT
                            for k, v in got.items():
                                alone[k] += v
                        else:
                            runs_page.goto(url)
                            episode.goto(f"{url}episode/bench/{task_id}")
                            episode.wait_for_selector("#plot[data-ready='1']", timeout=300_000)
                            got = _latencies(agent, args.calls)
                            for k, v in got.items():
                                watched[k] += v
                res["call_latency"] = {
                    "alone": {k: stats_ms(v) for k, v in alone.items()},
                    "watched": {k: stats_ms(v) for k, v in watched.items()},
                }
                browser.close()
        finally:
            agent.close()
            viewer.terminate()
            viewer.wait(timeout=30)
    res.update(
        load_after=os.getloadavg(),
        calls=args.calls,
        rounds=args.rounds,
        pause=args.pause,
        python=platform.python_version(),
        cpus=os.cpu_count(),
        command=" ".join([Path(sys.executable).name, *sys.argv]),
    )
    print(f"aw-view on {os.cpu_count()} CPUs, load {res['load_before'][0]:.1f} -> {res['load_after'][0]:.1f}")
    for name, s in res["update_delay"].items():
        print(
            f"  recorded call -> {name:<13} median {s['median_ms']:6.0f} ms  p90 {s['p90_ms']:6.0f} ms  "
            f"max {s['max_ms']:6.0f} ms  (n {s['n']}, missed {s['missed']})"
        )
    for tool in ("translate_objects", "capture_scene"):
        a, w = res["call_latency"]["alone"][tool], res["call_latency"]["watched"][tool]
        print(
            f"  {tool:<18} alone median {a['median_ms']:6.1f} ms p90 {a['p90_ms']:6.1f}  |  "
            f"watched median {w['median_ms']:6.1f} ms p90 {w['p90_ms']:6.1f}  (n {a['n']} / {w['n']})"
        )
    out.write_text(json.dumps(res, indent=2) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
