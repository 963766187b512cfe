"""report.md reads on its own: it opens with how to read it (headline, the four metrics, which
rows are calibration or floor, warnings such as a study too small for its tests), bolds only
real systems, and keeps Table 1's caption short."""

from __future__ import annotations

import re

import numpy as np
import pytest

from aw.formats import RunInfo, TokenUsage
from aw_eval.analyses import system_roles
from aw_eval.report import AnalysisSettings, build_results, render_markdown
from aw_eval.stats import randomization_pvalues, smallest_pvalue
from tests.aw_eval.score_helpers import make_study, paper_entries, run_from_errors

FAST = AnalysisSettings(n_draws=200, n_permutations=2000)
GOOD, HALF, BAD = [0.001] * 4, [0.001, 0.001, 0.5, 0.5], [0.5] * 4
# (run.json agent or None, per-part errors, wall seconds, calls): the oracles read the targets and
# win everything; idle is the fastest and cheapest and (its parts started in place) not at PA 0
SYSTEMS = {
    "heuristic": ("heuristic", HALF, 300.0, 80),
    "mine": (None, [0.001, 0.5, 0.5, 0.5], 200.0, 60),
    "oracle-noise0.5": ("oracle", GOOD, 120.0, 30),
    "oracle": (None, GOOD, 100.0, 30),
    "idle": ("idle", [0.001, 0.5, 0.5, 0.5], 5.0, 3),
}


def _study(n_objects: int, systems=SYSTEMS, blocks=None):
    entries = paper_entries(n_objects=n_objects)
    if blocks is not None:
        entries = [e for e in entries if (e.source, e.condition) in blocks]
    runs, infos = {}, {}
    for s, (agent, errors, wall, calls) in systems.items():
        for e in entries:
            runs[(s, e.task_id)] = run_from_errors(s, e.task_id, errors)
            infos[(s, e.task_id)] = RunInfo(
                system=s, task_id=e.task_id, agent=agent or "", wall_seconds=wall, mcp_calls=calls
            )
    return make_study(entries, runs, infos)


def _section(md: str, title: str) -> str:
    return md.split(f"## {title}")[1].split("\n## ")[0]


def _rows(table: str) -> dict[str, list[str]]:
    out = {}
    for line in table.splitlines():
        if line.startswith("| ") and not line.startswith("| System") and not line.startswith("| ---"):
            cells = [c.strip() for c in line.split("|")[1:-1]]
            out[cells[0]] = cells[1:]
    return out


@pytest.fixture(scope="module")
def small():
    """Three tasks on three objects (IKEA, AssemblyBench, Fantastic Breaks: one object each)."""
    study = _study(1, blocks={("ikea_manual", "manual"), ("assemblybench", "manual"), ("fantastic_breaks", "none")})
    doc = build_results(study, FAST)
    return doc, render_markdown(doc)


def test_roles_come_from_the_run_json_agent_else_from_baseline_names():
    from aw.agents import AGENTS, NEEDS_TARGETS, ROLES

    assert set(ROLES) == set(AGENTS) and all(ROLES[a] == "calibration" for a in NEEDS_TARGETS)
    roles = system_roles(_study(1))
    assert roles == {
        "heuristic": "system",
        "mine": "system",
        "oracle-noise0.5": "calibration",
        "oracle": "calibration",
        "idle": "floor",
    }
    # an own system named like nothing known is real; a run.json agent outranks the name
    named = {
        "idle-views3": (None, GOOD, 1.0, 1),
        "random": (None, GOOD, 1.0, 1),
        "oracles-fan": (None, GOOD, 1.0, 1),
        "idle-but-oracle": ("oracle", GOOD, 1.0, 1),
    }
    assert system_roles(_study(1, named)) == {
        "idle-views3": "floor",
        "random": "floor",
        "oracles-fan": "system",
        "idle-but-oracle": "calibration",
    }


def test_only_real_systems_are_bolded_and_the_others_are_marked(small):
    doc, md = small
    assert doc["roles"]["oracle"] == "calibration"
    rows = _rows(_section(md, "Table 1: benchmark results"))
    # real systems first, then the floor, then calibration
    assert list(rows) == ["heuristic", "mine", "idle (floor)", "oracle (calibration)", "oracle-noise0.5 (calibration)"]
    for name in ("oracle-noise0.5 (calibration)", "oracle (calibration)", "idle (floor)"):
        assert not any("**" in c for c in rows[name]), name  # the oracles' SR 100 and idle's 5 s are not "best"
    overall, time_, calls = -5, -4, -3
    assert rows["heuristic"][overall] == "0.00"  # real systems tie: nothing bolded, though the oracles reach 100
    assert rows["mine"][time_] == "**3.33**" and rows["mine"][calls] == "**60**"  # lowest among real systems
    assert rows["heuristic"][time_] == "5.00" and rows["heuristic"][calls] == "80"
    # every system-row table marks the roles
    assert "| oracle (calibration) |" in _section(md, "Table A-3: benchmark quality with bootstrap intervals")
    assert "**idle (floor)**" in _section(md, "Quality per cell (PA, SR, SR^a, SCD)")


