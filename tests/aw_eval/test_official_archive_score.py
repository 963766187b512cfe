"""assembly-world-bench ``tests/test_core.py`` (``test_xml_mjb_and_official_scoring``): the
official fixture's initial episode, scored against identity targets with the fixture's cloud
(``default_rng(12)`` normal, 1000 points, divisor 1), has PA = SR = 1 and SCD < 1e-20; the same
holds here, for XML and MJB worlds, from the state this project restores."""

from __future__ import annotations

import numpy as np
import pytest

from aw.official.archive import read_archive
from aw.official.episode import read_part_episode
from aw_eval import TaskGeometry, score
from tests.aw.official.test_official_fixture import official_style_episode


@pytest.mark.parametrize("mjb", [False, True])
def test_official_fixture_scores(tmp_path, mjb):
    path = tmp_path / "sample-00.episode.zip"
    path.write_bytes(official_style_episode(mjb))
    arc = read_archive(path)
    poses = read_part_episode(arc, arc, ["p"]).final_poses()
    cloud = np.random.default_rng(12).normal(size=(1000, 3))
    geom = TaskGeometry.from_points(["p"], cloud[None], np.array([[0, 0, 0, 1.0, 0, 0, 0]]), 1.0, [["p"]])
    res = score(geom, poses, mode="exact")
    assert res.pa == 1 and bool(res.sr) and 1000 * res.scd < 1e-20
