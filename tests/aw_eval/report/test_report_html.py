"""report.html end to end: a tiny study scored by ``aw-score``, its page opened in Debian's
Chromium (playwright, ``/usr/bin/chromium``: the ``browser`` fixture of tests/conftest.py) from the file system
with the network cut: no console error, sortable tables, the 3D view's slider and system switcher,
cards with real pictures, tool-call lists; renders reused on a second call; ``--no-html``."""

from __future__ import annotations

import io
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from aw_eval.cli import main
from aw_eval.study.fixtures import box_suite, write_scripted_run

OPTS = [
    "--protocol-setting",
    "n_surface=256",
    "--protocol-setting",
    "n_fps=64",
    "--bootstrap",
    "200",
    "--permutations",
    "500",
    "--no-progress",
    "--no-plots",
    "--jobs",
    "1",
]
TASK = "partnet-box000-none"


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    root = tmp_path_factory.mktemp("html")
    suite = box_suite(root / "suite", objects_per_source=1, n_parts=[3, 2, 3, 2])
    runs = root / "runs"
    write_scripted_run(runs / "alpha" / TASK, suite, TASK, system="alpha", inspect_moves=False)
    write_scripted_run(
        runs / "beta" / TASK, suite, TASK, system="beta", correct=["p01"], wrong_offset=0.5, inspect_moves=False
    )
    write_scripted_run(
        runs / "alpha" / "fantastic_breaks-box000-none",
        suite,
        "fantastic_breaks-box000-none",
        system="alpha",
        inspect_moves=False,
    )
    # names with digits (the demo's oracles) and a calibration role; gamma leaves one part 0.3 off
    # and the global registration then counts none of its parts
    for name, kw in (
        ("oracle-noise0.5", {}),
        ("oracle-noise1.5", {"correct": ["p01", "p02"], "wrong_offset": 0.05}),
        ("gamma", {"correct": ["p01", "p02"], "wrong_offset": 0.3}),
    ):
        agent = "heuristic" if name == "gamma" else "oracle"
        write_scripted_run(
            runs / name / TASK, suite, TASK, system=name, inspect_moves=False, run_info={"agent": agent}, **kw
        )
    out = root / "out"
    assert main([str(suite), str(runs), "--out", str(out), *OPTS]) == 0
    return {"root": root, "suite": suite, "runs": runs, "out": out}


def test_page_and_its_folder(report):
    out = report["out"]
    page = (out / "report.html").read_text()
    files = out / "report_files"
    for name in ("report.css", "report.js", "viewer.js"):
        assert (files / name).is_file() and f"report_files/{name}" in page
    (bundle,) = files.glob("plotly-*.min.js")
    assert bundle.stat().st_size > 1_000_000 and bundle.name in page
    assert "Table 1: benchmark results" in page and "Table A-11" in page  # everything report.md has
    assert page.count('<section class="card"') == 5  # every task, run or not
    renders = list((files / "renders").iterdir())
    assert renders and all(f"report_files/renders/{p.name}" in page for p in renders)
    assert len(list((files / "viewer").iterdir())) == 2  # the two tasks with runs


def test_second_call_reuses_every_picture_and_no_html_writes_none(report, capsys):
    out = report["out"]
    before = {p.name: p.stat().st_mtime_ns for p in (out / "report_files" / "renders").iterdir()}
    capsys.readouterr()
    assert main([str(report["suite"]), str(report["runs"]), "--out", str(out), *OPTS]) == 0
    err = capsys.readouterr().err
    assert f"{len(before)} pictures (0 rendered now)" in err
    assert {p.name: p.stat().st_mtime_ns for p in (out / "report_files" / "renders").iterdir()} == before
    other = report["root"] / "out-no-html"
    shutil.copytree(out / "cache", other / "cache")
    assert main([str(report["suite"]), str(report["runs"]), "--out", str(other), *OPTS, "--no-html"]) == 0
    assert (other / "report.md").is_file()
    assert not (other / "report.html").exists() and not (other / "report_files").exists()


