"""PA decreases diagnosed with the earlier checkpoint's registration and matching held fixed."""

from __future__ import annotations

import numpy as np
import pytest

import aw_eval
from aw.formats import read_targets
from aw.formats.suite import suite_paths
from aw_eval.settings import ProtocolSettings
from aw_eval.study.decreases import pa_decreases
from aw_eval.study.fixtures import box_suite


@pytest.fixture(scope="module")
def task(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("dec")
    suite = box_suite(tmp / "s", objects_per_source=1, n_parts=3, blocks=(("assemblybench", ("manual",)),))
    task_dir, targets_path = suite_paths(suite, "assemblybench-box000-manual")
    geom = aw_eval.load_task_geometry(
        task_dir, targets_path, cache_dir=tmp / "g", settings=ProtocolSettings(n_surface=256, n_fps=64)
    )
    targets = read_targets(targets_path)
    good = np.array([targets.parts[p].pose for p in geom.part_ids])
    return geom, good


def test_a_part_moved_away_is_a_persistent_decrease(task):
    geom, good = task
    away = good.copy()
    away[0, :3] += [3.0, 0.0, 0.0]  # one part far from the rest
    poses = np.stack([good, away, away, good])
    b = aw_eval.score_batch(geom, poses, mode="fast")
    assert b.pa.tolist()[0] == 1.0 and b.pa[1] < 1.0
    d = pa_decreases(geom, poses, b.pa, b.assignment, b.reg_rotation, b.reg_translation)
    assert d.index.tolist() == [0]  # 1 -> 2 is no change, 2 -> 3 an increase
    assert d.persist_alignment.tolist() == [True] and d.persist_both.tolist() == [True]
    assert d.assignment_changed.tolist() == [False]
    none = pa_decreases(geom, poses[:1], b.pa[:1], b.assignment[:1], b.reg_rotation[:1], b.reg_translation[:1])
    assert len(none.index) == 0


def test_a_drop_that_the_earlier_alignment_does_not_reproduce(task):
    """A recorded drop whose later state scores fine under the earlier registration and matching
    (here: the same state twice, with a PA drop fed in) does not persist."""
    geom, good = task
    poses = np.stack([good, good])
    b = aw_eval.score_batch(geom, poses, mode="fast")
    assignment = np.array([[0, 1, 2], [1, 0, 2]])  # as if the later checkpoint had been matched differently
    d = pa_decreases(geom, poses, np.array([1.0, 0.0]), assignment, b.reg_rotation, b.reg_translation)
    assert d.index.tolist() == [0]
    assert d.assignment_changed.tolist() == [True]
    assert d.persist_alignment.tolist() == [False] and d.persist_both.tolist() == [False]
