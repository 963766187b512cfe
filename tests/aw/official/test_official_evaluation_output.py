"""``summary.json`` from ``metrics.jsonl`` rows equals the official summarization (expected
values worked out here by the rules of ``summarize`` in the official ``scoring.py``), including
the partial-run policy; the files round-trip."""

from __future__ import annotations

import json
import math

import pytest

from aw.formats import FormatError
from aw.official.evaluation_output import read_metrics, read_summary, summarize, write_evaluation

BLOCKS = ("partnet-none", "partnet-final-image", "ikea-manualbook", "assemblybench-manualbook", "fantastic-breaks-none")
SOURCES = ("partnet", "ikea-manualbook", "assemblybench-manualbook", "fantastic-breaks-none")


def _benchmark():
    ids = {b: [f"{k:04d}" for k in range(20)] for b in BLOCKS}
    ids["ikea-manualbook"] = [f"Chair/c{k}" for k in range(20)]
    return {
        "blocks": [
            {"name": b, "source": "partnet" if b.startswith("partnet") else b, "samples": {s: {} for s in ids[b]}}
            for b in BLOCKS
        ],
        "sources": list(SOURCES),
    }


def _rows(benchmark):
    """Every sample: block i scores SCD i + k/8, PA k/4 mod 1, SR 1 on even k; every fifth
    sample of the IKEA block is an error row."""
    rows = []
    for i, block in enumerate(benchmark["blocks"]):
        for k, sid in enumerate(block["samples"]):
            base = {
                "block": block["name"],
                "sample_id": sid,
                "run": "/logs/r",
                "duration_seconds": 10.0 + k,
                "usage": {"input_tokens": 100 * k, "output_tokens": None, "cached": 3},
                "cost_usd": None,
                "tool_calls": k if k % 2 else None,
                "attempt_finished": True,
            }
            if block["name"] == "ikea-manualbook" and k % 5 == 0:
                rows.append({**base, "status": "error", "error": "ValueError: x", "SCD": None, "PA": 0.0, "SR": 0})
            else:
                rows.append({**base, "status": "scored", "SCD": i + k / 8, "PA": (k % 4) / 4, "SR": int(k % 2 == 0)})
    return rows


def _mean(xs):
    return math.fsum(xs) / len(xs)


def _expected_block(rows, name):
    mine = [r for r in rows if r["block"] == name]
    scored = [r for r in mine if r["status"] == "scored"]
    return {
        "attempted": len(mine),
        "expected": 20,
        "scored": len(scored),
        "SCD": _mean([r["SCD"] for r in scored]) if scored else None,
        "PA": _mean([r["PA"] for r in mine]),
        "SR": _mean([r["SR"] for r in mine]),
    }


def _close(a, b):
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, float) and isinstance(b, float):
        return a == pytest.approx(b, rel=1e-15, abs=0)
    return a == b


def test_complete_run_gives_source_and_overall_means():
    bench = _benchmark()
    rows = _rows(bench)
    got = summarize(rows, bench)
    blocks = {b: _expected_block(rows, b) for b in BLOCKS}
    assert _close(got["blocks"], blocks)
    # IKEA: 4 error rows count 0 in PA and SR, and are left out of SCD
    assert got["blocks"]["ikea-manualbook"]["scored"] == 16
    sources = {
        s: {
            m: _mean([blocks[b][m] for b in BLOCKS if (b.startswith("partnet") and s == "partnet") or b == s])
            for m in ("SCD", "PA", "SR")
        }
        for s in SOURCES
    }
    assert _close(got["sources"], sources)
    overall = {m: _mean([sources[s][m] for s in SOURCES]) for m in ("SCD", "PA", "SR")}
    assert _close(got["official_overall"], overall)
    # the two PartNet blocks share one source: overall SCD weighs each source, not each block
    assert got["official_overall"]["SCD"] != pytest.approx(_mean([blocks[b]["SCD"] for b in BLOCKS]))
    assert (got["status"], got["attempted"], got["expected"], got["scored"]) == ("complete", 100, 100, 96)
    assert list(got) == [
        "protocol",
        "status",
        "attempted",
        "expected",
        "scored",
        "blocks",
        "official_overall",
        "resource_accounting",
        "sources",
        "resources",
        "token_usage",
    ]
    assert got["resources"]["cost_usd"] == {"reported_samples": 0, "mean": None}
    assert got["resources"]["tool_calls"] == {
        "reported_samples": 50,
        "mean": _mean([k for k in range(20) if k % 2] * 5),
    }
    assert got["resources"]["duration_seconds"]["mean"] == pytest.approx(10 + 9.5)
    # only *_tokens keys that some row reports
    assert got["token_usage"] == {"input_tokens": {"reported_samples": 100, "mean": pytest.approx(950.0)}}


