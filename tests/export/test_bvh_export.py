"""BVH export: re-parse our own file (an independent minimal reader below), run its forward
kinematics and compare joint world positions with numeric_fk."""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

from scenarios.errors import ComposeError, InputError
from scenegraph.export import bvh as bvh_export
from scenegraph.model.body import make_character, standing_pose
from scenegraph.export.bvh import AXES, euler_zyx, export_bvh, resample_q
from scenegraph.model.kinematics import numeric_fk
from scenegraph.export.usd import CharacterTrack


def synthetic_q(ch, T, fps, seed):
    rng = np.random.default_rng(seed)
    t = np.arange(T) / fps
    q = np.tile(standing_pose(ch), (T, 1))
    lo, hi = ch.lower, ch.upper
    for j in range(6, q.shape[1]):
        amp = 0.45 * min(hi[j] - lo[j], 2.0)
        q[:, j] = np.clip(amp * np.sin(2 * np.pi * rng.uniform(0.3, 1.5) * t + rng.uniform(0, 6.3)), lo[j], hi[j])
    q[:, 0] = 1.1 * t
    q[:, 1] = 0.2 * np.sin(3 * t)
    q[:, 3] = 2.5 * t  # heading sweeps through 0..~145°: crosses the ZYX gimbal of the root
    q[:, 4] = 0.3 * np.sin(2 * t)
    q[:, 5] = 0.2 * np.sin(3 * t)
    return q


# --- a minimal independent BVH reader ------------------------------------------------------------

def parse_bvh(text):
    tok = text.split()
    i = 0
    joints = []  # (name, parent, offset, channels)
    ends = []  # (parent, offset)

    def block(parent):
        nonlocal i
        kind = tok[i]
        if kind == "End":
            assert tok[i + 1] == "Site" and tok[i + 2] == "{" and tok[i + 3] == "OFFSET"
            ends.append((parent, np.array(list(map(float, tok[i + 4:i + 7])))))
            assert tok[i + 7] == "}"
            i += 8
            return
        assert kind in ("ROOT", "JOINT"), kind
        name = tok[i + 1]
        assert tok[i + 2] == "{" and tok[i + 3] == "OFFSET"
        off = np.array(list(map(float, tok[i + 4:i + 7])))
        assert tok[i + 7] == "CHANNELS"
        n = int(tok[i + 8])
        chans = tok[i + 9:i + 9 + n]
        i += 9 + n
        me = len(joints)
        joints.append((name, parent, off, chans))
        while tok[i] != "}":
            block(me)
        i += 1

    assert tok[0] == "HIERARCHY"
    i = 1
    block(-1)
    assert tok[i] == "MOTION" and tok[i + 1] == "Frames:" and tok[i + 3] == "Frame" and tok[i + 4] == "Time:"
    F = int(tok[i + 2])
    dt = float(tok[i + 5])
    vals = np.array(list(map(float, tok[i + 6:])))
    C = sum(len(j[3]) for j in joints)
    assert vals.size == F * C
    return joints, ends, dt, vals.reshape(F, C)


