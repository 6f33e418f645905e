"""Small synthetic BVH corpora for the benchmark, corpus and transformer tests.

A 7-joint walker (``joint_Root`` static on top, like Bandai-Namco's files, then
Hips, Spine, Head and two legs) whose hips move forward along a slowly turning
heading while the spine sways and the legs swing; every clip has its own seeded
speed, phase and turn rate. Written with keyfill's own BVH writer.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from keyfill import io
from keyfill import rotations as R
from keyfill.motion import Motion, Skeleton

SIX = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
THREE = ("Zrotation", "Xrotation", "Yrotation")


def walker_skeleton(leg_length: float = 40.0, static_root: bool = True) -> Skeleton:
    names = ["Hips", "Spine", "Head", "Leg_L", "Foot_L", "Leg_R", "Foot_R"]
    parents = [-1, 0, 1, 0, 3, 0, 5]
    offsets = [[0, 90, 0], [0, 20, 0], [0, 25, 0], [10, -5, 0], [0, -leg_length, 0], [-10, -5, 0], [0, -leg_length, 0]]
    channels = [SIX] + [THREE] * 6
    if static_root:
        names = ["joint_Root"] + names
        parents = [-1] + [p + 1 for p in parents]
        offsets = [[0, 0, 0]] + offsets
        channels = [SIX] + channels
    return Skeleton(names, parents, offsets, channels, end_sites=())


def walker_motion(skeleton: Skeleton, frames: int, rng: np.random.Generator, fps: float = 30.0) -> Motion:
    """One clip: ``frames`` frames of a seeded walk."""
    J = skeleton.num_joints
    h = 1 if skeleton.names[0] == "joint_Root" else 0  # index of the hips
    t = np.arange(frames) / fps
    speed = rng.uniform(60, 140)  # cm/s
    turn = rng.uniform(-0.6, 0.6)  # rad/s
    yaw0 = rng.uniform(-np.pi, np.pi)
    phase = rng.uniform(0, 2 * np.pi)
    freq = rng.uniform(1.5, 2.5)
    yaw = yaw0 + turn * t
    heading = np.stack([np.sin(yaw), np.zeros_like(yaw), np.cos(yaw)], -1)
    step = np.concatenate([[0], np.full(frames - 1, speed / fps)])
    pos = np.cumsum(heading * step[:, None], axis=0) + rng.uniform(-200, 200, 3) * [1, 0, 1]
    pos[:, 1] = 90 + 2 * np.sin(2 * 2 * np.pi * freq * t + phase)
    rot = np.zeros((frames, J, 4))
    rot[..., 0] = 1
    rot[:, h] = R.euler_to_quat(np.stack([0.05 * np.sin(2 * np.pi * freq * t + phase), 0 * t, yaw], -1), "ZXY")
    swing = 0.5 * np.sin(2 * np.pi * freq * t + phase)
    rot[:, h + 1] = R.euler_to_quat(np.stack([0.1 * np.sin(2 * np.pi * freq * t), 0.05 * swing, 0 * t], -1), "ZXY")
    rot[:, h + 3] = R.euler_to_quat(np.stack([0 * t, swing, 0 * t], -1), "ZXY")
    rot[:, h + 4] = R.euler_to_quat(np.stack([0 * t, np.maximum(-swing, 0), 0 * t], -1), "ZXY")
    rot[:, h + 5] = R.euler_to_quat(np.stack([0 * t, -swing, 0 * t], -1), "ZXY")
    rot[:, h + 6] = R.euler_to_quat(np.stack([0 * t, np.maximum(swing, 0), 0 * t], -1), "ZXY")
    positions = np.broadcast_to(skeleton.offsets, (frames, J, 3)).copy()
    positions[:, h] = pos
    return Motion(skeleton, fps, rot, positions)


def write_corpus(folder: Path, styles=("happy", "tired", "calm"), clips_per_style: int = 3, seed: int = 0,
                 frames=(70, 130), skeleton: Skeleton | None = None) -> list[Path]:
    """Write ``walk_<style>_<i>.bvh`` clips into ``folder``; returns their paths."""
    rng = np.random.default_rng(seed)
    skeleton = skeleton or walker_skeleton()
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for style in styles:
        for i in range(clips_per_style):
            n = int(rng.integers(frames[0], frames[1] + 1))
            p = folder / f"walk_{style}_{i:03d}.bvh"
            io.save(walker_motion(skeleton, n, rng), p)
            paths.append(p)
    return paths
