"""Mocap import: BVH parsing, units/axes/floor, T-pose, resampling, retargeting, contacts,
and a corpus of malformed files (tests/bad_bvh) that must fail with the right line."""
from __future__ import annotations

import math
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from scenarios.errors import InputError
from scenegraph.model.body import N_DOF
from scenegraph.mocap.bvh import (END_SUFFIX, euler_channels_to_quat, quat_slerp, quat_to_matrix,
                            read_bvh, parse_bvh)
from scenegraph.mocap.contacts import detect_footsteps
from scenegraph.model.rotations import quat_from_matrix
from scenegraph.mocap.clip import load_clip, load_rig, read_clip

ROOT = Path(__file__).resolve().parents[2]
CLIPS = ROOT / "scenarios" / "clips"
BAD = Path(__file__).resolve().parents[1] / "bad_bvh"
C0701 = CLIPS / "walk_neutral_cmu_07_01.bvh"

# file: (frames, has T-pose, rig variant) — as in the mocap delivery's README
SHIPPED = {
    "walk_neutral_cmu_07_01.bvh": (317, True, "cmu/motionbuilder"),
    "walk_neutral_cmu_08_02.bvh": (310, True, "cmu/motionbuilder"),
    "run_cmu_09_11.bvh": (166, True, "cmu/motionbuilder"),
    "walk_stylized_mj_cmu_131_01.bvh": (994, False, "cmu/3dsmax"),
    "jump_broad_cmu_16_05.bvh": (296, True, "cmu/motionbuilder"),
}
# forward travel of the sacrum over the clip (m): the walks and the run travel more than 2 m,
# the standing broad jump 1.07 m stance to stance (README_jump.md)
MIN_TRAVEL = {"jump_broad_cmu_16_05.bvh": 0.9}


# --- parsing --------------------------------------------------------------------------------

@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_parse_shipped_clip(name):
    frames, _, _ = SHIPPED[name]
    b = read_bvh(CLIPS / name)
    assert b.n_frames == frames
    assert len(b.channel_joints) == 31  # the root plus 30 joints
    assert sum(j.end_site for j in b.joints) == 7
    assert b.n_channels == 96
    assert b.fps == pytest.approx(120.0, rel=1e-3)
    assert b.joints[0].name == "Hips" and b.joints[0].channels[:3] == ("Xposition", "Yposition", "Zposition")


def test_no_iclone_clip_is_shipped():
    assert not list(CLIPS.glob("*iclone*"))
    assert sorted(p.name for p in CLIPS.glob("*.bvh")) == sorted(SHIPPED)
    assert "mocap.cs.cmu.edu" in (CLIPS / "README.md").read_text()


def test_euler_channels_are_a_matrix_product():
    rng = np.random.default_rng(0)
    ang = rng.uniform(-170, 170, 3)

    def R(axis, a):
        c, s = math.cos(math.radians(a)), math.sin(math.radians(a))
        return {0: np.array([[1, 0, 0], [0, c, -s], [0, s, c]]), 1: np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
                2: np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]

    q = euler_channels_to_quat(ang, (2, 1, 0))  # "Zrotation Yrotation Xrotation"
    assert np.allclose(quat_to_matrix(q), R(2, ang[0]) @ R(1, ang[1]) @ R(0, ang[2]))
    q2 = euler_channels_to_quat(ang, (2, 0, 1))  # the 3dsMax arms: "Zrotation Xrotation Yrotation"
    assert np.allclose(quat_to_matrix(q2), R(2, ang[0]) @ R(0, ang[1]) @ R(1, ang[2]))
    assert np.allclose(np.abs(quat_from_matrix(quat_to_matrix(q))), np.abs(q))


def test_slerp_takes_the_short_way_through_gimbal_lock():
    # Two nearly equal rotations whose Z-Y-X Euler angles differ wildly (pitch near 90°):
    # Euler interpolation would swing through a large rotation; slerp must not.
    a = euler_channels_to_quat(np.array([41.7, 89.0, 0.0]), (2, 1, 0))
    Rb = quat_to_matrix(a) @ quat_to_matrix(euler_channels_to_quat(np.array([0.0, 0.0, 2.0]), (2, 1, 0)))
    b = -quat_from_matrix(Rb)  # opposite hemisphere on purpose
    m = quat_slerp(a, b, 0.5)
    ang = lambda p, q: 2 * math.degrees(math.acos(min(1.0, abs(float(np.dot(p, q))))))
    assert ang(a, m) == pytest.approx(1.0, abs=1e-6) and ang(m, b) == pytest.approx(1.0, abs=1e-6)