def test_cards_built_by_worker_processes_are_the_same(report):
    def cards(out: Path) -> str:
        return (out / "report.html").read_text().split('<h2 id="tasks">')[1]

    # a fresh folder: two spawned workers render every picture, the two PartNet tasks' targets alike
    other = report["root"] / "out-workers"
    shutil.copytree(report["out"] / "cache", other / "cache")
    assert main([str(report["suite"]), str(report["runs"]), "--out", str(other), *OPTS, "--jobs", "2"]) == 0
    assert cards(other) == cards(report["out"])
    assert sorted(p.name for p in (other / "report_files" / "renders").iterdir()) == sorted(
        p.name for p in (report["out"] / "report_files" / "renders").iterdir()
    )


def _cells(page, table: str, col: int) -> list[str]:
    return page.eval_on_selector(table, f"t => Array.from(t.tBodies[0].rows).map(r => r.cells[{col}].textContent)")


def _state_x(page) -> list[float]:
    """x of the first vertex of every state trace of the open 3D view."""
    return page.evaluate("""() => { const p = document.querySelector('.viewer .viewer-plot');
        return p.data.filter(t => !t.name.startsWith('target')).map(t => t.x[0]); }""")


def test_page_in_chromium(report, browser):
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    problems, remote = [], []
    page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: problems.append(str(e)))
    page.route("http*://**", lambda route: (remote.append(route.request.url), route.abort()))
    page.goto((report["out"] / "report.html").as_uri())
    page.wait_for_load_state("load")

    # tables sort by text and by number, both directions
    tasks = "table.tasks"
    names = _cells(page, tasks, 0)
    page.click(f"{tasks} th >> nth=0")
    assert _cells(page, tasks, 0) == sorted(names)
    page.click(f"{tasks} th >> nth=0")
    assert _cells(page, tasks, 0) == sorted(names, reverse=True)
    page.click(f"{tasks} th >> nth=4")  # parts
    parts = [int(x) for x in _cells(page, tasks, 4)]
    assert parts == sorted(parts) and len(set(parts)) > 1

    # a card's pictures load and are not blank
    card = page.locator(f"section#task-{TASK}")
    card.scroll_into_view_if_needed()
    page.wait_for_function(f"""() => Array.from(document.querySelectorAll('#task-{TASK} .finals img'))
        .every(i => i.complete && i.naturalWidth > 0)""")
    shot = np.asarray(Image.open(io.BytesIO(card.locator(".finals").screenshot())).convert("RGB"))
    assert len(np.unique(shot.reshape(-1, 3), axis=0)) > 200 and shot.std() > 10

    # the tool calls of a run, listed when opened
    calls = card.locator("details.calls").first
    n_calls = int(re.search(r"\((\d+)\)", calls.locator("summary").text_content()).group(1))
    calls.locator("summary").click()
    page.wait_for_selector(f"#task-{TASK} details.calls[data-ready='1']")
    assert n_calls > 0 and calls.locator("li").count() == n_calls

    # the 3D view: the slider steps through recorded states, the switcher changes system
    card.locator("button.open3d").click()
    page.wait_for_selector(f"#task-{TASK} .viewer[data-ready='1']", timeout=120_000)
    viewer = card.locator(".viewer")
    final_x = _state_x(page)
    final_shot = viewer.screenshot()
    page.eval_on_selector(
        f"#task-{TASK} .viewer-slider", "s => { s.value = '0'; s.dispatchEvent(new Event('input')); }"
    )
    page.wait_for_selector(f"#task-{TASK} .viewer[data-state='0']")
    first_x = _state_x(page)
    assert first_x != final_x
    assert viewer.screenshot() != final_shot
    assert "1/" in card.locator(".viewer-label").text_content()
    page.select_option(f"#task-{TASK} .viewer-system", "beta")
    page.wait_for_function(f"""() => {{ const v = document.querySelector('#task-{TASK} .viewer');
        return v.dataset.state === String(document.querySelector('#task-{TASK} .viewer-slider').max); }}""")
    assert _state_x(page) != final_x  # beta's final state is not alpha's

    assert problems == [] and remote == []
    page.close()


