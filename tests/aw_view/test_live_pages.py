"""aw-view in Debian's Chromium while a scripted agent drives a real aw-serve over MCP: the runs
page's row appears and its call count grows, the episode page's call list, 3D scene and captures
follow each recorded call, two browsers watch at once, the final status shows, and a recording
deleted while it is watched leaves both pages standing."""

from __future__ import annotations

import shutil

import pytest
from view_helpers import ONE_TASK, ScriptedAgent, get_json, viewer

from aw.formats import read_manifest
from aw.formats.suite import suite_paths
from aw_eval.study.fixtures import box_suite

WAIT = 120_000  # ms: page loads share two cores with the rest of the suite


def _watch_errors(page) -> list[str]:
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    return errors


def _calls_are(rid: str, n: int) -> str:
    """A page function: the runs page's row ``rid`` shows ``n`` calls."""
    return f"""() => {{ const tr = document.querySelector('#runs tr[data-id="{rid}"]');
        return !!tr && tr.querySelector('td.calls').textContent === '{n}'; }}"""


def _first_x(page) -> list[float]:
    """x of the first vertex of every part's trace in the episode page's scene."""
    return page.evaluate("() => document.getElementById('plot').data.slice(0, 3).map(t => t.x[0])")


@pytest.fixture
def suite(tmp_path):
    return box_suite(tmp_path / "suite", objects_per_source=1, n_parts=3, blocks=ONE_TASK)


def test_pages_follow_a_live_episode_of_a_real_server(suite, tmp_path, browser):
    (task_id,) = [t.task_id for t in read_manifest(suite).tasks]
    task_dir = suite_paths(suite, task_id)[0]
    runs = tmp_path / "runs"
    rid = f"scripted/{task_id}"
    with viewer(runs.resolve(), [suite / "tasks"]) as url:
        runs.mkdir()
        agent = ScriptedAgent(task_dir, runs / "scripted" / task_id)
        first = browser.new_context(viewport={"width": 1300, "height": 900})
        second = browser.new_context(viewport={"width": 1300, "height": 900})  # another browser's session
        pages = first.new_page()
        errors = _watch_errors(pages)
        pages.goto(url)
        pages.wait_for_selector(f'#runs tr[data-id="{rid}"][data-status="running"]', timeout=WAIT)

        agent.call("start_episode")
        agent.call("list_objects")
        pages.wait_for_function(_calls_are(rid, 2), timeout=WAIT)

        episode = first.new_page()
        errors += _watch_errors(episode)
        episode.goto(f"{url}episode/{rid}")
        episode.wait_for_selector("#plot[data-ready='1']", timeout=WAIT)
        episode.wait_for_function("() => document.body.dataset.calls === '2'", timeout=WAIT)
        before = _first_x(episode)
        assert episode.locator("#calls tbody tr").count() == 2
        assert episode.locator("#references img").count() == 1  # the task's reference image

        agent.call("translate_objects", {"ids": ["p01"], "delta": [0.3, 0.0, 0.0]})
        episode.wait_for_function(
            "() => document.getElementById('plot').dataset.state === '1' && document.body.dataset.calls === '3'",
            timeout=WAIT,
        )
        after = _first_x(episode)
        assert after[0] == pytest.approx(before[0] + 0.3, abs=1e-4) and after[1:] == before[1:]
        assert "translate_objects" in episode.locator("#calls tbody tr").nth(2).text_content()

        # moving the slider stops following; the box brings the newest state back
        episode.eval_on_selector("#slider", "s => { s.value = '0'; s.dispatchEvent(new Event('input')); }")
        episode.wait_for_function("() => document.getElementById('plot').dataset.state === '0'", timeout=WAIT)
        agent.call("translate_objects", {"ids": ["p02"], "delta": [0.0, 0.2, 0.0]})
        episode.wait_for_function("() => document.getElementById('plot').dataset.states === '3'", timeout=WAIT)
        assert episode.eval_on_selector("#plot", "p => p.dataset.state") == "0" and _first_x(episode) == before
        episode.check("#follow")
        episode.wait_for_function("() => document.getElementById('plot').dataset.state === '2'", timeout=WAIT)

        agent.call("rotate_objects", {"ids": ["p09"], "angles": [0, 0, 90]})  # refused: an unknown id
        agent.call("capture_scene")
        watcher = second.new_page()
        errors += _watch_errors(watcher)
        watcher.goto(url)
        for page in (pages, watcher):
            page.wait_for_function(_calls_are(rid, 6), timeout=WAIT)
            page.wait_for_function(
                f"""() => {{ const i = document.querySelector('#runs tr[data-id="{rid}"] td.thumb img');
                    return i && i.complete && i.naturalWidth > 0; }}""",
                timeout=WAIT,
            )
        episode.wait_for_function("() => document.body.dataset.calls === '6'", timeout=WAIT)
        assert "error: unknown id" in episode.locator("#calls tbody tr").nth(4).text_content()
        episode.wait_for_function(
            "() => Array.from(document.querySelectorAll('#captures img')).some(i => i.complete && i.naturalWidth > 0)",
            timeout=WAIT,
        )

        agent.close()
        for page in (pages, watcher):
            page.wait_for_selector(f'#runs tr[data-id="{rid}"][data-status="finished"]', timeout=WAIT)
        episode.wait_for_function("() => document.body.dataset.status === 'finished'", timeout=WAIT)
        assert "the client disconnected" in episode.locator("#status").text_content()

        # deleted while watched: the row goes, the episode page says so and keeps what it showed
        shutil.rmtree(runs / "scripted")
        pages.wait_for_function(f"""() => !document.querySelector('#runs tr[data-id="{rid}"]')""", timeout=WAIT)
        episode.wait_for_function("() => document.body.dataset.gone === '1'", timeout=WAIT)
        assert "gone" in episode.locator("#problems").text_content()
        assert episode.locator("#calls tbody tr").count() == 6
        assert get_json(url + "api/runs")["rows"] == []
        assert errors == []
        first.close()
        second.close()