def test_segments_are_rigid_over_the_clip():
    from scenegraph.mocap.bvh import bvh_forward_kinematics, bvh_local_pose

    b = read_bvh(C0701)
    q, t = bvh_local_pose(b)
    pos, _ = bvh_forward_kinematics([j.parent for j in b.joints], q, t)
    for i, j in enumerate(b.joints):
        if j.parent >= 0:
            L = np.linalg.norm(pos[:, i] - pos[:, j.parent], axis=1)
            assert np.ptp(L) < 1e-9 and L[0] == pytest.approx(np.linalg.norm(j.offset))


# --- import: variants, units, axes, floor, T-pose, resampling ---------------------------------

@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_import_units_axes_floor(name):
    frames, tpose, variant = SHIPPED[name]
    d = read_clip(CLIPS / name)
    assert d.rig == variant
    assert d.tpose_skipped == tpose
    assert d.frame_range == ((1 if tpose else 0), frames - 1)
    # walking direction: file +Z is our +X; the performer's left (file +X) is our +Y
    disp = d.target("sacrum")[-1] - d.target("sacrum")[0]
    assert disp[0] > MIN_TRAVEL.get(name, 2.0) and abs(disp[1]) < 0.3 * disp[0]
    assert np.median(d.target("hip_l")[:, 1] - d.target("hip_r")[:, 1]) > 0.1
    # the CMU head end site is mid-head: 1.35–1.6 m; the fitted stature 1.5–1.8 m
    assert 1.35 < np.median(d.joint("Head" + END_SUFFIX)[:, 2]) < 1.6
    assert 1.5 < d.performer_height < 1.8
    # floor: estimated per clip within a few cm of the file's y = 0, and now at z = 0
    assert abs(d.floor_height) < 0.04
    toes = np.concatenate([d.target("toe_l")[:, 2], d.target("toe_r")[:, 2]])
    assert abs(np.percentile(toes, 5)) < 0.01


def test_walk_speed_matches_the_delivery_notes():
    d = read_clip(C0701)
    x = d.target("sacrum")[:, 0]
    speed = (x[-1] - x[0]) / d.duration
    assert speed == pytest.approx(1.36, abs=0.06)


def test_tpose_frame_detected_and_skipped():
    kept = read_clip(C0701, skip_tpose=False, frames=(0, 8))
    skipped = read_clip(C0701, frames=(1, 9))
    assert not kept.tpose_skipped and kept.frame_range == (0, 7)
    # in the T-pose the wrists are at shoulder height; in captured motion they hang
    for d, arms_out in ((kept, True), (skipped, False)):
        lift = d.target("wrist_l")[0, 2] - d.target("shoulder_l")[0, 2]
        assert (abs(lift) < 0.1) == arms_out
    with pytest.raises(InputError, match="T-pose"):
        read_clip(C0701, frames=(0, 10))


def test_resampling_to_30fps():
    src = read_clip(C0701, fps=120.0)
    d = read_clip(C0701, fps=30.0)
    assert d.fps == 30.0 and src.n_frames == 316
    assert d.n_frames == 315 // 4 + 1
    assert np.allclose(np.diff(d.times), 1 / 30)
    # every 4th source frame is hit exactly (up to floating point)
    assert np.allclose(d.joints, src.joints[::4], atol=1e-9)
    # between source frames, slerped joints stay on their rigid segments and between neighbours
    odd = read_clip(C0701, fps=45.0, frames=(1, 40))
    ref = read_clip(C0701, fps=120.0, frames=(1, 40))
    k = 1  # t = 1/45 s lies between source frames 2 and 3 (times 2/120, 3/120)
    p = odd.target("toe_l")[k]
    a, b = ref.target("toe_l")[2], ref.target("toe_l")[3]
    assert np.linalg.norm(p - a) + np.linalg.norm(p - b) < np.linalg.norm(a - b) + 2e-3


# --- retargeting and contacts -----------------------------------------------------------------

@pytest.fixture(scope="module")
def gait_cycle():
    """One gait cycle of 07_01 (left stance onsets at source frames 64 and 200) with margins."""
    return load_clip(C0701, frames=(40, 280))


