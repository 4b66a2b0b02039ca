"""Previews, report plots and the preview / export-bvh commands (fast: tiny motions)."""
from __future__ import annotations

import os

import numpy as np
import pytest

pytest.importorskip("matplotlib")
pytest.importorskip("pxr")

from scenarios.errors import InputError  # noqa: E402
from scenegraph.export import preview  # noqa: E402
from scenegraph.model.body import make_character, standing_pose  # noqa: E402
from scenegraph.export.bvh import export_bvh  # noqa: E402
from scenegraph.export.usd import CharacterTrack, Marker, export_usd  # noqa: E402
from schedules.cli.main import main  # noqa: E402

FPS = 20.0


def _q(ch, T, x0=0.0, y0=0.0):
    t = np.arange(T) / FPS
    q = np.tile(standing_pose(ch), (T, 1))
    q[:, 0] = x0 + 1.0 * t
    q[:, 1] = y0
    q[:, 3] = 0.3 * t
    for side, s in (("l", 1), ("r", -1)):
        q[:, ch.dof_index(f"hip_flex_{side}")] = 0.4 * s * np.sin(2 * np.pi * t)
        q[:, ch.dof_index(f"knee_flex_{side}")] = 0.5 + 0.4 * np.sin(2 * np.pi * t)
        q[:, ch.dof_index(f"shoulder_flex_{side}")] = -0.3 * s * np.sin(2 * np.pi * t)
        q[:, ch.dof_index(f"elbow_flex_{side}")] = 0.6
        q[:, ch.dof_index(f"ankle_flex_{side}")] = 0.2 * np.sin(2 * np.pi * t + 1)
    return q


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    d = tmp_path_factory.mktemp("preview")
    a, b = make_character("adult_male"), make_character("child")
    tracks = [CharacterTrack("Ann", a, _q(a, 12)), CharacterTrack("Ben", b, _q(b, 10, 0.5, 1.0), start_time=1 / FPS)]
    markers = [Marker("fp0", "footprint", (0.1, 0.1, 0.0), (0.0, 0.2), character="Ann"),
               Marker("fp1", "footprint", (0.4, -0.1, 0.0), (0.2, 0.5), character="Ann"),
               Marker("goal", "goal", (1.2, 0.5, 1.0))]
    stage = export_usd(d / "run.usdc", tracks, FPS, markers=markers)
    return d, tracks, markers, stage


def test_stage_scene_matches_tracks(setup):
    d, tracks, markers, stage = setup
    s_stage = preview.scene_from_stage(stage)
    s_tracks = preview.scene_from_tracks(tracks, FPS, markers)
    assert np.allclose(s_stage.times, s_tracks.times) and len(s_stage.times) == 12
    assert [c.name for c in s_stage.characters] == ["Ann", "Ben"]
    for cs, ct in zip(s_stage.characters, s_tracks.characters):
        assert np.abs(cs.world - ct.world).max() < 1e-6
        es = sorted((j, tuple(c), tuple(s)) for j, c, s in cs.ellipsoids)
        et = sorted((j, tuple(c), tuple(s)) for j, c, s in ct.ellipsoids)
        assert len(es) == 18
        for (j1, c1, s1), (j2, c2, s2) in zip(es, et):
            assert j1 == j2 and np.allclose(c1, c2, atol=1e-5) and np.allclose(s1, s2, atol=1e-5)
    kinds = sorted((m.name, m.kind) for m in s_stage.markers)
    assert kinds == [("fp0", "footprint"), ("fp1", "footprint"), ("goal", "goal")]
    fp1 = [m for m in s_stage.markers if m.name == "fp1"][0]
    assert np.allclose(fp1.position, (0.4, -0.1, 0.0), atol=1e-9) and fp1.interval == pytest.approx((0.2, 0.5))


def test_ellipse_projection():
    cam = preview.ViewCamera(-90.0, 0.0)  # from -Y: screen x = world x, screen y = world z
    P = cam.basis()[:2]
    assert np.allclose(P, [[1, 0, 0], [0, 0, 1]], atol=1e-12)
    w, h, ang = preview._ellipse_2d(P, np.diag([0.1, 0.3, 0.5]))
    assert sorted([w, h]) == pytest.approx([0.2, 1.0]) and abs(abs(ang) - 90) < 1e-6 or abs(ang) < 1e-6
    top = preview.parse_camera("top").basis()
    assert np.allclose(top[2], [0, 0, 1], atol=1e-12)
    assert preview.parse_camera("-55,20") == preview.ViewCamera(-55.0, 20.0)
    with pytest.raises(InputError):
        preview.parse_camera("sideways")
    with pytest.raises(InputError):
        preview.parse_camera("0,120")


def _png_ok(path, min_colors=20):
    from matplotlib.image import imread
    img = imread(str(path))
    assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 200
    px = (img[..., :3] * 255).astype(np.int64).reshape(-1, 3)
    assert np.unique(px[:, 0] << 16 | px[:, 1] << 8 | px[:, 2]).size >= min_colors
    return img


def test_strip_draws_the_characters(setup, tmp_path):
    d, tracks, markers, stage = setup
    scene = preview.scene_from_stage(stage)
    out = preview.render_strip(scene, tmp_path / "strip.png", frames=3, camera="three-quarter")
    img = _png_ok(out)
    rgb = img[..., :3]
    reddish = (rgb[..., 0] > 0.6) & (rgb[..., 1] < 0.45) & (rgb[..., 2] < 0.4)  # Ann's colour
    bluish = (rgb[..., 2] > 0.6) & (rgb[..., 0] < 0.4)  # Ben's colour
    assert reddish.sum() > 200 and bluish.sum() > 200
    assert os.listdir(tmp_path) == ["strip.png"]


