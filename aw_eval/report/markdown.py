"""``report.md``: the paper's tables from a ``scores.json`` document.

Tables follow the layout of Table 1 (``tab:benchmark``) and Appendix tables A-3 to A-12 where the
study has the data; a section says so when it does not (for example, no paired reference
conditions, no run.json completion reports, no robustness variants).
"""

from __future__ import annotations

from typing import Any

from aw.cli.common import plural
from aw_eval.analyses.failures import CLASSES, HIGH_PA
from aw_eval.report.fmt import DASH, bold_best, ci, fixed, md_table, paper, pval, signed, threshold_label
from aw_eval.report.heaps import far_from_assembled_note
from aw_eval.report.published import MARK as PUBLISHED_MARK
from aw_eval.report.refinement import REFINEMENT_TITLE, refinement_headline, render_refinement
from aw_eval.report.results import protocol_of

__all__ = ["render_markdown", "system_label", "SUMMARY_SECTIONS"]

HOW_TO_READ = "How to read this"
TABLE1 = "Table 1: benchmark results"
OVERVIEW = "Table A-3: benchmark quality with bootstrap intervals"
PAIRS = "Table A-4: paired system differences"
# The sections a reader needs first; report.html shows them open and folds the rest.
SUMMARY_SECTIONS = (REFINEMENT_TITLE, HOW_TO_READ, TABLE1, OVERVIEW, PAIRS)

SOURCE_NAMES = {
    "partnet": "PartNet",
    "ikea_manual": "IKEA-Manual",
    "assemblybench": "AssemblyBench",
    "fantastic_breaks": "Fantastic Breaks",
}


ROLE_MARKS = {"calibration": " (calibration)", "floor": " (floor)"}


def _role(doc: dict[str, Any], system: str) -> str:
    return doc.get("roles", {}).get(system, "system")


def system_label(doc: dict[str, Any], system: str) -> str:
    """A system's name as the tables print it: calibration and floor systems marked."""
    return system + ROLE_MARKS.get(_role(doc, system), "")


def _order(doc: dict[str, Any]) -> list[str]:
    """Row order: real systems, then floors, then calibration, each by Overall SR then PA."""
    order = doc["uncertainty"].get("order") or list(doc["systems"])
    rank = {"system": 0, "floor": 1, "calibration": 2}
    return sorted(order, key=lambda s: rank.get(_role(doc, s), 0))


def _real(doc: dict[str, Any]) -> list[str]:
    return [s for s in _order(doc) if _role(doc, s) == "system"]


NO_ORIGINALS = "The suite has no original (non-variant) tasks: no benchmark aggregate."


def _no_power(doc: dict[str, Any]) -> str | None:
    """Why the paired tests cannot show anything on this study, or None when they can."""
    u = doc["uncertainty"]
    floor, alpha = u.get("min_p_holm"), 1 - u.get("level", 0.95)
    if floor is None or floor <= alpha:
        return None
    return (
        f"with {plural(u['n_objects'], 'object')} the smallest p_Holm any result could give is {pval(floor)} "
        f"({u['family_size']} comparisons), so no difference can reach p < {alpha:g}: p_Holm here says the study "
        "is too small, not that the systems are alike"
    )