def test_retarget_error_and_limits(gait_cycle):
    c = gait_cycle
    assert c.q.shape == (c.n_frames, N_DOF) and c.n_frames == (279 - 40) // 4 + 1
    assert c.solver["status"] == "Solve_Succeeded"
    assert c.mean_fit_error() < 0.03  # m, mean over points and frames
    per_point = dict(zip(c.data.target_names, c.fit_error.mean(axis=0)))
    for leg in ("knee_l", "knee_r", "ankle_l", "ankle_r", "ball_l", "ball_r", "toe_l", "toe_r"):
        assert per_point[leg] < 0.02, (leg, per_point[leg])
    lo, hi = c.character.lower, c.character.upper
    assert np.all(c.q >= lo - 1e-6) and np.all(c.q <= hi + 1e-6)
    assert c.character.height == pytest.approx(c.performer_height)
    # the walk goes forward: heading near 0 and knees bend in swing
    assert np.all(np.abs(c.q[:, 3]) < math.radians(20))
    knee = c.q[:, c.character.dof_index("knee_flex_l")]
    assert math.radians(50) < knee.max() < math.radians(80)


def test_footsteps_of_one_gait_cycle(gait_cycle):
    steps = detect_footsteps(gait_cycle)
    last = gait_cycle.n_frames - 1
    full = [s for s in steps if s.first_frame > 0 and s.last_frame < last]  # not cut by the window
    sides = [s.side for s in full]
    assert sides == ["l", "r", "l"], [(s.side, s.start, s.end) for s in steps]
    x = [s.position[0] for s in full]
    step_lengths = np.diff(x)
    assert np.all((0.55 < step_lengths) & (step_lengths < 0.9)), step_lengths
    assert 1.2 < x[2] - x[0] < 1.7  # stride
    # onsets near the delivery notes' stance onsets (source frames 64, 130, 200) at 30 fps
    onsets = [gait_cycle.frame_range[0] + s.start * 120 for s in full]
    assert np.allclose(onsets, [64, 130, 200], atol=10), onsets
    for s in full:
        assert abs(s.position[2]) < 0.04
        assert abs(s.heading) < math.radians(20)
        assert {c.handle for c in s.contacts} == {"heel", "ball", "toe"}
        assert s.contacts[0].handle == "heel"  # heel strike first


# --- malformed input ----------------------------------------------------------------------------

BAD_CASES = {
    "truncated_motion.bvh": (192, "truncated motion"),
    "wrong_channel_count.bvh": (190, "has 95 values"),
    "channels_declared_wrong.bvh": (17, "declares 3 channels but lists 2"),
    "channels_listed_extra.bvh": (17, "more channel names"),
    "too_many_channels.bvh": (5, "must be 0..6"),
    "unknown_joint.bvh": (14, "unknown joint 'LeftShin'"),
    "non_numeric.bvh": (191, "'abc' is not a number"),
    "non_finite.bvh": (189, "finite"),
    "bad_offset.bvh": (86, "expected a number"),
    "extra_frames.bvh": (193, "more motion lines"),
    "unbalanced_braces.bvh": (184, "found 'MOTION'"),
    "bad_frame_time.bvh": (187, "frame time"),
}


def test_bad_corpus_is_complete():
    assert sorted(p.name for p in BAD.glob("*.bvh")) == sorted(BAD_CASES)


@pytest.mark.parametrize("name", sorted(BAD_CASES))
def test_bad_bvh_fails_with_line(name, tmp_path):
    line, fragment = BAD_CASES[name]
    f = tmp_path / name
    shutil.copy(BAD / name, f)
    before = sorted(tmp_path.iterdir())
    with pytest.raises(InputError) as ei:
        load_clip(f)
    err = ei.value
    assert err.location.file == str(f) and err.location.line == line, str(err)
    assert fragment in str(err)
    assert str(err).startswith(f"{f}:{line}")
    assert err.exit_code == 2
    assert sorted(tmp_path.iterdir()) == before  # nothing written


def test_parse_errors_without_a_file():
    with pytest.raises(InputError, match="HIERARCHY"):
        parse_bvh("", "x.bvh")
    with pytest.raises(InputError, match="not found"):
        read_bvh(BAD / "missing.bvh")


# --- rigs are data -------------------------------------------------------------------------------

def test_new_rig_by_data_only(tmp_path):
    """A skeleton with other joint names loads after writing a rig file, without code."""
    text = C0701.read_text()
    names = [j.name for j in read_bvh(C0701).joints if not j.end_site]
    for n in sorted(names, key=len, reverse=True):
        text = text.replace(f"JOINT {n}\n", f"JOINT rig:{n}\n")
    text = text.replace("ROOT Hips", "ROOT rig:Hips")
    clip = tmp_path / "renamed.bvh"
    clip.write_text(text)
    with pytest.raises(InputError, match="unknown joint"):
        read_clip(clip, frames=(1, 30))
    rig_text = (ROOT / "scenarios" / "rigs" / "cmu.yaml").read_text()
    import yaml

    rig = yaml.safe_load(rig_text)
    mb = rig["variants"]["motionbuilder"]
    rig["variants"] = {"prefixed": {f"rig:{k}": v for k, v in mb.items()}}
    rig["name"] = "prefixed"
    (tmp_path / "prefixed.yaml").write_text(yaml.safe_dump(rig))
    d = read_clip(clip, rig=tmp_path / "prefixed.yaml", frames=(1, 30))
    ref = read_clip(C0701, frames=(1, 30))
    assert d.rig == "prefixed/prefixed"
    for name in ref.target_names:
        assert np.allclose(d.target(name), ref.target(name))


