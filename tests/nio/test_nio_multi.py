"""Several clips of one person in one NIO (issue #18, item 2): Σ_c G_c(θ) + D(θ), per-clip
counterexamples, the bundle's cuts grouped by clip, and ``compose learn PATH:A:B …`` parsing."""
from __future__ import annotations

import numpy as np
import pytest

from scenarios.errors import InputError
from scenegraph.model.body import make_character
from scenegraph.model.footsteps import footsteps_for_walk
from scenegraph.model.gait import initial_motion
from scenegraph.model.style import default_style
from scenegraph.nio import NIO, MultiNIO, d_penalty
from scenegraph.nio.bundle import model_step, run_bundle
from scenegraph.nio.theta import theta_scales
from schedules.cli.learn import clip_specs, parse_clip_spec


@pytest.fixture(scope="module")
def walk():
    """Two NIO problems of the same kinematically pre-solved walk (identical clips), and a third
    of a different walk (another step length and duration)."""
    from scenegraph.problem.synthesis import presolve_kinematics
    ch = make_character("adult_male")
    d = default_style(ch.total_mass)
    out = []
    for n, length, dur in ((3, 0.7, 1.3), (3, 0.7, 1.3), (3, 0.6, 1.45)):
        fs = footsteps_for_walk(n_steps=n, step_length=length)
        m = presolve_kinematics(ch, d, initial_motion(ch, fs, 0.0, dur), fs).motion
        out.append(NIO(ch, m, fs, local=True))
    return out, d.vector()


def test_identical_clips_double_g_and_its_gradient(walk):
    """Two identical clips: G and the gradient of Σ G_c are twice the one clip's; D counts once."""
    (a, b, _), th = walk
    one = MultiNIO((a,)).evaluate(th)
    two = MultiNIO((a, b)).evaluate(th)
    D, gD = d_penalty(th)
    assert one.G > 0
    assert two.G == pytest.approx(2 * one.G, rel=1e-9)
    assert two.D == D and one.D == D
    assert np.allclose(two.grad - gD, 2 * (one.grad - gD), rtol=1e-9, atol=1e-12 * np.abs(one.grad).max())
    assert len(two.parts) == 2


def test_bundle_cuts_are_grouped_per_clip(walk):
    """The bundle's G at θ0 (re-read from every clip's own counterexamples) of two different clips
    is the sum of each clip's, not the larger one (what one max over all cuts would give)."""
    (a, _, c), th = walk
    ga = run_bundle(a, th, max_iter=0).g_initial
    gc = run_bundle(c, th, max_iter=0).g_initial
    both = run_bundle(MultiNIO((a, c)), th, max_iter=0).g_initial
    assert min(ga, gc) > 0
    assert both == pytest.approx(ga + gc, rel=1e-9)
    assert both > max(ga, gc) * 1.01


def test_model_step_sums_the_groups():
    """Cuts of two clips with no slope: the LP's model is L_a + L_b (per-clip max, summed);
    in one group it is max(L_a, L_b)."""
    th = default_style().vector()
    z = np.zeros_like(th)
    sc = theta_scales(default_style())
    cuts = [(1.0, z), (0.5, z), (2.0, z)]
    _, grouped = model_step(th, cuts, 0.1, sc, groups=[0, 0, 1])
    _, single = model_step(th, cuts, 0.1, sc)
    assert grouped == pytest.approx(3.0, rel=1e-9) and single == pytest.approx(2.0, rel=1e-9)


