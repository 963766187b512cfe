"""Evaluator benchmark: checkpoints per second of the reference, ``exact`` and ``fast`` on the same
checkpoints, compile time apart, peak memory, and the agreement of ``fast`` with ``exact``.

Prints a table and writes JSON to ``--out DIR`` (``DIR/bench_eval.json``, or ``--name``). Geometry is
synthetic (:mod:`aw_eval.fixtures`): tables of 2-20 parts with identical legs and symmetric
parts; checkpoints come from agent-like synthetic trajectories. Examples::

    # issue 3/8 throughput table (reference on few checkpoints: it takes minutes each)
    .venv/bin/python benchmarks/bench_eval.py --parts 2 5 10 --ref 2 --fast-batches 1 100 --out OUT
    # agreement of fast against exact on many checkpoints at reduced resolution
    .venv/bin/python benchmarks/bench_eval.py --parts 2 5 10 --ref 0 --exact 0 --agreement 1000 --agree-fps 64 --out OUT

Every figure is measured in one process on this machine; ratios compare runs on identical
checkpoints, the reference and ``exact`` alternating checkpoint by checkpoint. ``--workers`` is not offered on purpose: throughput per process is reported, and a
pool of ``k`` processes (``aw-score`` does that) multiplies it by about ``k`` on ``k`` free cores.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(Path(__file__).resolve().parents[1] / ".jax_cache"))

import aw_eval  # noqa: E402
from aw_eval import reference as ref  # noqa: E402
from aw_eval.fixtures import make_points_geometry, trajectory_checkpoints  # noqa: E402


def peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def time_calls(fn, items):
    t0 = time.perf_counter()
    res = [fn(x) for x in items]
    return time.perf_counter() - t0, res


def bench_parts(p: int, args, rows: list, agree: list) -> None:
    t0 = time.perf_counter()
    geom, obj = make_points_geometry(
        p, args.n_fps, seed=p, settings=aw_eval.ProtocolSettings(n_fps=args.n_fps, n_surface=max(4096, 4 * args.n_fps))
    )
    t_geom = time.perf_counter() - t0
    n_need = max(args.ref, args.exact, max(args.fast_batches or [0]), 1)
    cks = trajectory_checkpoints(obj, n_need + 1, seed=1000 + p)
    # compile (JAX) apart: the first fast call on this shape
    t0 = time.perf_counter()
    aw_eval.score(geom, cks[-1], mode="fast")
    first_fast = time.perf_counter() - t0
    t0 = time.perf_counter()
    aw_eval.score(geom, cks[-1], mode="fast")
    warm_fast = time.perf_counter() - t0
    row = {
        "parts": p,
        "points_per_part": args.n_fps,
        "geometry_s": t_geom,
        "fast_first_call_s": first_fast,
        "fast_warm_call_s": warm_fast,
        "compile_s": max(0.0, first_fast - warm_fast),
    }
    same = cks[: max(args.ref, args.exact)]

    def ref_score(c):
        return ref.score(geom.clouds, geom.target_poses, geom.divisor, geom.groups, c, geom.settings)

    def exact_score(c):
        return aw_eval.score(geom, c, mode="exact")

    # reference and exact alternate checkpoint by checkpoint, so that a shared machine's load
    # changes weigh on both alike
    t_ref = t_exact = 0.0
    rres, eres = [], []
    for i in range(max(args.ref, args.exact)):
        for on, fn, out in ((i < args.ref, ref_score, rres), (i < args.exact, exact_score, eres)):
            if on:
                t, res = time_calls(fn, same[i : i + 1])
                out += res
                if fn is ref_score:
                    t_ref += t
                else:
                    t_exact += t
    if args.ref:
        row["reference_s_per_ck"] = t_ref / args.ref
    if args.exact:
        row["exact_s_per_ck"] = t_exact / args.exact
        row["peak_mib_after_exact"] = peak_mib()
        if args.ref:
            k = min(args.ref, args.exact)
            row["exact_vs_reference_identical_pa_sr"] = sum(
                (e.pa, e.sr) == (r.pa, r.sr) for e, r in zip(eres[:k], rres[:k], strict=True)
            )
            row["exact_vs_reference_max_rel_scd"] = max(
                abs(e.scd - r.scd) / max(r.scd, 1e-300) for e, r in zip(eres[:k], rres[:k], strict=True)
            )
            row["exact_vs_reference_compared"] = k
    t, fres = time_calls(lambda c: aw_eval.score(geom, c, mode="fast"), same if len(same) else cks[:1])
    row["fast_s_per_ck_same"] = t / max(1, len(same) or 1)
    for b in args.fast_batches:
        batch = cks[:b]
        t0 = time.perf_counter()
        out = aw_eval.score_batch(geom, batch, mode="fast")
        dt = time.perf_counter() - t0
        row[f"fast_batch{b}_ck_per_s"] = b / dt
        row[f"fast_batch{b}_unique"] = out.n_unique
    row["peak_mib"] = peak_mib()
    if "reference_s_per_ck" in row:
        row["exact_speedup"] = row["reference_s_per_ck"] / row["exact_s_per_ck"] if "exact_s_per_ck" in row else None
        row["fast_speedup"] = row["reference_s_per_ck"] / row["fast_s_per_ck_same"]
    rows.append(row)
    print(json.dumps(row), flush=True)


_GEOMS: dict = {}


def _fast_settings(pairs: list[str], exact_margin: float | None) -> dict:
    """``KEY=VALUE`` strings (and ``--exact-margin``) -> FastSettings fields, typed like the defaults."""
    from aw_eval.kernels import fast

    kw = {}
    for item in pairs:
        key, _, value = item.partition("=")
        if not hasattr(fast.FAST, key) or not value:
            raise SystemExit(f"--fast-set: {item!r} is not KEY=VALUE for a FastSettings field")
        kw[key] = type(getattr(fast.FAST, key))(value)
    if exact_margin is not None:
        kw["exact_margin"] = exact_margin
    return kw


def _apply_fast_settings(kw: dict) -> None:
    import dataclasses

    from aw_eval.kernels import fast

    fast.FAST = dataclasses.replace(fast.FastSettings(), **kw)


def _agreement_chunk(job):
    """Exact and fast on checkpoints ``lo:hi`` of the ``p``-part trajectory set (one worker)."""
    p, fps, seed, k, lo, hi, fast_kw = job
    _apply_fast_settings(fast_kw)  # spawned workers start from the defaults
    if (p, fps) not in _GEOMS:
        st = aw_eval.ProtocolSettings(n_fps=fps, n_surface=max(4096, 4 * fps))
        geom, obj = make_points_geometry(p, fps, seed=p, settings=st)
        _GEOMS[(p, fps)] = (geom, trajectory_checkpoints(obj, k, seed=seed + 7 * p))
    geom, cks = _GEOMS[(p, fps)]
    cks = cks[lo:hi]
    t0 = time.perf_counter()
    e = aw_eval.score_batch(geom, cks, mode="exact")
    t_exact = time.perf_counter() - t0
    t0 = time.perf_counter()
    f = aw_eval.score_batch(geom, cks, mode="fast")
    t_fast = time.perf_counter() - t0
    return p, e.pa, e.sr, e.scd, f.pa, f.sr, f.scd, e.n_unique, t_exact, t_fast


def _log_chunk(log: Path | None, out) -> None:
    """Append one chunk's results to ``log`` (JSON lines), so a run stopped early keeps them."""
    if log is None:
        return
    p, epa, esr, escd, fpa, fsr, fscd, n_unique, te, tf = out
    row = {
        "parts": p,
        "pa_exact": epa.tolist(),
        "sr_exact": esr.tolist(),
        "scd_exact": escd.tolist(),
        "pa_fast": fpa.tolist(),
        "sr_fast": fsr.tolist(),
        "scd_fast": fscd.tolist(),
        "unique": n_unique,
        "exact_s": te,
        "fast_s": tf,
    }
    with open(log, "a") as fh:
        fh.write(json.dumps(row) + "\n")