def _how_to_read(doc: dict[str, Any]) -> str:
    """The report's first section: the headline, the four metrics in a line each, which rows are
    not results, and what makes this study's numbers weak."""
    p = protocol_of(doc)
    over, q = doc["uncertainty"].get("overview") or {}, doc["quality"]["systems"]
    real = [s for s in _real(doc) if s in over]
    # RUNS is a refinement study: its four-arm table is the headline, Table 1 a second protocol
    study_headline = refinement_headline(doc["refinement"]) if doc.get("refinement") else ""
    if real:
        head = "; ".join(
            f"{s} {paper(over[s]['sr']['value'])}% (95% CI {ci(over[s]['sr']['ci'])}; PA "
            f"{paper(over[s]['pa']['value'])}%)"
            for s in real
        )
        title = "Overall SR by the benchmark's protocol" if study_headline else "Headline: Overall SR"
        headline = f"- **{title}** (Table 1; sources weighted equally): {head}."
    elif over:
        headline = (
            "- **Headline: none.** Every system is calibration or floor: the study measures the scorer, not an agent."
        )
    else:
        headline = f"- **Headline: none.** {NO_ORIGINALS}"
    if study_headline:
        headline = study_headline + ("\n" + headline if real else "")
    lines = [
        headline,
        f"- **PA** (part accuracy, %): parts whose Chamfer distance to their matched target part is at most "
        f"{p.threshold:g}, after ONE rigid registration of the whole assembly onto the target (one misplaced part "
        "can pull every other part off).",
        "- **SR** (success rate, %): tasks with every part correct (PA 100%).",
        f"- **SR^a** (%): tasks whose whole assembly is within SCD {p.sra_threshold:g} of the target: a looser, "
        "shape-level success that can hold while PA is low (parts that look alike swapped, small offsets everywhere).",
        "- **SCD** (x1000, lower is better): Chamfer distance of the whole registered assembly to the target, "
        "averaged over scored runs only.",
    ]
    roles = doc.get("roles", {})
    cal = [s for s in doc["systems"] if roles.get(s) == "calibration"]
    flo = [s for s in doc["systems"] if roles.get(s) == "floor"]
    if cal:
        lines.append(
            f"- **Calibration rows** ({', '.join(cal)}): read the hidden targets, so they show what the scorer "
            "gives a near-perfect assembly; not results, never bolded."
        )
    if flo:
        lines.append(
            f"- **Floor rows** ({', '.join(flo)}): make no real attempt (idle never moves, random moves "
            "blindly); the level any agent should beat; never bolded."
        )
    lines.append(
        "- **Bold** marks the best value among real systems only (the lowest resource use only among those "
        "with PA > 0), and only where at least two differ."
    )
    warn = []
    n_orig = doc["suite"]["n_original"]
    why = _no_power(doc)
    if why:
        warn.append(f"{plural(n_orig, 'task')}: the tests have no power: {why}.")
    n_unscored = sum(len(v) for v in doc["unscored_runs"].values())
    if n_unscored:
        kinds = ", ".join(f"{len(v)} {k}" for k, v in sorted(doc["unscored_runs"].items()))
        warn.append(f"{plural(n_unscored, 'run')} not scored ({kinds}) count PA = SR = 0: see Runs.")
    running = doc.get("running_runs") or []
    if running:
        scored = [r for r in running if r["scored"]]
        warn.append(
            f"{plural(len(running), 'run')} {'was' if len(running) == 1 else 'were'} still being recorded when "
            "scored (a live lock): "
            + (
                "scored at their last state (--allow-running), not their end; marked running under Runs."
                if scored
                else "left out (status running, counted 0); score again when they end."
            )
        )
    if doc.get("unknown_runs"):
        n = len(doc["unknown_runs"])
        warn.append(f"{plural(n, 'run')} for tasks not in the suite {'was' if n == 1 else 'were'} ignored: see Runs.")
    for s in _order(doc):
        o = q.get(s, {}).get("overall")
        if o and _role(doc, s) != "calibration" and o["sra"] - o["sr"] >= 25:
            warn.append(
                f"{system_label(doc, s)}: SR^a {paper(o['sra'])}% but SR {paper(o['sr'])}% and PA {paper(o['pa'])}%: "
                "its assemblies are close in shape, not part by part."
            )
    far = [r for r in doc["runs"] if r.get("far_from_assembled")]
    if far:
        warn.append(
            f"{plural(len(far), 'run')} {'scores' if len(far) == 1 else 'score'} PA of {100 * HIGH_PA:g}% or "
            "more, or SR^a, on a state far from assembled (most parts displaced): see Runs for why."
        )
    if doc["settings"].get("protocol_overrides"):
        warn.append("Scored with protocol overrides: not comparable with the paper's numbers.")
    lines += [f"- **Warning:** {w}" for w in warn]
    return "\n".join(lines)


def _resource_note(doc: dict[str, Any], systems: list[str]) -> str:
    """Which resource means rest on fewer runs than tasks (empty when none)."""
    res, q = doc["resources"], doc["quality"]["systems"]
    names = {"time_min": "time", "mcp_calls": "calls", "tokens_m": "tokens", "cost_usd": "cost"}
    none, fewer = [], []
    for k, label in names.items():
        if all(res[s][k]["n"] == 0 for s in systems):
            none.append(label)
            continue
        short = [f"{s} {res[s][k]['n']}/{q[s]['n_tasks']}" for s in systems if res[s][k]["n"] < q[s]["n_tasks"]]
        if short:
            fewer.append(f"{label} ({', '.join(short)})")
    out = ([f"Not recorded: {', '.join(none)}."] if none else []) + (
        [f"Means over fewer runs: {'; '.join(fewer)}."] if fewer else []
    )
    composed = [s for s in systems if any(res[s][k].get("composed") for k in names)]
    if composed:
        out.append(
            f"{', '.join(composed)} started from another system's final states: their resources add up both stages."
        )
    short = [s for s in systems if any(res[s][k].get("stages_left_out") for k in names)]
    if short:
        out.append(
            f"{', '.join(short)}: resources leave out the stage that made their start states (a run outside this "
            "study, or a poses file); never bolded."
        )
    refused = [(s, res[s]["mcp_calls"].get("refused_by_harness", {})) for s in systems]
    said = [f"{s} {r['total']} in {plural(r['n'], 'run')}" for s, r in refused if r.get("n")]
    if said:
        out.append(
            "MCP calls include the calls the harness refused before they reached aw-serve (Inspect checks "
            f"arguments against the tools' schemas itself; Claude Code and Codex pass them on): {'; '.join(said)}."
        )
    return " ".join(out)