def test_clip_spec_parsing(tmp_path):
    f = tmp_path / "a.bvh"
    f.write_text("x")
    assert parse_clip_spec("a.bvh:64:201") == ("a.bvh", (64, 201))
    assert parse_clip_spec("dir/b.bvh") == ("dir/b.bvh", None)
    assert parse_clip_spec(f"{f}:3:10") == (str(f), (3, 10))
    for bad in ("a.bvh:64", "a.bvh:x:201", "a.bvh:201:64", ":1:5", "a.bvh:5:6"):
        with pytest.raises(InputError, match="PATH"):
            parse_clip_spec(bad)
    assert clip_specs(["a.bvh"], "1:60") == [("a.bvh", (1, 60))]
    assert clip_specs(["a.bvh:1:60", "b.bvh:5:90"], None) == [("a.bvh", (1, 60)), ("b.bvh", (5, 90))]
    for args, frames, msg in ((["a.bvh"], None, "no frames"), (["a.bvh:1:60"], "1:60", "has frames already"),
                              (["a.bvh:1:60", "b.bvh"], "1:60", "--frames is for one clip"),
                              (["a.bvh:1:60", "a.bvh:1:60"], None, "given twice"),
                              (["a.bvh:1:60", "b.bvh"], None, "no frames")):
        with pytest.raises(InputError, match=msg):
            clip_specs(args, frames)


def test_cli_learn_several_clips_bad_input(tmp_path, capsys):
    """``compose learn`` with several clips: a missing one and a malformed range are errors
    (exit 2) before any NIO runs, and nothing is written."""
    from pathlib import Path

    from schedules.cli.main import main
    clip = Path(__file__).resolve().parents[2] / "scenarios" / "clips" / "walk_neutral_cmu_07_01.bvh"
    out = tmp_path / "s.yaml"
    assert main(["learn", f"{clip}:64:201", "nope.bvh:1:60", "-o", str(out)]) == 2
    assert "nope.bvh" in capsys.readouterr().err
    assert main(["learn", f"{clip}:64:201", f"{clip}:130", "-o", str(out)]) == 2
    assert "PATH:A:B" in capsys.readouterr().err
    assert main(["learn", f"{clip}:64:201", f"{clip}:130:262", "--counterexamples", "ipopt", "-o", str(out)]) == 2
    assert not out.exists()


@pytest.mark.slow
def test_compose_learn_two_segments_end_to_end(tmp_path):
    """`compose learn A.bvh:64:201 A.bvh:130:262` (two strides of 07_01, 2 NIO iterations): a
    style whose provenance lists both segments, the first as its clip, and whose header repeats
    the command."""
    from pathlib import Path

    from schedules.cli.main import main
    from scenegraph.model.style import load_style
    clip = Path(__file__).resolve().parents[2] / "scenarios" / "clips" / "walk_neutral_cmu_07_01.bvh"
    out = tmp_path / "w.yaml"
    assert main(["learn", f"{clip}:64:201", f"{clip}:130:262", "--max-iter", "2", "-o", str(out)]) == 0
    st = load_style(out)
    prov = st.provenance.model_dump()
    assert prov["clip"] == clip.name and prov["frames"] == "64:201"
    assert [c["frames"] for c in prov["clips"]] == ["64:201", "130:262"]
    assert f"{clip.name}:64:201 {clip.name}:130:262" in out.read_text().splitlines()[0]
    assert prov["g_final"] <= prov["g_initial"]


def test_learned_header_names_every_clip(tmp_path):
    """``save_learned`` of a several-clip style: the header repeats ``compose learn PATH:A:B …``."""
    from types import SimpleNamespace

    from schedules.cli.learn import save_learned
    from scenegraph.model.style import Provenance, load_style
    st = default_style().model_copy(update={"provenance": Provenance(clip="a.bvh", frames="1:60")})
    out = tmp_path / "s.yaml"
    save_learned(SimpleNamespace(style=st), out, [("a.bvh", (1, 60)), ("b.bvh", (5, 90))], None, "adult_male")
    assert out.read_text().splitlines()[0] == ("# learned by: compose learn a.bvh:1:60 b.bvh:5:90 --body adult_male "
                                               "--alpha-prior 0 --spring-prior 0 --tie none --contacts central -o s.yaml")
    assert load_style(out).provenance.clip == "a.bvh"
    save_learned(SimpleNamespace(style=st), out, "a.bvh", (1, 60), "adult_male")
    assert out.read_text().splitlines()[0].startswith("# learned by: compose learn a.bvh --frames 1:60 --body")