def test_bad_rig_file_names_line(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text((ROOT / "scenarios" / "rigs" / "cmu.yaml").read_text().replace("LeftLeg: knee_l", "LeftLeg: kne_l"))
    with pytest.raises(InputError) as ei:
        load_rig(p)
    assert ei.value.location.file == str(p) and ei.value.location.line is not None
    assert "kne_l" in str(ei.value)


@pytest.mark.parametrize("name,frames", [("walk_neutral_cmu_08_02.bvh", None), ("run_cmu_09_11.bvh", None),
                                         ("walk_stylized_mj_cmu_131_01.bvh", (0, 360))])
def test_retarget_other_clips(name, frames):
    c = load_clip(CLIPS / name, frames=frames)
    assert c.solver["status"] == "Solve_Succeeded"
    assert c.mean_fit_error() < 0.03, c.mean_fit_error()
    assert np.all(c.q >= c.character.lower - 1e-6) and np.all(c.q <= c.character.upper + 1e-6)


# --- smooth reconstruction (Appendix A) -------------------------------------------------------

def test_reconstruct_one_gait_cycle():
    from scenegraph.model.body import G
    from scenegraph.mocap.clip import reconstruct_clip

    clip = load_clip(C0701, frames=(64, 201))
    rec = reconstruct_clip(clip)
    assert rec.solver["status"] in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    m = rec.motion
    assert m.start == pytest.approx(0.0) and m.end == pytest.approx(clip.times[-1])
    # the motion reproduces its own samples and stays within joint limits (control points)
    _, q = m.sample(clip.fps)
    assert np.allclose(q, rec.q, atol=1e-9)
    assert np.all(m.ctrl >= clip.character.lower - 1e-6) and np.all(m.ctrl <= clip.character.upper + 1e-6)
    # still close to the clip, with the root residual (units of body weight) nearly zero
    assert rec.fit_error.mean() < 0.035
    assert np.abs(rec.root_residual).max() < 0.01
    # the contact forces carry the body on average over a gait cycle, and push, never pull
    mg = clip.character.total_mass * G
    fz = np.zeros(clip.n_frames)
    for h, (times, forces) in rec.contact_forces.items():
        assert np.all(forces[:, 2] >= -1e-6)
        fz[np.searchsorted(clip.times, times - 1e-9)] += forces[:, 2]
    assert fz.mean() / mg == pytest.approx(1.0, abs=0.1)
    # second derivatives stay plausible (no spikes): joint accelerations RMS below 20 rad/s²
    _, _, qdd = m.at(clip.times)
    assert np.sqrt(np.mean(qdd[:, 6:] ** 2)) < 20.0


# the shared delivery folder sits next to the repository (<repo>/../shared/mocap), or where
# COMPOSE_SHARED_MOCAP points
SHARED_MOCAP = Path(os.environ.get("COMPOSE_SHARED_MOCAP") or Path(__file__).resolve().parents[3] / "shared" / "mocap")
SHARED_TURN = SHARED_MOCAP / "walk_turn_left_cmu_16_18.bvh"


@pytest.mark.skipif(not SHARED_TURN.exists(),
                    reason=f"the CMU 16_18 turn clip is not in the shared mocap folder ({SHARED_TURN}); "
                           "set COMPOSE_SHARED_MOCAP to the folder that holds walk_turn_left_cmu_16_18.bvh")
def test_turn_clip_root_near_gimbal_lock():
    """16_18's root Euler angles swing wildly after the 90° left turn (near gimbal lock);
    slerp resampling must still give a smooth path that ends heading +Y (our left)."""
    d = read_clip(SHARED_TURN)
    p = d.target("sacrum")
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    assert step.max() < 0.08  # m per 1/30 s: no jumps
    end_dir = p[-1] - p[-20]
    assert end_dir[1] > 0.4 and abs(end_dir[0]) < 0.25 * end_dir[1]
    start_dir = p[20] - p[0]
    assert start_dir[0] > 0.4 and abs(start_dir[1]) < 0.25 * start_dir[0]