def _table1(doc: dict[str, Any]) -> str:
    q, res = doc["quality"], doc["resources"]
    if not q["systems"]:
        return NO_ORIGINALS
    systems = _order(doc)
    cells = q["cells"]
    header = (
        ["System"]
        + [c["label"] for c in cells]
        + ["Overall SR (%)", "Time (min)", "MCP calls", "Tokens (M)", "Cost ($)"]
    )
    cols: list[list[Any]] = []
    for ci_ in range(len(cells)):
        cols.append([q["systems"][s]["cells"][ci_]["sr"] for s in systems])
    cols.append([q["systems"][s]["overall"]["sr"] for s in systems])
    res_keys = ("time_min", "mcp_calls", "tokens_m", "cost_usd")
    for k in res_keys:
        cols.append([res[s][k]["mean"] for s in systems])
    # Only real systems compete; lowest resource use is only "best" for a system that achieved
    # something (an idle system's few calls are not an achievement).
    real = [_role(doc, s) == "system" for s in systems]
    achieved = [r and float(q["systems"][s]["overall"]["pa"] or 0) > 0 for r, s in zip(real, systems, strict=True)]
    text_cols = []
    for j, col in enumerate(cols):
        if j <= len(cells):
            txt = [paper(v) for v in col]
            text_cols.append(bold_best(txt, col, higher=True, eligible=real))
        else:
            k = res_keys[j - len(cells) - 1]
            digits = {"time_min": 2, "mcp_calls": 0, "tokens_m": 2, "cost_usd": 2}[k]
            txt = [fixed(v, digits) for v in col]
            # a cost that leaves out a stage is not a system's whole cost: never the best
            whole = [a and not res[s][k].get("stages_left_out") for a, s in zip(achieved, systems, strict=True)]
            text_cols.append(bold_best(txt, col, higher=False, eligible=whole))
    rows = [[system_label(doc, s)] + [tc[i] for tc in text_cols] for i, s in enumerate(systems)]
    rows += _published_table1(doc)
    note = (
        "SR (%) per source and condition (NR: no reference, IR: image, M: manual); Overall by eq. 3 (sources "
        "weighted equally). Resources: mean per run. Bold: best among real systems."
    )
    extra = _resource_note(doc, systems)
    return md_table(header, rows) + "\n\n" + note + (f" {extra}" if extra else "") + "\n\n" + _published_note(doc)


def _published(doc: dict[str, Any]) -> list[dict[str, Any]]:
    pub = doc.get("published") or {}
    return pub.get("systems", []) if pub.get("shown") else []


def _published_label(row: dict[str, Any]) -> str:
    return f"{row['system']} ({row['harness']}; {PUBLISHED_MARK})"


def _published_table1(doc: dict[str, Any]) -> list[list[str]]:
    """The paper's Table 1 rows in this table's columns (a cell the paper does not have: a dash)."""
    pub = doc.get("published") or {}
    where = {tuple(c): i for i, c in enumerate(pub.get("cells", []))}
    rows = []
    for r in _published(doc):
        cells = [
            r["sr_cells"][where[k]] if (k := (c["source"], c["condition"])) in where else None
            for c in doc["quality"]["cells"]
        ]
        rows.append(
            [_published_label(r)]
            + [paper(v) for v in cells]
            + [
                paper(r["sr"]),
                fixed(r["time_min"], 2),
                fixed(r["mcp_calls"], 0),
                fixed(r["tokens_m"], 2),
                fixed(r["cost_usd"], 2),
            ]
        )
    return rows


