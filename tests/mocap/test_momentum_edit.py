"""Momentum-preserving edits of the CMU 16_05 broad jump (thesis ch. 4; ``compose edit``).

The edited jump meets its new constraints, keeps the clip's momentum curves (Pearson
correlation on a stage-normalised time axis), and its flight — measured from the written
USD stage by the stage auditor's mesh momenta, not by the model that made it — is a
parabola with g = 9.81 m/s² within 2 mm, where the naive displacement-map edit of the same
clip is not.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from scenegraph.export.clip_edit import edit_clip
from scenegraph.mocap.clip import load_clip
from scenegraph.mocap.momentum_edit import body_momenta, jump_stages, momentum_edit
from schedules.cli.main import main

CLIP = Path(__file__).resolve().parents[2] / "scenarios" / "clips" / "jump_broad_cmu_16_05.bvh"
FRAMES = (60, 250)


@pytest.fixture(scope="module")
def clip():
    return load_clip(CLIP, fps=120.0, frames=FRAMES)


def test_the_clip_stages_match_the_readme(clip):
    st = jump_stages(clip.character, clip.q)
    # README_jump.md: both feet airborne in file frames 139–186 (48 frames, 0.400 s)
    assert (st.a + FRAMES[0], st.b + FRAMES[0]) == (139, 187)
    com, P, H, _ = body_momenta(clip.character, clip.q, 120.0)
    tau = np.arange(st.b - st.a) / 120.0
    g = -2 * np.polyfit(tau, com[st.a:st.b, 2], 2)[0]
    assert 9.5 < g < 10.1  # the captured flight is ballistic (README: 9.80 for a segment model)


def test_a_longer_jump_keeps_its_momentum_and_a_parabolic_flight(clip, tmp_path):
    rep = edit_clip(CLIP, tmp_path / "longer.usda", frames=FRAMES, longer=0.3)
    m = rep["measured"]
    assert m["com_flight_distance"] - m["clip_com_flight_distance"] == pytest.approx(0.3, abs=0.01)
    assert m["com_apex_rise"] == pytest.approx(m["clip_com_apex_rise"], abs=0.01)
    assert m["momentum_corr"]["min"] >= 0.9, m["momentum_corr"]
    assert m["planted_foot_error_max"] < 0.05
    assert rep["flight"]["parabola_rms_mm"] <= 2.0 and abs(rep["flight"]["fitted_g"] - 9.81) < 0.1
    assert rep["naive"]["flight"]["parabola_rms_mm"] > 2.0  # the displacement map bends the flight
    # angular momentum about the centre of mass held in flight (the clip's own drifts 28 %, 2 kg·m²/s)
    assert rep["flight"]["ang_mom_drift_abs"] <= 0.5 < rep["naive"]["flight"]["ang_mom_drift_abs"]
    assert Path(rep["bvh"]).read_text().startswith("HIERARCHY")


@pytest.mark.slow
def test_a_higher_and_a_turned_jump(clip, tmp_path):
    rep = edit_clip(CLIP, tmp_path / "higher.usdc", frames=FRAMES, higher=0.2)
    m = rep["measured"]
    assert m["com_apex_rise"] - m["clip_com_apex_rise"] == pytest.approx(0.2, abs=0.015)
    assert m["flight_s"] > m["clip_flight_s"] + 0.1  # a higher jump flies longer
    assert m["momentum_corr"]["P_forward"] >= 0.9 and m["momentum_corr"]["P_z"] >= 0.9
    assert rep["flight"]["parabola_rms_mm"] <= 2.0
    assert rep["naive"]["flight"]["parabola_rms_mm"] > 2.0
    r = momentum_edit(clip.character, clip.q, 120.0, turn=math.radians(45))
    assert r.measured["turn_deg"] == pytest.approx(45.0, abs=0.5)
    assert r.measured["momentum_corr"]["min"] >= 0.9


@pytest.mark.slow
def test_compose_edit_prints_its_line_and_writes_its_files(tmp_path, capsys):
    out = tmp_path / "e.usda"
    assert main(["edit", str(CLIP), "--frames", "60:250", "--longer", "0.3", "-o", str(out)]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("edit: longer=0.3 higher=0 turn_deg=0 momentum_corr=")
    assert out.exists() and out.with_suffix(".bvh").exists()
    assert json.loads(out.with_suffix(".edit.json").read_text())["asked"]["longer"] == 0.3
    assert main(["edit", str(CLIP), "--frames", "60:250", "--higher", "5", "-o", str(out)]) == 2