_TABLES = """() => Array.from(document.querySelectorAll('table.sortable')).map((t, ti) => {
    Array.from(t.tBodies[0].rows).forEach((r, i) => { r.dataset.testI = i; });
    return Array.from(t.tBodies[0].rows).map(r => Array.from(r.cells).map(c =>
        [c.hasAttribute('data-v'), c.getAttribute('data-v'), c.textContent.trim()]));
})"""
_CLICK = """([ti, col]) => { const t = document.querySelectorAll('table.sortable')[ti];
    t.tHead.rows[0].cells[col].click();
    return Array.from(t.tBodies[0].rows).map(r => Number(r.dataset.testI)); }"""


def _expected_orders(rows: list[list], col: int, text_rank: dict[str, int]) -> tuple[list[int], list[int]]:
    """Ascending and descending row orders of column ``col``: numbers (data-v) before text (natural
    order), values without a number or text last in both directions, ties in the original order."""
    keys = []
    for i, row in enumerate(rows):
        has_v, v, text = row[col] if col < len(row) else (False, None, "")
        if has_v:
            try:
                keys.append((0, float(v), i))
            except ValueError:
                keys.append((2, 0, i))
        elif text in ("", "–"):
            keys.append((2, 0, i))
        else:
            keys.append((1, text_rank[text], i))
    asc = [k[2] for k in sorted(keys)]
    full = sorted((k for k in keys if k[0] != 2), key=lambda k: (-k[0], -k[1], k[2])) + [k for k in keys if k[0] == 2]
    return asc, [k[2] for k in full]


def test_every_table_sorts_on_every_column_stably(report, browser):
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.goto((report["out"] / "report.html").as_uri())
    page.wait_for_load_state("load")
    tables = page.evaluate(_TABLES)
    texts = sorted({c[2] for t in tables for r in t for c in r})
    # the browser's own collator (numeric, case-insensitive) fixes the natural order of the texts
    ranked = page.evaluate(
        """ts => { const c = new Intl.Collator(undefined, {numeric: true, sensitivity: 'base'});
        return ts.slice().sort((a, b) => c.compare(a, b) || (a < b ? -1 : a > b ? 1 : 0)); }""",
        texts,
    )
    rank = {t: i for i, t in enumerate(ranked)}
    checked = 0
    for ti, rows in enumerate(tables):
        if not rows:
            continue
        for col in range(len(rows[0])):
            asc, desc = _expected_orders(rows, col, rank)
            first, second, third = (page.evaluate(_CLICK, [ti, col]) for _ in range(3))
            assert first == asc, (ti, col)
            assert second == desc, (ti, col)
            assert third == first, (ti, col)  # the same click always gives the same order
            checked += 1
    assert checked > 100
    # Table 1's System column: text order, the oracles' digits read as numbers within the name
    t1 = "h2#table-1-benchmark-results ~ .tablewrap table"
    page.click(f"{t1} th >> nth=0")
    assert _cells(page, t1, 0) == [
        "alpha",
        "beta",
        "gamma",
        "oracle-noise0.5 (calibration)",
        "oracle-noise1.5 (calibration)",
    ]
    page.close()