def _published_note(doc: dict[str, Any]) -> str:
    """One line: where the published rows come from, or why they are absent."""
    pub = doc.get("published")
    if not pub:
        return "The paper's eight systems are not shown: this scores.json predates them."
    if pub["shown"]:
        return (
            f"Rows marked '{PUBLISHED_MARK}': the paper's eight systems on the same 100 tasks, as published "
            f"({pub['source']}); no per-task data is published, so they are in no paired test and never bold."
        )
    return (
        "The paper's eight systems are not shown: they are published for the official benchmark's 100 tasks only, "
        f"and this suite is not it: {pub['why']}."
    )


def _quality_full(doc: dict[str, Any]) -> str:
    q = doc["quality"]
    if not q["systems"]:
        return NO_ORIGINALS
    out = []
    for s in _order(doc):
        row = q["systems"][s]
        rows = []
        for c, v in zip(q["cells"], row["cells"], strict=True):
            rows.append(
                [
                    c["label"],
                    str(c["n_tasks"]),
                    str(v["n_scored"]),
                    fixed(v["pa"], 2),
                    fixed(v["sr"], 2),
                    fixed(v["sra"], 2),
                    fixed(v["scd"], 2),
                ]
            )
        o = row["overall"]
        rows.append(
            [
                "**Overall**",
                str(row["n_tasks"]),
                str(row["n_scored"]),
                fixed(o["pa"], 2),
                fixed(o["sr"], 2),
                fixed(o["sra"], 2),
                fixed(o["scd"], 2),
            ]
        )
        out.append(
            f"**{system_label(doc, s)}**\n\n"
            + md_table(["Cell", "Tasks", "Scored", "PA (%)", "SR (%)", "SR^a (%)", "SCD (x1000)"], rows)
        )
    return "\n\n".join(out) + (
        "\n\nPA, SR and SR^a average all attempted tasks (an unscored attempt counts 0); SCD "
        "averages scored attempts only. Overall SCD applies eq. 3 to the cell means."
    )


def _overview(doc: dict[str, Any]) -> str:
    u, oc = doc["uncertainty"], doc["outcomes"]
    if not u["overview"]:
        return NO_ORIGINALS
    rows = []
    for s in _order(doc):
        o = u["overview"].get(s)
        if o is None:
            continue
        rows.append(
            [
                system_label(doc, s),
                paper(o["sr"]["value"]),
                ci(o["sr"]["ci"]),
                paper(o["pa"]["value"]),
                ci(o["pa"]["ci"]),
                str(oc[s]["errors_timeouts"]),
            ]
        )
    rows += [
        [_published_label(r), paper(r["sr"]), ci(r["sr_ci"]), paper(r["pa"]), ci(r["pa_ci"]), str(r["errors_timeouts"])]
        for r in _published(doc)
    ]
    return (
        md_table(["System", "SR (%)", "95% CI", "PA (%)", "95% CI", "Errors/timeouts"], rows)
        + f"\n\nSource-weighted quality with pointwise percentile bootstrap intervals ({u['n_draws']:,} draws, seed "
        f"{u['seed']}; objects resampled within sources, PartNet conditions paired). Errors/timeouts count runs "
        "that did not finish normally, including missing and unreadable runs."
    )


def _pairs(doc: dict[str, Any]) -> str:
    u = doc["uncertainty"]
    if not u["overview"]:
        return NO_ORIGINALS
    if not u["pairs"]:
        return "Only one system: no pairwise comparisons."
    rows = [
        [
            system_label(doc, p["a"]),
            system_label(doc, p["b"]),
            f"{signed(p['sr']['diff'])} {ci(p['sr']['ci'])}",
            pval(p["sr"]["p_holm"]),
            f"{signed(p['pa']['diff'])} {ci(p['pa']['ci'])}",
            pval(p["pa"]["p_holm"]),
        ]
        for p in u["pairs"]
    ]
    return (
        md_table(["A", "B", "ΔSR (pp) [95% CI]", "p_Holm", "ΔPA (pp) [95% CI]", "p_Holm"], rows, "llrrrr")
        + f"\n\nA minus B in percentage points. Two-sided randomization tests ({u['n_permutations']:,} relabellings, "
        f"add-one correction, labels exchanged within objects), Holm correction over all {u.get('family_size', 0)} "
        "system-pair/metric comparisons; intervals are pointwise."
        + (f" **Too few objects for these tests: {why}.**" if (why := _no_power(doc)) else "")
    )


