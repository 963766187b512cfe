"""Episode states restored with MuJoCo: poses, the final state, MJB worlds, continuation."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from aw.official.archive import EpisodeArchive, Frame, write_archive
from aw.official.episode import (
    catalogue_part_ids,
    check_continuation,
    free_body_rotations,
    load_model,
    read_part_episode,
)
from aw.official.errors import EpisodeMismatchError, WorldModelError
from tests.aw.official.builders import FINAL, INITIAL, PART_IDS, write_active, write_setup


def to_mjb(ep: EpisodeArchive, path) -> EpisodeArchive:
    """The same episode with its world compiled to MJB, as the official MJB archives hold it."""
    import mujoco

    model = load_model(ep)
    buffer = np.empty(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    manifest = dict(copy.deepcopy(ep.manifest), model={"format": "mjb", "path": "model.mjb"})
    files = {n: d for n, d in ep.files.items() if not n.startswith("world/")}
    files["world/model.mjb"] = buffer.tobytes()
    return write_archive(
        EpisodeArchive(path, manifest, files, ep.initial, ep.states, ep.traces, ep.calls, ep.events), path
    )


def test_poses_of_every_state(tmp_path):
    setup = write_setup(tmp_path / "s.episode.zip")
    final = write_active(setup, tmp_path / "f.episode.zip")
    ep = read_part_episode(final.path, setup.path)
    assert ep.part_ids == PART_IDS == catalogue_part_ids(final)
    assert ep.poses.shape == (4, 3, 7)
    np.testing.assert_allclose(ep.poses[0], INITIAL, atol=1e-15)
    assert np.array_equal(ep.final_poses(), FINAL) and ep.final_index == 3
    assert np.array_equal(ep.poses[1, 0], FINAL[0]) and np.array_equal(ep.poses[1, 1:], ep.poses[0, 1:])


def test_final_state_is_the_highest_state_not_the_last_row(tmp_path):
    setup = write_setup(tmp_path / "s.episode.zip")
    final = write_active(setup, tmp_path / "f.episode.zip")
    last = final.calls[-2]  # the failed call: give it one more trace holding the initial state
    final.traces.append(
        Frame(
            "trace",
            dict(final.traces[-1].record, index=len(final.traces), call_id=last["id"]),
            final.initial.integration.copy(),
        )
    )
    last["trace_end"] = len(final.traces)
    final.calls[-1].update(trace_start=len(final.traces), trace_end=len(final.traces))
    rewritten = write_archive(final, tmp_path / "g.episode.zip")
    assert np.array_equal(rewritten.traces[-1].integration, setup.initial.integration)
    assert np.array_equal(read_part_episode(rewritten, setup).final_poses(), FINAL)


def test_mjb_world(tmp_path):
    setup = write_setup(tmp_path / "s.episode.zip")
    final = write_active(setup, tmp_path / "f.episode.zip")
    setup_mjb, final_mjb = to_mjb(setup, tmp_path / "s.mjb.episode.zip"), to_mjb(final, tmp_path / "f.mjb.episode.zip")
    assert final_mjb.is_mjb and "world/model.xml" not in final_mjb.files
    ep = read_part_episode(final_mjb.path, setup_mjb.path)
    assert np.array_equal(ep.final_poses(), FINAL)
    with pytest.raises(EpisodeMismatchError, match="model declaration"):
        check_continuation(final_mjb, setup, PART_IDS)


def test_continuation_checks(tmp_path):
    setup = write_setup(tmp_path / "s.episode.zip")
    final = write_active(setup, tmp_path / "f.episode.zip")
    other = write_setup(tmp_path / "other.episode.zip", PART_IDS[:2])
    with pytest.raises(EpisodeMismatchError, match="catalogue"):
        check_continuation(final, other, PART_IDS)
    with pytest.raises(EpisodeMismatchError, match="catalogue"):
        read_part_episode(final.path, setup.path, ["0", "1", "3"])
    changed = copy.deepcopy(final)
    changed.manifest["id"] = "another"
    with pytest.raises(EpisodeMismatchError, match="id differs"):
        check_continuation(changed, setup, PART_IDS)
    changed = copy.deepcopy(final)
    changed.files["world/meshes/part-0001.obj"] += b"\n"
    with pytest.raises(EpisodeMismatchError, match="world/"):
        check_continuation(changed, setup, PART_IDS)


def test_world_problems(tmp_path):
    setup = write_setup(tmp_path / "s.episode.zip")
    broken = copy.deepcopy(setup)
    del broken.files["world/meshes/part-0002.obj"]
    with pytest.raises(WorldModelError, match="part-0002.obj"):
        load_model(broken)
    broken = copy.deepcopy(setup)
    bodies = "".join(f"<body name='{n}'><freejoint/><geom size='.1'/></body>" for n in "abc")
    broken.files["world/model.xml"] = f"<mujoco><worldbody>{bodies}</worldbody></mujoco>".encode()
    with pytest.raises(WorldModelError, match="no bodies"):
        read_part_episode(broken)
    broken.files["world/model.xml"] = b"<mujoco><worldbody><body name='part-0001'/></worldbody></mujoco>"
    with pytest.raises(EpisodeMismatchError, match="stateSize"):
        read_part_episode(broken)


def test_free_body_rotations_are_mujocos_xmat(tmp_path):
    """The rotations MuJoCo's forward kinematics leaves in ``xmat`` for the stored joint
    quaternions (unit, a few bits off unit, far off unit), bit for bit; SciPy's matrices of
    the same quaternions differ from them in the last bits."""
    import mujoco
    from scipy.spatial.transform import Rotation

    setup = write_setup(tmp_path / "s.episode.zip")
    model = load_model(setup)
    data = mujoco.MjData(model)
    rng = np.random.default_rng(4)
    scipy_differs = 0
    for trial in range(30):
        quats = rng.normal(size=(3, 4))
        quats /= np.linalg.norm(quats, axis=1, keepdims=True)
        quats *= [[1.0], [1 + 3e-16 * (trial % 5 - 2)], [2.5]]
        for k, q in enumerate(quats):
            data.qpos[7 * k : 7 * k + 7] = [0.1 * k, 0.0, 0.2, *q]
        mujoco.mj_forward(model, data)
        want = data.xmat[1:4].reshape(3, 3, 3)
        assert np.array_equal(free_body_rotations(quats), want)
        scipy_differs += not np.array_equal(Rotation.from_quat(quats[:, [1, 2, 3, 0]]).as_matrix(), want)
    assert scipy_differs > 0