def test_official_equal_source_weights_example():
    """The official test's numbers: block i scores SCD i, so the overall SCD is
    mean(0.5, 2, 3, 4) (the PartNet source averages blocks 0 and 1)."""
    bench = _benchmark()
    rows = [
        {"block": b["name"], "sample_id": s, "status": "scored", "SCD": float(i), "PA": i / 4, "SR": i % 2}
        for i, b in enumerate(bench["blocks"])
        for s in b["samples"]
    ]
    assert summarize(rows, bench)["official_overall"]["SCD"] == _mean([0.5, 2, 3, 4])
    assert summarize(rows[:20], bench)["official_overall"] is None


def test_partial_runs_get_no_overall():
    bench = _benchmark()
    rows = _rows(bench)
    for partial in (rows[:-1], [{**r, "attempt_finished": r is not rows[7]} for r in rows]):
        got = summarize(partial, bench)
        assert got["status"] == "partial" and got["official_overall"] is None and "sources" not in got
    got = summarize([r for r in rows if r["block"] == "ikea-manualbook"], bench)
    assert list(got["blocks"]) == ["ikea-manualbook"] and got["attempted"] == 20 and got["expected"] == 100
    extra = rows + [{**rows[0], "sample_id": "not-in-benchmark"}]
    assert summarize(extra, bench)["status"] == "partial"


def test_metrics_and_summary_files_round_trip(tmp_path):
    bench = _benchmark()
    rows = _rows(bench)[::-1]
    out = write_evaluation(tmp_path / "eval", rows, summarize(rows, bench))
    lines = (out / "metrics.jsonl").read_text().splitlines()
    back = read_metrics(out / "metrics.jsonl")
    assert [(r["block"], r["sample_id"]) for r in back] == sorted((r["block"], r["sample_id"]) for r in rows)
    assert lines[0] == json.dumps(back[0])
    assert summarize(back, bench) == read_summary(out / "summary.json")
    assert (out / "summary.json").read_text() == json.dumps(summarize(rows, bench), indent=2) + "\n"
    with pytest.raises(FileExistsError):
        write_evaluation(out, rows, {})


def test_bad_evaluation_files_get_named_errors(tmp_path):
    bad = tmp_path / "metrics.jsonl"
    bad.write_text('{"block": "b", "sample_id": "s", "status": "scored", "SCD": 1, "PA": 1}\n')
    with pytest.raises(FormatError, match=r"metrics.jsonl: line 1: missing \['SR'\]"):
        read_metrics(bad)
    bad.write_text("[1]\n")
    with pytest.raises(FormatError, match="line 1: expected a JSON object"):
        read_metrics(bad)
    bad.write_text("\n" + "[" * 3000 + "]" * 3000 + "\n")
    with pytest.raises(FormatError, match="metrics.jsonl: line 2: JSON nested deeper than 64 levels"):
        read_metrics(bad)
    summary = tmp_path / "summary.json"
    summary.write_text('{"protocol": "v0"}')
    with pytest.raises(FormatError, match="summary.json: not an official summary"):
        read_summary(summary)
    summary.write_text('{"protocol": "v0", "protocol": "v1"}')
    with pytest.raises(FormatError, match="summary.json: duplicate key 'protocol'"):
        read_summary(summary)


def test_comparing_two_evaluations(tmp_path, capsys):
    from aw.official.evaluation_output import compare_evaluations, main

    bench = _benchmark()
    rows = _rows(bench)
    a = write_evaluation(tmp_path / "a", rows, summarize(rows, bench))
    near = [{**r, "SCD": r["SCD"] * (1 + 1e-13)} if r["status"] == "scored" else r for r in rows]
    b = write_evaluation(tmp_path / "b", near, summarize(near, bench))
    assert compare_evaluations(a, b) == [] and main([str(a), str(b)]) == 0
    changed = [dict(r) for r in rows[:-1]]
    changed[3]["PA"] = 0.5 if changed[3]["PA"] != 0.5 else 0.25
    c = write_evaluation(tmp_path / "c", changed, summarize(changed, bench))
    diffs = compare_evaluations(a, c)
    assert f"{rows[-1]['block']}/{rows[-1]['sample_id']}: only in {a}" in diffs
    assert any(d.startswith(f"{rows[3]['block']}/{rows[3]['sample_id']}: PA") for d in diffs)
    assert "summary: status 'complete' != 'partial'" in diffs
    assert main([str(a), str(c)]) == 1 and "differences" in capsys.readouterr().out
    assert main([str(a), str(tmp_path / "missing")]) == 2