def _reference(doc: dict[str, Any]) -> str:
    ref = doc["uncertainty"]["reference"]
    if not ref:
        return "No source has paired no-reference and image conditions: no reference effects."
    rows = []
    for r in ref:
        rows.append(
            [
                system_label(doc, r["system"]),
                SOURCE_NAMES.get(r["source"], r["source"]),
                str(r["n_objects"]),
                signed(r["pa"]["diff"]),
                ci(r["pa"]["ci"]),
                f"{r['pa']['up']}/{r['pa']['down']}",
                signed(r["sr"]["diff"]),
                ci(r["sr"]["ci"]),
                f"{r['sr']['up']}/{r['sr']['down']}",
            ]
        )
    return (
        md_table(
            ["System", "Source", "Objects", "ΔPA (pp)", "95% CI", "PA up/down", "ΔSR (pp)", "95% CI", "SR up/down"],
            rows,
            "llrrrrrrr",
        )
        + "\n\nImage-conditioned minus no-reference results on the same objects. Up/down counts exclude ties; SR counts "
        "are discordant successes. Intervals are pointwise percentile bootstrap intervals over objects."
    )


def _part_scale(doc: dict[str, Any]) -> str:
    ps = doc["part_scale"]
    if not ps:
        return "No task geometry was loaded: no part-size ratios."
    rows = [
        [
            SOURCE_NAMES.get(s, s),
            str(v["n"]),
            fixed(v["median"], 2),
            f"{fixed(v['q1'], 2)}–{fixed(v['q3'], 2)}",
            fixed(v["p90"], 2),
            fixed(v["above_10"], 1),
        ]
        for s, v in ps.items()
    ]
    return (
        md_table(["Dataset", "N", "Median", "Interquartile range", "90th percentile", "Ratio > 10 (%)"], rows)
        + "\n\nLargest over smallest part PCA bounding-box diagonal (unique vertices), one value per object."
    )


def _part_count(doc: dict[str, Any]) -> str:
    pc = doc["part_count"]
    bands = [b for b in pc["bands"]]
    out = []
    for s in _order(doc):
        rows_src = pc["systems"].get(s, [])
        used = [b for b in bands if any(b in r["bands"] for r in rows_src)]
        rows = []
        for r in rows_src:
            cells = []
            for b in used:
                v = r["bands"].get(b)
                cells.append(DASH if v is None else f"{v['n']}: {fixed(v['pa'], 2)}/{fixed(v['sr'], 2)}")
            rows.append([r["label"]] + cells)
        out.append(
            f"**{system_label(doc, s)}**\n\n"
            + md_table(["Condition"] + [f"{b} parts (n: PA/SR %)" for b in used], rows)
        )
    return "\n\n".join(out) + "\n\nEach cell: number of tasks and mean PA/SR in percent."


def _scd_tail(doc: dict[str, Any]) -> str:
    out = []
    for s in _order(doc):
        rows = [
            [
                r["label"],
                str(r["n"]),
                fixed(r["mean"], 2),
                fixed(r["median"], 2),
                str(r["k"]),
                fixed(r["contribution"], 2),
                fixed(r["remaining_mean"], 2),
                str(r["tail_never_moved"]),
            ]
            for r in doc["scd_tail"]["systems"].get(s, [])
        ]
        if rows:
            out.append(
                f"**{system_label(doc, s)}**\n\n"
                + md_table(
                    [
                        "Setting",
                        "N",
                        "Mean SCD (x1000)",
                        "Median SCD (x1000)",
                        "k",
                        "Contribution (%)",
                        "Remaining mean SCD (x1000)",
                        "Tail never moved",
                    ],
                    rows,
                )
            )
    if not out:
        return "No scored attempts."
    return "\n\n".join(out) + (
        "\n\nSCD x1000 over scored attempts; the largest k = ceil(0.05 N) values form the tail. "
        "'Tail never moved' counts tail runs in which no part ever moved."
    )


def _categories(doc: dict[str, Any]) -> str:
    out = []
    for s in _order(doc):
        rows = [
            [r["label"], r["category"], str(r["n"]), fixed(r["scd"], 2), fixed(r["pa"], 2), fixed(r["sr"], 2)]
            for r in doc["categories"]["systems"].get(s, [])
        ]
        out.append(
            f"**{system_label(doc, s)}**\n\n"
            + md_table(["Cell", "Category", "N", "SCD (x1000)", "PA (%)", "SR (%)"], rows, "llrrrr")
        )
    return "\n\n".join(out)