def test_report_opens_with_how_to_read_it(small):
    doc, md = small
    heads = re.findall(r"(?m)^## (.*)$", md)
    assert heads[0] == "How to read this"
    how = _section(md, "How to read this")
    lines = how.strip().splitlines()
    assert (
        lines[0].startswith("- **Headline: Overall SR**")
        and "heuristic 0.00% (95% CI [0.0, 0.0]; PA 50.00%)" in lines[0]
    )
    assert "mine 0.00%" in lines[0]
    assert "oracle" not in lines[0] and "idle" not in lines[0]  # the headline is about real systems only
    for metric in ("**PA**", "**SR**", "**SR^a**", "**SCD**"):
        assert sum(line.startswith(f"- {metric}") for line in lines) == 1, metric
    assert "at most 0.01" in how and "ONE rigid registration" in how and "SCD 0.02" in how
    assert "- **Calibration rows** (oracle, oracle-noise0.5): read the hidden targets" in how
    assert "- **Floor rows** (idle)" in how


def test_a_study_too_small_for_its_tests_says_so_next_to_them(small):
    doc, md = small
    u = doc["uncertainty"]
    assert u["n_objects"] == 3 and u["family_size"] == 20  # 10 pairs x SR and PA
    assert u["min_p_holm"] == 1.0  # 20 x 2^-2
    how = _section(md, "How to read this")
    assert (
        "- **Warning:** 3 tasks: the tests have no power: with 3 objects the smallest p_Holm any result could give "
        "is 1.000 (20 comparisons)" in how
    )
    pairs = _section(md, "Table A-4: paired system differences")
    assert "1.000" in pairs and "**Too few objects for these tests: with 3 objects" in pairs


def test_a_study_with_enough_objects_has_no_power_warning():
    doc = build_results(_study(8, {k: SYSTEMS[k] for k in ("heuristic", "mine")}), FAST)
    # 32 objects, 2 comparisons: the floor is the relabellings' 1 / 2001
    assert doc["uncertainty"]["min_p_holm"] == pytest.approx(2 / 2001)
    md = render_markdown(doc)
    assert "no power" not in md and "Too few objects" not in md


def test_smallest_pvalue_is_what_the_test_gives_for_the_most_extreme_data():
    for n in (1, 3, 5):
        contrib = np.ones((n, 1))  # every object favours A: nothing more extreme exists
        p = float(randomization_pvalues(contrib, n_permutations=40_000, seed=3)[0])
        assert p == pytest.approx(smallest_pvalue(n), rel=0.05)
    assert smallest_pvalue(40, n_permutations=999) == pytest.approx(1e-3)


def test_sra_far_above_sr_is_pointed_out():
    close = {"heuristic": ("heuristic", [0.5, 0.5, 0.5, 0.5], 1.0, 1)}
    study = _study(2, close)
    for r in study.runs.values():
        r.score.scd, r.score.sra = 0.015, 1.0  # whole shape within SCD 0.02, no part within 0.01
    md = render_markdown(build_results(study, FAST))
    assert "- **Warning:** heuristic: SR^a 100.00% but SR 0.00% and PA 0.00%" in _section(md, "How to read this")


def _caption(md: str) -> str:
    """Table 1's caption: its paragraph after the table (the published rows' line follows it)."""
    return next(p for p in _section(md, "Table 1: benchmark results").strip().split("\n\n") if p.startswith("SR (%)"))


def test_table1_caption_is_short_and_says_only_what_is_missing(small):
    doc, md = small
    caption = _caption(md)
    assert len(caption.split()) <= 45
    assert caption.endswith("Bold: best among real systems. Not recorded: tokens, cost.")
    full = _study(1, {"a": ("heuristic", GOOD, 1.0, 1)})
    for r in full.runs.values():
        r.info.tokens, r.info.cost_usd = TokenUsage(total=10), 0.5
    caption = _caption(render_markdown(build_results(full, FAST)))
    assert caption.endswith("Bold: best among real systems.")
    some = _study(1, {"a": ("heuristic", GOOD, 1.0, 1), "b": ("heuristic", GOOD, 1.0, 1)})
    for (s, t), r in some.runs.items():
        r.info.cost_usd = 0.5 if s == "a" or t.startswith("partnet") else None
    caption = _caption(render_markdown(build_results(some, FAST)))
    assert caption.endswith("Not recorded: tokens. Means over fewer runs: cost (b 2/5).")


def test_counts_are_plural_only_when_more_than_one():
    one = _study(
        1, {"a": ("heuristic", GOOD, 1.0, 1), "b": ("heuristic", BAD, 1.0, 1)}, blocks={("ikea_manual", "manual")}
    )
    md = render_markdown(build_results(one, FAST))
    assert "1 task: the tests have no power: with 1 object the smallest" in md


def test_unscored_and_unknown_runs_are_warned_about_up_front():
    study = _study(1, {"a": ("heuristic", GOOD, 1.0, 1)})
    for tid in ("partnet-o00-none", "ikea_manual-o00-manual"):
        rec = study.runs[("a", tid)]
        rec.score = run_from_errors("a", tid, [], status="missing")
    doc = build_results(study, FAST)
    doc["unknown_runs"] = [{"system": "a", "task_id": "elsewhere-1"}]
    how = _section(render_markdown(doc), "How to read this")
    assert "- **Warning:** 2 runs not scored (2 missing) count PA = SR = 0: see Runs." in how
    assert "- **Warning:** 1 run for tasks not in the suite was ignored: see Runs." in how