def test_page_reads_top_down_in_a_1400_px_window(report, browser):
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.goto((report["out"] / "report.html").as_uri())
    page.wait_for_load_state("load")
    # how to read it first, then Table 1 and a strip of pictures before any other table
    heads = page.eval_on_selector_all("main h2", "hs => hs.map(h => h.id)")
    assert heads[:4] == ["how-to-read-this", "runs", "table-1-benchmark-results", "at-a-glance"]
    first_img = page.evaluate("""() => { const img = document.querySelector('main img');
        const before = Array.from(document.querySelectorAll('main table')).filter(t =>
            !t.contains(img) && (t.compareDocumentPosition(img) & Node.DOCUMENT_POSITION_FOLLOWING));
        return {top: img.getBoundingClientRect().top + window.scrollY, tablesBefore: before.length,
                rowsBefore: before.map(t => t.rows.length)}; }""")
    assert first_img["tablesBefore"] == 1 and first_img["top"] < 2000, first_img  # only Table 1 comes before
    # the first task of each source with runs: PartNet's (target + 5 systems), Fantastic Breaks' (target + alpha)
    assert page.locator("table.glance tbody tr").count() == 2 and page.locator("table.glance img").count() == 6 + 2
    # the appendix is folded; a link from the contents opens its section
    assert page.eval_on_selector("h2#table-a-11-geometric-failure-classes", "h => !h.closest('details').open")
    opened = "() => document.getElementById('table-a-11-geometric-failure-classes').closest('details').open"
    page.click("nav a[href='#table-a-11-geometric-failure-classes']")
    page.wait_for_function(opened)
    page.eval_on_selector("h2#table-a-11-geometric-failure-classes", "h => { h.closest('details').open = false; }")
    page.click("nav a[href='#table-a-11-geometric-failure-classes']")  # the same link again: no hashchange
    page.wait_for_function(opened)
    # nothing is wider than the window: wide tables scroll inside their box
    page.evaluate("() => document.querySelectorAll('details').forEach(d => { d.open = true; })")
    widths = page.evaluate("""() => ({page: document.documentElement.scrollWidth, win: window.innerWidth,
        tables: Array.from(document.querySelectorAll('main table')).map(t => {
            const box = t.closest('.tablewrap'); const r = (box || t).getBoundingClientRect();
            return {w: t.scrollWidth, boxRight: r.right, boxed: !!box}; })})""")
    assert widths["page"] <= widths["win"] == 1400
    assert all(t["boxed"] and t["boxRight"] <= 1400 for t in widths["tables"]), widths["tables"]
    assert all(t["w"] <= 1400 for t in widths["tables"]), widths["tables"]
    page.close()


def test_cards_say_why_parts_in_place_score_zero(report):
    page = (report["out"] / "report.html").read_text()
    card = page.split(f'id="task-{TASK}"')[1].split('<section class="card"')[0]
    hints = re.findall(r'<p class="hint">(.*?)</p>', card)
    # beta placed one part of three, gamma two; alpha and the oracles' PA counts what they placed
    assert [h.split(":")[0] for h in hints] == ["beta", "gamma"]
    assert hints[0].startswith("beta: 1 of 3 parts lie at their targets as placed, yet PA is 0.0%")
    assert "the parts left away, p02, p03, pull that transform" in hints[0]
    assert hints[1].startswith("gamma: 2 of 3 parts lie at their targets as placed, yet PA is 0.0%")
    assert "the part left away, p03, pulls that transform off the parts in place" in hints[1]


def test_viewer_url_links_each_run_to_its_episode_page(report):
    """Last in this module: it rewrites the report with the links (renders and scores reused)."""
    url = "http://127.0.0.1:8770/?token=abc"
    assert (
        main([str(report["suite"]), str(report["runs"]), "--out", str(report["out"]), *OPTS, "--viewer-url", url]) == 0
    )
    page = (report["out"] / "report.html").read_text()
    card = page.split(f'id="task-{TASK}"')[1].split('<section class="card"')[0]
    links = re.findall(r'<a class="live" href="([^"]+)">([^<]+)</a>', card)
    assert ("http://127.0.0.1:8770/episode/alpha/" + TASK + "?token=abc", "alpha") in links
    assert len(links) == 5  # every system with a run of this task
    assert (
        main([str(report["suite"]), str(report["runs"]), "--out", str(report["out"]), *OPTS, "--viewer-url", "x"]) == 2
    )