def _thresholds(doc: dict[str, Any]) -> str:
    th = doc["thresholds"]
    ts = th["thresholds"]
    show = [
        i for i, t in enumerate(ts) if any(abs(t - x) < 1e-12 for x in (1e-4, 1e-3, 0.00316228, 0.01, 0.0316228, 0.1))
    ]
    header = (
        ["System"]
        + [f"PA@{threshold_label(ts[i])} (%)" for i in show]
        + [f"SR@{threshold_label(ts[i])} (%)" for i in show]
    )
    rows = []
    for s in _order(doc):
        v = th["systems"].get(s)
        if v is None:
            continue
        rows.append([system_label(doc, s)] + [paper(v["pa"][i]) for i in show] + [paper(v["sr"][i]) for i in show])
    return md_table(header, rows) + (
        "\n\nPA/SR (%, eq. 3) at correctness thresholds, with the saved registration and "
        "Hungarian correspondence fixed; the full sweep is in scores.json and thresholds.png."
    )


def _stages(doc: dict[str, Any]) -> str:
    rows = []
    for s in _order(doc):
        st = doc["dynamics"]["systems"].get(s, {}).get("stages")
        if not st:
            continue
        rows.append(
            [
                system_label(doc, s),
                fixed(st["translation_early"], 3),
                fixed(st["translation_late"], 3),
                fixed(st["rotation_early"], 1),
                fixed(st["rotation_late"], 1),
                fixed(st["revisit"], 1),
            ]
        )
    return (
        md_table(
            ["System", "Trans. early (diag.)", "Late (diag.)", "Rot. early (deg)", "Late (deg)", "Revisit (%)"], rows
        )
        + "\n\nSource-weighted medians of per-evaluation medians in the first and last third of the interaction "
        "interval. Translation is normalized by the largest-part diagonal; rotation is in degrees; operations "
        "below 0.5 degrees count as translations. Revisit: weighted median fraction of edits touching a part "
        "edited before."
    )


def _activity(doc: dict[str, Any]) -> str:
    dy = doc["dynamics"]
    out = []
    for s in _order(doc):
        v = dy["systems"].get(s)
        if v is None:
            continue
        rows = []
        for b in range(dy["n_bins"]):
            sh = v["shares"][b]
            mg = v["magnitudes"]
            rows.append(
                [f"{b * 10}–{(b + 1) * 10}%", str(v["active"][b])]
                + [DASH if x is None else fixed(100 * x, 1) for x in sh]
                + [fixed(mg["translation"][b], 3), fixed(mg["rotation_deg"][b], 1)]
            )
        out.append(
            f"**{system_label(doc, s)}**\n\n"
            + md_table(
                [
                    "Bin",
                    "Active",
                    "Inspect (%)",
                    "Observe (%)",
                    "Manipulate (%)",
                    "Other (%)",
                    "Translation",
                    "Rotation (deg)",
                ],
                rows,
            )
        )
    return "\n\n".join(out) + (
        "\n\nMean call shares within active evaluation-bins (ten equal-width bins from the first to "
        "the last call), averaged with benchmark weights; magnitudes are weighted medians of "
        "per-evaluation medians."
    )


def _curves(doc: dict[str, Any]) -> str:
    cv = doc["curves"]
    pts = cv["points"]
    rows = []
    for s in _order(doc):
        v = cv["systems"].get(s)
        if v is None:
            continue
        rows.append(
            [system_label(doc, s)]
            + [f"{paper(a)}/{paper(b)}" for a, b in zip(v["pa"]["normalized"], v["sr"]["normalized"], strict=True)]
        )
    t1 = md_table(["System"] + [f"PA/SR (%) at {p:g}" for p in pts], rows)
    rows = []
    for s in _order(doc):
        v = cv["systems"].get(s)
        if v is None:
            continue
        rows.append(
            [system_label(doc, s)]
            + [f"{paper(a)}/{paper(b)}" for a, b in zip(v["pa"]["budget"], v["sr"]["budget"], strict=True)]
            + [f"{paper(v['pa']['final'])}/{paper(v['sr']['final'])}", str(v["edits_after_last_budget"])]
        )
    t2 = md_table(
        ["System"]
        + [f"PA/SR (%) at {m:g} min" for m in cv["budget_minutes"]]
        + ["Final PA/SR (%)", "Edits after last budget"],
        rows,
    )
    dec = doc["pa_decreases"]
    t3 = md_table(
        [
            "System",
            "PA decreases",
            "with an assignment change",
            "persist, alignment fixed",
            "persist, alignment and matching fixed",
        ],
        [
            [
                s,
                str(dec[s]["decreases"]),
                str(dec[s]["with_assignment_change"]),
                str(dec[s]["persist_alignment_fixed"]),
                str(dec[s]["persist_both_fixed"]),
            ]
            for s in _order(doc)
            if s in dec
        ],
    )
    return (
        "PA/SR (%) at normalized interaction time (first to last call; 1 = final state):\n\n"
        + t1
        + "\n\nPA/SR (%) at absolute time budgets (state after the last completed operation; no interpolation; "
        "an episode that ended earlier keeps its final state). These are retrospective truncations, not new "
        "budget-conditioned runs:\n\n"
        + t2
        + "\n\nPA decreases between consecutive checkpoints: how many change at least one matched assignment, and "
        "how many persist when the later state is rescored with the earlier checkpoint's registration "
        "(re-matched), and with its registration and matching:\n\n" + t3
    )