def bench_agreement(
    parts: list[int],
    n: int,
    fps: int,
    seed: int = 0,
    workers: int = 1,
    chunk: int = 6,
    log: Path | None = None,
    fast_kw: dict | None = None,
) -> dict:
    """Fast vs exact (exact == reference by the tests) on ``n`` trajectory checkpoints, split
    evenly over ``parts``; ``workers`` processes share the chunks (largest tasks first). Agreement
    does not depend on the worker count; the seconds are summed over workers."""
    per = {p: n // len(parts) + (1 if i < n % len(parts) else 0) for i, p in enumerate(parts)}
    jobs = [
        (p, fps, seed, k, lo, min(k, lo + chunk), fast_kw or {})
        for p, k in sorted(per.items(), reverse=True)
        for lo in range(0, k, chunk)
    ]
    if workers > 1:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        from aw_eval.kernels import compile_kernels

        compile_kernels()  # fill numba's on-disk cache once, before the workers load it

        with ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn")) as pool:
            outs = []
            for out in pool.map(_agreement_chunk, jobs):
                outs.append(out)
                _log_chunk(log, out)
    else:
        outs = []
        for j in jobs:
            outs.append(_agreement_chunk(j))
            _log_chunk(log, outs[-1])
    same_pa = same_sr = total = unique = 0
    rel = []
    t_exact = t_fast = 0.0
    flips = []
    by_parts: dict = {}
    for p, epa, esr, escd, fpa, fsr, fscd, n_unique, te, tf in outs:
        same_pa += int(np.sum(epa == fpa))
        same_sr += int(np.sum(esr == fsr))
        total += len(epa)
        unique += n_unique
        t_exact += te
        t_fast += tf
        rel += list(np.abs(fscd - escd) / np.maximum(escd, 1e-12))
        row = by_parts.setdefault(p, {"checkpoints": 0, "identical_pa_and_sr": 0})
        row["checkpoints"] += len(epa)
        row["identical_pa_and_sr"] += int(np.sum((epa == fpa) & (esr == fsr)))
        for i in np.flatnonzero((epa != fpa) | (esr != fsr)):
            flips.append(
                {
                    "parts": p,
                    "pa_exact": float(epa[i]),
                    "pa_fast": float(fpa[i]),
                    "scd_exact": float(escd[i]),
                    "scd_fast": float(fscd[i]),
                }
            )
    print(
        f"agreement: {total} checkpoints ({unique} unique), exact {t_exact:.1f}s fast {t_fast:.1f}s (worker seconds)",
        flush=True,
    )
    rel = np.asarray(rel)
    return {
        "checkpoints": total,
        "unique_checkpoints": unique,
        "points_per_part": fps,
        "parts": parts,
        "workers": workers,
        "by_parts": by_parts,
        "identical_pa": same_pa / total,
        "identical_sr": same_sr / total,
        "identical_pa_and_sr_count": total - len(flips),
        "scd_rel_err_median": float(np.median(rel)),
        "scd_rel_err_p99": float(np.quantile(rel, 0.99)),
        "scd_rel_err_max": float(rel.max()),
        "exact_worker_s": t_exact,
        "fast_worker_s": t_fast,
        "exact_over_fast_time": t_exact / max(t_fast, 1e-9),
        "disagreements": flips[:50],
    }


def agreement_from_logs(logs: list[Path], fps: int, seed: int = 0, check_exact: bool = False) -> dict:
    """``fast`` (this process, current code) against the ``exact`` results recorded in ``logs``
    (``--agree-log`` files of earlier agreement runs, for example from a larger machine): the
    checkpoints are regenerated deterministically (their order is prefix-stable), so ``exact``,
    the expensive side, is not run again. ``check_exact``: run it again all the same and compare
    its PA/SR decisions and SCD with the log (the labels still hold for the current code)."""
    exact: dict[int, dict[str, list]] = {}
    for log in logs:
        for line in Path(log).read_text().splitlines():
            r = json.loads(line)
            d = exact.setdefault(int(r["parts"]), {"pa": [], "sr": [], "scd": []})
            for k in ("pa", "sr", "scd"):
                d[k] += r[f"{k}_exact"]
    total = same = 0
    flips, rel, t_fast, by_parts = [], [], 0.0, {}
    for p, d in sorted(exact.items()):
        n = len(d["pa"])
        st = aw_eval.ProtocolSettings(n_fps=fps, n_surface=max(4096, 4 * fps))
        geom, obj = make_points_geometry(p, fps, seed=p, settings=st)
        cks = trajectory_checkpoints(obj, n, seed=seed + 7 * p)
        t0 = time.perf_counter()
        f = aw_eval.score_batch(geom, cks, mode="fast")
        t_fast += time.perf_counter() - t0
        epa, esr, escd = np.asarray(d["pa"]), np.asarray(d["sr"]), np.asarray(d["scd"])
        ok = (epa == f.pa) & (esr == f.sr)
        by_parts[p] = {"checkpoints": n, "identical_pa_and_sr": int(ok.sum())}
        total += n
        same += int(ok.sum())
        rel += list(np.abs(f.scd - escd) / np.maximum(escd, 1e-12))
        if check_exact:
            t0 = time.perf_counter()
            e = aw_eval.score_batch(geom, cks, mode="exact")
            same_exact = (epa == e.pa) & (esr == e.sr)
            by_parts[p]["exact_rerun"] = {
                "identical_pa_and_sr": int(same_exact.sum()),
                "seconds": time.perf_counter() - t0,
                "scd_rel_diff_max": float(np.max(np.abs(e.scd - escd) / np.maximum(escd, 1e-300))),
            }
            print(f"exact re-run vs logged exact, parts={p}: {int(same_exact.sum())}/{n} identical", flush=True)
        for i in np.flatnonzero(~ok):
            flips.append(
                {
                    "parts": p,
                    "index": int(i),
                    "pa_exact": float(epa[i]),
                    "pa_fast": float(f.pa[i]),
                    "scd_exact": float(escd[i]),
                    "scd_fast": float(f.scd[i]),
                    "part_errors_fast": [float(x) for x in f.part_errors[i]],
                }
            )
        print(
            f"agreement vs logged exact, parts={p}: {int(ok.sum())}/{n} identical, fast {t_fast:.1f}s so far",
            flush=True,
        )
    rel = np.asarray(rel)
    return {
        "checkpoints": total,
        "identical_pa_and_sr_count": same,
        "identical_rate": same / total,
        "by_parts": by_parts,
        "points_per_part": fps,
        "exact_logs": [str(x) for x in logs],
        "scd_rel_err_median": float(np.median(rel)),
        "scd_rel_err_p99": float(np.quantile(rel, 0.99)),
        "scd_rel_err_max": float(rel.max()),
        "fast_s": t_fast,
        "disagreements": flips,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", type=int, nargs="*", default=[2, 5, 10, 20])
    ap.add_argument("--n-fps", type=int, default=1000, help="points per part (paper: 1000)")
    ap.add_argument("--ref", type=int, default=1, help="checkpoints scored by the reference per part count")
    ap.add_argument(
        "--exact", type=int, default=1, help="checkpoints scored by exact (the first --ref of them are shared)"
    )
    ap.add_argument("--fast-batches", type=int, nargs="*", default=[1, 100])
    ap.add_argument("--agreement", type=int, default=0, help="checkpoints for the fast-vs-exact agreement")
    ap.add_argument("--agree-fps", type=int, default=64)
    ap.add_argument("--agree-parts", type=int, nargs="+", default=[2, 5, 10])
    ap.add_argument(
        "--agree-exact-log",
        type=Path,
        nargs="*",
        default=[],
        help="score fast against the exact results of these --agree-log files (exact is not re-run)",
    )
    ap.add_argument("--agree-log", type=Path, default=None, help="JSON lines of every chunk's results, as they finish")
    ap.add_argument(
        "--agree-workers",
        type=int,
        default=1,
        help="processes for the agreement run (agreement does not depend on it; timings are worker seconds)",
    )
    ap.add_argument(
        "--exact-margin",
        type=float,
        default=None,
        help="run fast with FastSettings(exact_margin=M), the opt-in exact fallback near thresholds",
    )
    ap.add_argument(
        "--fast-set",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="run fast with these FastSettings fields (e.g. coarse=16), in this process and the workers",
    )
    ap.add_argument(
        "--agree-seed", type=int, default=0, help="seed of the agreement trajectories (0: the recorded set)"
    )
    ap.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder to write the JSON to (a new file)")
    ap.add_argument(
        "--name", default="bench_eval", help="the JSON file's name in --out, without .json (default bench_eval)"
    )
    ap.add_argument(
        "--agree-check-exact",
        action="store_true",
        help="with --agree-exact-log: also re-run exact on the logged checkpoints and compare it with the log",
    )
    args = ap.parse_args(argv)
    from _output import output_file

    out = output_file(args.out, f"{args.name}.json")  # refused before the run, not after it
    fast_kw = _fast_settings(args.fast_set, args.exact_margin)
    _apply_fast_settings(fast_kw)
    rows: list = []
    result = {
        "command": " ".join(["benchmarks/bench_eval.py"] + (argv if argv is not None else sys.argv[1:])),
        "machine": {
            "cpus": os.cpu_count(),
            "platform": platform.platform(),
            "python": platform.python_version(),
            "load_avg_start": os.getloadavg(),
        },
        "rows": rows,
    }
    for p in args.parts:
        bench_parts(p, args, rows, [])
    if args.agreement:
        result["agreement"] = bench_agreement(
            args.agree_parts,
            args.agreement,
            args.agree_fps,
            seed=args.agree_seed,
            workers=args.agree_workers,
            log=args.agree_log,
            fast_kw=fast_kw,
        )
        print(json.dumps({k: v for k, v in result["agreement"].items() if k != "disagreements"}), flush=True)
    if args.agree_exact_log:
        result["agreement_vs_logged_exact"] = agreement_from_logs(
            args.agree_exact_log, args.agree_fps, seed=args.agree_seed, check_exact=args.agree_check_exact
        )
        result["agreement_vs_logged_exact"]["fast_settings"] = fast_kw
        a = result["agreement_vs_logged_exact"]
        print(json.dumps({k: v for k, v in a.items() if k != "disagreements"}), flush=True)
        for d in a["disagreements"]:
            print(json.dumps(d), flush=True)
    result["machine"]["load_avg_end"] = os.getloadavg()
    result["peak_mib"] = peak_mib()
    out.write_text(json.dumps(result, indent=1))
    print(f"wrote {out}")
    print("\n| parts | reference s/ck | exact s/ck | fast s/ck | exact x | fast x | compile s | peak MiB |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")

    def cell(r, k, fmt="{:.3g}"):
        v = r.get(k)
        return fmt.format(v) if isinstance(v, (int, float)) else "-"

    for r in rows:
        print(
            f"| {r['parts']} | {cell(r, 'reference_s_per_ck')} | {cell(r, 'exact_s_per_ck')} | "
            f"{cell(r, 'fast_s_per_ck_same')} | {cell(r, 'exact_speedup', '{:.1f}')} | "
            f"{cell(r, 'fast_speedup', '{:.0f}')} | {cell(r, 'compile_s', '{:.2f}')} | {cell(r, 'peak_mib', '{:.0f}')} |"
        )
    for r in rows:
        for b in args.fast_batches:
            print(
                f"parts={r['parts']} fast batch {b}: {r[f'fast_batch{b}_ck_per_s']:.2f} ck/s ({r[f'fast_batch{b}_unique']} unique)"
            )
    if "agreement" in result:
        a = result["agreement"]
        print(
            f"agreement fast vs exact: {a['checkpoints']} checkpoints at {a['points_per_part']} pts/part: "
            f"PA identical {a['identical_pa']:.4f}, SR identical {a['identical_sr']:.4f}, SCD rel err p99 {a['scd_rel_err_p99']:.2e}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