def _rot(axis, deg):
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return {"X": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "Y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "Z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def bvh_world_positions(joints, motion):
    """(F, J, 3) joint world positions (file units and axes)."""
    F = motion.shape[0]
    out = np.zeros((F, len(joints), 3))
    for f in range(F):
        col = 0
        Rw, pw = [], []
        for j, (name, parent, off, chans) in enumerate(joints):
            t = off.copy()
            R = np.eye(3)
            for c in chans:
                v = motion[f, col]
                col += 1
                if c.endswith("position"):
                    t["XYZ".index(c[0])] += v
                else:
                    R = R @ _rot(c[0], v)
            if parent < 0:
                Rw.append(R)
                pw.append(t)
            else:
                Rw.append(Rw[parent] @ R)
                pw.append(pw[parent] + Rw[parent] @ t)
            out[f, j] = pw[-1]
    return out


@pytest.fixture(scope="module")
def character():
    return make_character("adult_female")


def _check_against_fk(path, ch, q, units_scale=100.0):
    joints, ends, dt, motion = parse_bvh(path.read_text())
    names = [b.name for b in ch.bodies]
    order = [names.index(j[0]) for j in joints]  # BVH (depth-first) order -> body index
    assert sorted(order) == list(range(18))
    assert joints[0][3] == ["Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"]
    assert all(j[3] == ["Zrotation", "Yrotation", "Xrotation"] for j in joints[1:])
    pos = bvh_world_positions(joints, motion)  # file axes, file units
    ours = pos @ AXES / units_scale  # back to our axes (AXES is orthogonal), metres
    R, p = numeric_fk(ch, q)
    assert motion.shape[0] == q.shape[0]
    err = np.abs(ours - p[:, order]).max()
    return err, dt, joints, ends


def test_joint_positions_match_fk(tmp_path, character):
    q = synthetic_q(character, 40, 30.0, seed=3)
    path = export_bvh(tmp_path / "walk.bvh", CharacterTrack("A", character, q), 30.0)
    err, dt, joints, ends = _check_against_fk(path, character, q)
    assert err < 1e-6, err
    assert dt == pytest.approx(1 / 30, abs=1e-8)
    assert len(joints) == 18 and len(ends) == 5  # head, 2 hands, 2 toes
    # Y up: the head's End Site points up in the rest pose, the root starts at standing height.
    names = [j[0] for j in joints]
    head_end = [o for par, o in ends if names[par] == "head"][0]
    assert head_end[1] > 0 and abs(head_end[0]) < 1e-9 and abs(head_end[2]) < 1e-9
    assert os.listdir(tmp_path) == ["walk.bvh"]


def test_resampled_frame_rate(tmp_path, character):
    q = synthetic_q(character, 31, 30.0, seed=4)  # 1 s at 30 fps
    path = export_bvh(tmp_path / "r.bvh", CharacterTrack("A", character, q), 24.0, source_fps=30.0, units="m")
    q24 = resample_q(q, 30.0, 24.0)
    assert q24.shape[0] == 25
    err, dt, _, _ = _check_against_fk(path, character, q24, units_scale=1.0)
    assert err < 1e-6 and dt == pytest.approx(1 / 24, abs=1e-8)
    # exact at shared instants (t = 0, 1/6, 1/3 ... s)
    assert np.allclose(q24[::4], q[::5])


def test_euler_zyx_roundtrip_and_continuity():
    rng = np.random.default_rng(1)
    ang = np.cumsum(rng.normal(scale=0.2, size=(300, 3)), axis=0)  # wanders far beyond ±π
    ang[:, 1] = np.clip(ang[:, 1], -1.4, 1.4)
    R = np.array([_rot("Z", math.degrees(a)) @ _rot("Y", math.degrees(b)) @ _rot("X", math.degrees(c)) for a, b, c in ang])
    out = euler_zyx(R)
    back = np.array([_rot("Z", math.degrees(a)) @ _rot("Y", math.degrees(b)) @ _rot("X", math.degrees(c)) for a, b, c in out])
    assert np.allclose(back, R, atol=1e-12)
    assert np.abs(np.diff(out, axis=0)).max() < 1.0  # no ±360° jumps


def test_gimbal_lock_is_exact():
    R = np.array([_rot("Z", 30) @ _rot("Y", 90) @ _rot("X", 10)])
    a = euler_zyx(R)[0]
    back = _rot("Z", math.degrees(a[0])) @ _rot("Y", math.degrees(a[1])) @ _rot("X", math.degrees(a[2]))
    assert np.allclose(back, R[0], atol=1e-9)


def test_bad_input_and_atomic_write(tmp_path, character, monkeypatch):
    q = synthetic_q(character, 5, 30.0, seed=5)
    tr = CharacterTrack("A", character, q)
    with pytest.raises(InputError):
        export_bvh(tmp_path / "x.bvh", tr, 0.0)
    with pytest.raises(InputError):
        export_bvh(tmp_path / "x.bvh", tr, 30.0, units="inch")
    with pytest.raises(InputError):
        export_bvh(tmp_path / "x.bvh", CharacterTrack("A", character, q[:, :30]), 30.0)
    target = tmp_path / "keep.bvh"
    target.write_text("OLD")

    def boom(a, b):
        raise OSError("no space left")
    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(ComposeError, match="no space"):
        export_bvh(target, tr, 30.0)
    assert target.read_text() == "OLD" and os.listdir(tmp_path) == ["keep.bvh"]