def test_movie_falls_back_to_strip_without_ffmpeg(setup, tmp_path, monkeypatch):
    d, tracks, markers, stage = setup
    scene = preview.scene_from_stage(stage)
    monkeypatch.setattr(preview, "have_ffmpeg", lambda: False)
    out = preview.render_preview(scene, tmp_path / "movie.mp4", frames=2)
    assert out.name == "movie.png" and out.exists()
    with pytest.raises(InputError):
        preview.render_preview(scene, tmp_path / "x.tiff")


def test_gif_movie(setup, tmp_path):
    d, tracks, markers, stage = setup
    scene = preview.scene_from_stage(stage, codes=[0, 4, 8])
    out = preview.render_movie(scene, tmp_path / "m.gif", camera="side")
    from PIL import Image
    with Image.open(out) as im:
        assert im.n_frames == 3


@pytest.mark.skipif(not preview.have_ffmpeg(), reason="ffmpeg is not installed")
def test_mp4_movie(setup, tmp_path):
    d, tracks, markers, stage = setup
    scene = preview.scene_from_stage(stage, codes=[0, 4, 8])
    out = preview.render_preview(scene, tmp_path / "m.mp4")
    assert out.suffix == ".mp4" and out.stat().st_size > 1000


def test_report_plots(tmp_path):
    names = make_character().dof_names[6:]
    t = np.linspace(0, 1, 21)
    tau = np.sin(np.outer(t, np.arange(1, len(names) + 1)))
    out = preview.write_report_plots(
        tmp_path / "report", energy={"cycle A": [100.0, 30.0, 2.0], "cycle B": [90.0, 20.0, 0.5]},
        torques={"Ann Lee": (t, tau, names)},
        footprints=[{"position": (0.0, 0.1), "character": "Ann Lee", "interval": (0.0, 0.3)},
                    Marker("fp", "footprint", (0.5, -0.1, 0.0), character="Ben")],
        trajectories={"Ann Lee": np.c_[t, 0.1 * t]})
    assert set(out) == {"energy", "torques:Ann Lee", "footprints"}
    assert out["torques:Ann Lee"].name == "torques_Ann_Lee.png"
    for p in out.values():
        _png_ok(p, min_colors=5)
    with pytest.raises(InputError):
        preview.plot_joint_torques(t, tau[:, :3], names, tmp_path / "bad.png")
    preview.plot_energy_per_cycle([5.0, 4.0], tmp_path / "e.png")


def test_report_plots_named_after_the_report_and_umask_mode(tmp_path):
    """Two reports in one folder keep their own plots; files get the umask's mode (0644), not 0600."""
    import stat
    old = os.umask(0o022)
    try:
        a = preview.write_report_plots(tmp_path, energy=[3.0, 2.0], prefix="run_a")
        b = preview.write_report_plots(tmp_path, energy=[5.0, 1.0],
                                       footprints=[{"position": (0.0, 0.1), "character": "x"}], prefix="run_b")
    finally:
        os.umask(old)
    assert a["energy"].name == "run_a.energy_per_cycle.png" and b["energy"].name == "run_b.energy_per_cycle.png"
    assert b["footprints"].name == "run_b.footprints.png"
    assert a["energy"].exists() and a["energy"].read_bytes() != b["energy"].read_bytes()
    for p in (*a.values(), *b.values()):
        assert stat.S_IMODE(p.stat().st_mode) == 0o644, p
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporaries left


def test_cli_preview_and_run_directory(setup, tmp_path, capsys):
    d, tracks, markers, stage = setup
    out = tmp_path / "p.png"
    assert main(["preview", str(stage), "-o", str(out), "--frames", "2", "--camera=-30,25"]) == 0
    _png_ok(out)
    assert main(["preview", str(d), "-o", str(tmp_path / "q.png"), "--frames", "1"]) == 0  # run directory
    assert main(["preview", str(tmp_path / "missing.usda")]) == 2
    assert "no such stage" in capsys.readouterr().err


def _numbers(text):
    head, motion = text.split("MOTION")
    return head, np.array([float(x) for x in motion.split("Frame Time:")[1].split()[1:]])


def test_cli_export_bvh_matches_direct_export(setup, tmp_path):
    d, tracks, markers, stage = setup
    out = tmp_path / "s.bvh"
    assert main(["export-bvh", str(stage), "-o", str(out), "--character", "Ann"]) == 0
    direct = export_bvh(tmp_path / "direct.bvh", tracks[0], FPS)
    h1, m1 = _numbers(out.read_text())
    h2, m2 = _numbers(direct.read_text())
    assert h1.split() [:3] == h2.split()[:3]
    t1, t2 = h1.split(), h2.split()
    assert len(t1) == len(t2)
    for a, b in zip(t1, t2):  # same hierarchy; offsets equal to float32 precision (cm)
        try:
            assert abs(float(a) - float(b)) < 1e-3
        except ValueError:
            assert a == b
    assert m1.shape == m2.shape and np.abs(m1 - m2).max() < 1e-3  # cm and degrees
    assert main(["export-bvh", str(stage), "-o", str(tmp_path / "all.bvh"), "--fps", "10"]) == 0
    assert sorted(p.name for p in tmp_path.glob("all_*.bvh")) == ["all_Ann.bvh", "all_Ben.bvh"]
    assert "Frames: 6" in (tmp_path / "all_Ann.bvh").read_text()  # 0.55 s at 10 fps
    assert main(["export-bvh", str(stage), "--character", "Nobody"]) == 2