def _completion(doc: dict[str, Any]) -> str:
    c = doc["completion"]
    rows = [
        [
            system_label(doc, s),
            str(v["declared"]),
            str(v["declared_successful"]),
            str(v["not_declared"]),
            str(v["no_report"]),
            fixed(v["median_incorrect_fraction_of_failed_claims"]),
        ]
        for s, v in c.items()
    ]
    if all(v["declared"] + v["not_declared"] == 0 for v in c.values()):
        return "No run.json records declared completion: nothing to compare."
    return md_table(
        [
            "System",
            "Declared complete",
            "of which successful",
            "Not declared",
            "No report",
            "Median incorrect parts of failed claims (%)",
        ],
        rows,
    )


def _failures(doc: dict[str, Any]) -> str:
    f = doc["failures"]
    rows = []
    for s in _order(doc):
        v = f["systems"].get(s)
        if v is None:
            continue
        rng = v["grid_range"]
        rows.append(
            [
                system_label(doc, s),
                str(v["failed_tasks"]),
                str(v["wrong_parts"]),
                fixed(v["translation_part_pooled"]),
                fixed(v["translation_task_pooled"]),
                DASH if rng is None else f"{fixed(rng[0])}–{fixed(rng[1])}",
            ]
        )
    t1 = md_table(
        ["System", "Failed tasks", "Wrong parts", "Part pooled (%)", "Task pooled (%)", "Sensitivity range (%)"], rows
    )
    rows = []
    for s in _order(doc):
        v = f["systems"].get(s)
        if v is None:
            continue
        rows.append([system_label(doc, s)] + [str(v["class_counts"][c]) for c in CLASSES])
    t2 = md_table(["System"] + [c.replace("_", " ") for c in CLASSES], rows)
    return (
        t1 + "\n\nTranslation-dominated fractions of incorrect parts (part pooling weights incorrect parts equally; "
        "task pooling averages within failed tasks first). The sensitivity range spans offset cutoffs "
        f"{', '.join(map(str, f['offset_grid']))} x centred-CD cutoffs {', '.join(map(str, f['centred_grid']))}.\n\n"
        "Parts per class (ordered classifier; correct parts included):\n\n" + t2
    )


def _robustness(doc: dict[str, Any]) -> str:
    rb = doc["robustness"]
    if not rb["systems"]:
        return "The suite has no robustness variants."
    out = []

    def one(x):
        return f"{fixed(x['pa'], 2)}/{int(x['sr'])}" if x["status"] == "scored" else f"({x['status']})"

    def cell(v):
        return " ".join(one(x) for x in v) if v else DASH

    for s in _order(doc):
        v = rb["systems"].get(s)
        if v is None:
            continue
        rows = [
            [
                r["label"],
                r["object_id"],
                one(r["original"]),
                cell(r["layout"]),
                cell(r["distractor"]),
                cell(r["missing"]),
            ]
            for r in v["rows"]
        ]
        out.append(
            f"**{system_label(doc, s)}**\n\n"
            + md_table(["Source", "Object", "Original", "Layouts", "Distractor", "Missing"], rows, "llrrrr")
        )
    return "\n\n".join(out) + (
        "\n\nEach cell: PA (%) / SR (0 or 1); the missing-part column reports retained-part PA / "
        "retained-part completeness. A dash marks an untested condition; a status in parentheses a run "
        "that was not scored (counted 0 in the aggregates)."
    )


