"""Builders of official-format files: an AssemblyWorldBench package and 3DWebAgent episode
archives, the latter simulated with MuJoCo from a small scene (one free-jointed body per part,
``qpos`` rows as frames). Written with zipfile/hashlib directly, independent of aw.official."""

from __future__ import annotations

import hashlib
import json
import zipfile
from pathlib import Path

import numpy as np

from aw.pose import compose_poses


def scene_xml(part_ids: list[str], half_sizes: list[tuple[float, float, float]], mesh_asset: bool = False) -> str:
    bodies = []
    for pid, hs in zip(part_ids, half_sizes):
        geom = f'<geom type="box" size="{hs[0]} {hs[1]} {hs[2]}"/>'
        # body declared away from the origin: its free joint's qpos is still its world pose
        bodies.append(f'<body name="{pid}" pos="0.3 0.1 0.2"><freejoint name="j_{pid}"/>{geom}</body>')
    asset = ""
    extra = ""
    if mesh_asset:
        asset = '<asset><mesh name="tet" file="tet.obj"/></asset>'
        extra = '<body name="deco" pos="0 0 -1"><geom type="mesh" mesh="tet"/></body>'
    return f'<mujoco model="scene">{asset}<worldbody>{"".join(bodies)}{extra}</worldbody></mujoco>'


TET_OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


def qpos_rows(poses: np.ndarray, extra_nq: int = 0) -> np.ndarray:
    """``(F, P, 7)`` poses -> qpos rows ``(F, 7 P)`` (free joints: position then wxyz)."""
    f, p, _ = poses.shape
    rows = poses.reshape(f, p * 7)
    if extra_nq:
        rows = np.concatenate([rows, np.zeros((f, extra_nq))], axis=1)
    return rows


def episode_poses(targets: np.ndarray, n_frames: int, seed: int = 0, finish_exact: bool = True) -> np.ndarray:
    """``(F, P, 7)``: identity at frame 0, then a path of moves ending at ``targets`` (or near)."""
    rng = np.random.default_rng(seed)
    p = len(targets)
    ident = np.tile([0, 0, 0, 1.0, 0, 0, 0], (p, 1))
    frames = [ident]
    for k in range(1, n_frames):
        cur = frames[-1].copy()
        i = k % p
        if k == n_frames - 1 and finish_exact:
            cur = targets.copy()
        else:
            cur[i] = targets[i] if rng.random() < 0.5 else compose_poses(
                np.array([*(0.05 * rng.normal(size=3)), 1.0, 0, 0, 0]), targets[i])
        frames.append(cur)
    out = np.stack(frames)
    out[..., 3:] /= np.linalg.norm(out[..., 3:], axis=-1, keepdims=True)
    # MuJoCo keeps the sign of a quaternion; use a canonical one (qw >= 0) so poses compare exactly
    out[..., 3:] *= np.where(out[..., 3:4] < 0, -1.0, 1.0)
    return out


def write_archive(path: Path, members: dict[str, bytes], manifest: dict, hash_overrides: dict | None = None,
                  extra_members: dict[str, bytes] | None = None, unlisted: tuple[str, ...] = ()) -> Path:
    """A zip with ``manifest.json`` listing every member's sha256 (optionally tampered with)."""
    files = {}
    for name, data in members.items():
        if name in unlisted:
            continue
        files[name] = {"sha256": hashlib.sha256(data).hexdigest(), "size": len(data)}
    for name, h in (hash_overrides or {}).items():
        files[name] = {"sha256": h, "size": files.get(name, {}).get("size")}
    man = dict(manifest, files=files)
    path.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("manifest.json", json.dumps(man))
        for name, data in {**members, **(extra_members or {})}.items():
            zf.writestr(name, data)
    return path


def episode_members(part_ids: list[str], half_sizes, poses: np.ndarray, mesh_asset: bool = False,
                    end_reason: str | None = "finished") -> dict[str, bytes]:
    """Members of an episode whose frames are ``poses (F, P, 7)``; frame k > 0 follows call k."""
    rows = qpos_rows(poses)
    n = len(rows)
    frames = [{"frame": k, "t": 1.5 * k, "call": (k if k > 0 else None)} for k in range(n)]
    calls = []
    for k in range(1, n):
        calls.append({"seq": k, "t": 1.5 * k - 0.1, "tool": "set_object_pose", "args": {"id": part_ids[k % len(part_ids)]}, "ok": True})
    if n > 2:  # a camera call between frames: no state is recorded for it
        calls.append({"seq": 100, "t": 1.5 * n, "tool": "capture_scene", "args": {}, "ok": True})
    events = [{"t": 0.0, "type": "start"}]
    if end_reason:
        events.append({"t": 1.5 * n, "type": "end", "reason": end_reason})
    m = {
        "frames.jsonl": "\n".join(json.dumps(f) for f in frames).encode() + b"\n",
        "frames.bin": rows.astype("<f8").tobytes(),
        "calls.jsonl": "\n".join(json.dumps(c) for c in calls).encode() + b"\n",
        "events.jsonl": "\n".join(json.dumps(e) for e in events).encode() + b"\n",
        "world/model.xml": scene_xml(part_ids, half_sizes, mesh_asset).encode(),
    }
    if mesh_asset:
        m["world/tet.obj"] = TET_OBJ
    return m


def write_package(root: Path, samples: list[dict], inputs: dict[str, dict]) -> Path:
    """``manifest.json`` + ``eval/<sample_id>.npz`` (inputs: part_ids, points, target_poses,
    scale_divisor, equivalence_groups labels)."""
    (root / "eval").mkdir(parents=True, exist_ok=True)
    (root / "manifest.json").write_text(json.dumps({"format": "assemblyworldbench.package", "samples": samples}))
    for sid, arrays in inputs.items():
        np.savez(root / "eval" / f"{sid}.npz", **arrays)
    return root
