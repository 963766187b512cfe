"""The official test fixture's episode (assembly-world-bench ``tests/conftest.py``
``make_episode``: one free box, written with ``zipfile`` defaults and ``json.dumps``), built here
the same way, opens with this reader: XML and MJB, state size 38, the initial frame as the
final state."""

from __future__ import annotations

import hashlib
import io
import json
import zipfile

import numpy as np
import pytest

from aw.official.archive import read_archive
from aw.official.episode import read_part_episode


def official_style_episode(mjb: bool) -> bytes:
    import mujoco

    xml = b'<mujoco><worldbody><body name="part-0001"><freejoint/><geom type="box" size=".1 .2 .3"/></body></worldbody></mujoco>'
    model = mujoco.MjModel.from_xml_string(xml.decode())
    spec = int(mujoco.mjtState.mjSTATE_INTEGRATION)
    state = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, mujoco.MjData(model), state, spec)
    frame = {
        "kind": "initial",
        "index": 0,
        "groups": [],
        "groupCounter": 0,
        "camera": {"position": [3, -4, 3], "target": [0, 0, 0]},
    }
    files = {
        "world/model.xml": xml,
        "frames.bin": state.astype("<f8").tobytes(),
        "frames.jsonl": json.dumps(frame).encode(),
        "calls.jsonl": b"",
        "events.jsonl": b"",
    }
    physics = {
        "enabled": False,
        "detection": False,
        "response": False,
        "gravity": [0, 0, -9.81],
        "strategy": "fixed",
        "duration": 0.25,
        "maxDuration": 5,
        "quietDuration": 0.1,
        "linearThreshold": 0.01,
        "angularThreshold": 0.01,
    }
    manifest = {
        "format": "3dwebagent-episode",
        "version": 1,
        "id": "fixture",
        "name": "Synthetic fixture",
        "contract": "3dwebagent-runtime-1",
        "engine": "3.12.0",
        "lifecycle": "setup",
        "originTime": 0,
        "units": "normalized",
        "task": "Assemble.",
        "requiredCapabilities": ["state"],
        "producer": {
            "backend": "native",
            "build": "0" * 64,
            "engine": "3.12.0",
            "implementation": "synthetic-fixture",
            "language": "python",
        },
        "stateSpec": spec,
        "stateSize": len(state),
        "objects": [{"id": "part-0001", "name": "Part p", "type": "rigid", "collisionEnabled": False}],
        "runtime": {"enabledTools": [], "physics": physics},
    }
    if mjb:
        buffer = np.empty(mujoco.mj_sizeModel(model), dtype=np.uint8)
        mujoco.mj_saveModel(model, None, buffer)
        files["world/model.mjb"] = buffer.tobytes()
        del files["world/model.xml"]
        manifest["model"] = {"format": "mjb", "path": "model.mjb"}
    manifest["hashes"] = {k: hashlib.sha256(v).hexdigest() for k, v in files.items()}
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as zf:  # stored entries, manifest first, as the official fixture
        zf.writestr("manifest.json", json.dumps(manifest))
        for name, value in files.items():
            zf.writestr(name, value)
    return out.getvalue()


@pytest.mark.parametrize("mjb", [False, True])
def test_official_fixture_episode_opens(tmp_path, mjb):
    path = tmp_path / "sample-00.episode.zip"
    path.write_bytes(official_style_episode(mjb))
    arc = read_archive(path)
    assert arc.manifest["id"] == "fixture" and arc.manifest["stateSize"] == 38 and arc.is_mjb == mjb
    ep = read_part_episode(arc, arc, ["p"])
    assert ep.final_index == 0 and np.array_equal(ep.final_poses(), [[0, 0, 0, 1, 0, 0, 0]])