def _runs(doc: dict[str, Any]) -> str:
    lines = []
    for status, items in sorted(doc["unscored_runs"].items()):
        lines.append(f"- **{status}** ({len(items)}), scored PA = SR = 0:")
        for it in items[:200]:
            lines.append(f"  - {it['system']} / {it['task_id']}: {'; '.join(it['problems']) or status}")
        if len(items) > 200:
            lines.append(f"  - ... and {len(items) - 200} more (see scores.json)")
    if doc["unknown_runs"]:
        lines.append(f"- **runs for tasks not in the suite** ({len(doc['unknown_runs'])}), ignored:")
        lines += [f"  - {u['system']} / {u['task_id']}" for u in doc["unknown_runs"]]
    far = [r for r in doc["runs"] if r.get("far_from_assembled")]
    if far:
        lines.append(f"- **high scores on states far from assembled** ({len(far)}):")
        for r in far:
            label = f"{r['system']} / {r['task_id']}"
            lines.append(f"  - {far_from_assembled_note(label, r['far_from_assembled'])}")
    notes = [
        r
        for r in doc["runs"]
        if r["status"] == "scored" and (r["problems"] or r["final_from"] != "final.json" or r.get("running"))
    ]
    if notes:
        lines.append(f"- **scored with notes** ({len(notes)}):")
        for r in notes:
            msg = "; ".join(r["problems"]) if r["problems"] else ""
            lines.append(
                f"  - {r['system']} / {r['task_id']}: "
                + ("**running**, " if r.get("running") else "")
                + f"final state from {r['final_from']}"
                + (f"; {msg}" if msg else "")
            )
    return "\n".join(lines) if lines else "Every run was found and scored from its final.json."


def render_markdown(doc: dict[str, Any], plots: dict[str, str] | None = None) -> str:
    st = doc["settings"]
    plots = plots or {}
    parts = [
        f"# AssemblyWorld scores: {doc['suite']['name']}",
        f"Suite `{doc['suite']['dir']}` ({doc['suite']['n_original']} original tasks, {doc['suite']['n_tasks']} in all); "
        f"runs `{doc['runs_dir']}`; systems: {', '.join(doc['systems'])}. Final states scored in `{st.get('final_mode')}` "
        f"mode, checkpoints in `{st.get('checkpoint_mode')}` mode"
        + (" (final states only)" if st.get("final_only") else "")
        + f"; seed {st['seed']}. Generated {doc['generated_at']} (schema {doc['format']} v{doc['format_version']})."
        + (
            f" **Protocol overrides (not the paper's protocol): {st['protocol_overrides']}.**"
            if st.get("protocol_overrides")
            else ""
        ),
        *(
            [
                f"**PARTIAL STUDY: {plural(sum(len(doc['unscored_runs'].get(k, [])) for k in ('error', 'task_error')), 'run')} "
                "could not be scored (listed under Runs); the tables count them 0.**"
            ]
            if doc.get("partial")
            else []
        ),
        *(
            [render_refinement(doc["refinement"], plots.get("refinement_paired_cd")).rstrip("\n")]
            if doc.get("refinement")
            else []
        ),
        f"## {HOW_TO_READ}",
        _how_to_read(doc),
        "## Runs",
        _runs(doc),
        f"## {TABLE1}",
        _table1(doc),
        "## Quality per cell (PA, SR, SR^a, SCD)",
        _quality_full(doc),
        f"## {OVERVIEW}",
        _overview(doc),
        f"## {PAIRS}",
        _pairs(doc),
        "## Table A-5: paired reference effects",
        _reference(doc),
    ]
    if "reference" in plots:
        parts.append(f"![reference effects]({plots['reference']})")
    parts += [
        "## Table A-6: within-object part-size ratios",
        _part_scale(doc),
        "## Table A-7: part-count bands",
        _part_count(doc),
        "## Table A-8: SCD concentration",
        _scd_tail(doc),
        "## Table A-9: results per category",
        _categories(doc),
        "## Correctness-threshold sensitivity",
        _thresholds(doc),
    ]
    if "thresholds" in plots:
        parts.append(f"![threshold sensitivity]({plots['thresholds']})")
    parts += [
        "## Table A-10: early-to-late interaction changes",
        _stages(doc),
        "## Interaction dynamics per bin",
        _activity(doc),
    ]
    for k in ("activity", "magnitudes"):
        if k in plots:
            parts.append(f"![{k}]({plots[k]})")
    parts += ["## Quality over time", _curves(doc)]
    for k in ("quality_normalized", "quality_budget"):
        if k in plots:
            parts.append(f"![{k.replace('_', ' ')}]({plots[k]})")
    parts += [
        "## Completion reports",
        _completion(doc),
        "## Table A-11: geometric failure classes",
        _failures(doc),
        "## Table A-12: robustness variants",
        _robustness(doc),
    ]
    return "\n\n".join(parts) + "\n"
