"""Style θ: the default, YAML round trip, and bad files that must fail with file, line and field."""
from __future__ import annotations

import copy
import re

import numpy as np
import pytest
import yaml

from scenarios.errors import InputError
from scenegraph.model.body import JOINT_DOF_NAMES, N_JOINT
from scenegraph.model.style import PER_DOF_FIELDS, Style, default_style, load_style, save_style


def test_default_style_is_valid():
    s = default_style()
    v = s.vector()
    assert v.shape == (147,) == (5 * N_JOINT + 2,)
    assert np.sum(s.alpha) == pytest.approx(1.0, abs=1e-12)
    assert np.all(s.alpha >= 0) and np.all(s.ks1 > 0) and np.all(s.ks2 > 0) and np.all(s.kd > 0)
    assert s.k_shoe > 0 and 0 < s.h_rest <= 0.1
    assert np.allclose(Style.from_vector(v).vector(), v)
    # stiffer for a heavier body
    assert np.all(default_style(100.0).ks1 > s.ks1)


def test_yaml_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    alpha = rng.uniform(0.1, 1.0, N_JOINT)
    s = default_style().with_(name="bouncy", alpha=alpha / alpha.sum(), ks1=rng.uniform(1, 90, N_JOINT),
                              q_rest=rng.uniform(-1, 1, N_JOINT), k_shoe=12345.0, h_rest=0.007)
    path = tmp_path / "bouncy.style.yaml"
    save_style(s, path, header="# a test style\n")
    text = path.read_text()
    assert text.startswith("# a test style")
    assert "knee_flex_l" in text  # per-DOF fields are written by name
    back = load_style(path)
    assert back.name == "bouncy"
    assert np.allclose(back.vector(), s.vector(), rtol=0, atol=1e-8)
    # and again: a saved-and-loaded style is a fixed point
    save_style(back, tmp_path / "again.yaml")
    assert (tmp_path / "again.yaml").read_text() == path.read_text().split("\n", 1)[1]


def test_example_poses_round_trip_and_bad_example(tmp_path):
    """A learned style's example poses (phase codes and joint angles) survive save and load; a
    malformed example block fails with the file, its line and the field."""
    from scenegraph.model.style import ExamplePoses
    rng = np.random.default_rng(3)
    codes = rng.uniform(0, 2, (12, 2))
    joints = rng.uniform(-1, 1, (12, N_JOINT))
    s = default_style().with_(example=ExamplePoses.from_arrays(codes, joints))
    path = tmp_path / "ex.yaml"
    save_style(s, path)
    c2, j2 = load_style(path).example.arrays()
    assert np.allclose(c2, codes, atol=1e-4) and np.allclose(j2, joints, atol=1e-5)
    assert load_style(path).vector().shape == (5 * N_JOINT + 2,)  # not part of θ
    data = yaml.safe_load(path.read_text())
    data["example"]["joints"]["knee_flex_l"].pop()
    src = yaml.safe_dump(data, sort_keys=False, default_flow_style=False)
    path.write_text(src)
    with pytest.raises(InputError) as exc:
        load_style(path)
    msg = str(exc.value)
    assert "same length" in msg and exc.value.location.field.startswith("example"), msg
    assert f"{path}:{_value_line(src, 'example')}:" in msg, msg


def test_per_dof_fields_accept_a_list_in_dof_order(tmp_path):
    data = default_style().to_data()
    data["ks2"] = [float(x) for x in range(1, N_JOINT + 1)]
    path = tmp_path / "list.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    s = load_style(path)
    assert s.ks2[JOINT_DOF_NAMES.index("waist_lat")] == 2.0


def _set(field, dof, value):
    def edit(d):
        d[field][dof] = value
    return edit


def _rename(field, old, new):
    def edit(d):
        d[field] = {(new if k == old else k): v for k, v in d[field].items()}
    return edit


# (case id, edit of the default style's data, field the error must name, text the message must contain,
#  YAML key whose line the error must point at: (parent key, key) or None for the document start)
BAD = [
    ("negative stiffness", _set("ks1", "knee_flex_l", -5.0), "ks1", "knee_flex_l", ("ks1", None)),
    ("negative damping", _set("kd", "hip_abd_r", -0.1), "kd", ">= 0", ("kd", None)),
    ("wrong length list", lambda d: d.__setitem__("kd", [1.0] * (N_JOINT - 1)), "kd", "29", ("kd", None)),
    ("matrix instead of list", lambda d: d.__setitem__("ks2", [[1.0] * N_JOINT]), "ks2", "29", ("ks2", None)),
    ("unknown DOF name", _rename("alpha", "knee_flex_l", "knee_flx_l"), "alpha", "knee_flx_l", ("alpha", None)),
    ("missing DOF", lambda d: d["q_rest"].pop("toe_flex_r"), "q_rest", "toe_flex_r", ("q_rest", None)),
    ("missing field", lambda d: d.pop("k_shoe"), "k_shoe", "required", None),
    ("alpha sum too large", _set("alpha", "knee_flex_l", 1.0), "alpha", "sum to 1", ("alpha", None)),
    ("alpha sum too small", lambda d: d.__setitem__("alpha", {k: 0.01 for k in d["alpha"]}), "alpha", "sum to 1",
     ("alpha", None)),
    ("negative alpha", _set("alpha", "waist_flex", -0.01), "alpha", ">= 0", ("alpha", None)),
    ("non-number scalar", lambda d: d.__setitem__("k_shoe", "stiff"), "k_shoe", "number", ("k_shoe", None)),
    ("non-number per DOF", _set("ks2", "hip_abd_r", "stiff"), "ks2", "numbers", ("ks2", None)),
    ("not finite", _set("ks1", "elbow_flex_l", float("nan")), "ks1", "finite", ("ks1", None)),
    ("rest angle out of range", _set("q_rest", "knee_flex_l", 7.0), "q_rest", "pi", ("q_rest", None)),
    ("negative shoe stiffness", lambda d: d.__setitem__("k_shoe", -1.0), "k_shoe", "greater than", ("k_shoe", None)),
    ("shoe rest length too long", lambda d: d.__setitem__("h_rest", 0.5), "h_rest", "0.1", ("h_rest", None)),
    ("unknown field", lambda d: d.__setitem__("colour", "red"), "colour", "unknown field", ("colour", None)),
]


def _value_line(text: str, key: str) -> int:
    """1-based line where the YAML value of top-level ``key`` starts (block or flow)."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line.startswith(f"{key}:"):
            rest = line[len(key) + 1:].strip()
            return i + 1 if rest else i + 2
    raise AssertionError(f"{key} not in file")


@pytest.mark.parametrize("case,edit,field,text,where", BAD, ids=[b[0] for b in BAD])
def test_bad_style_files(tmp_path, case, edit, field, text, where):
    data = copy.deepcopy(default_style().to_data())
    edit(data)
    path = tmp_path / f"{case.replace(' ', '_')}.style.yaml"
    src = yaml.safe_dump(data, sort_keys=False, default_flow_style=False)
    path.write_text(src)
    with pytest.raises(InputError) as exc:
        load_style(path)
    err = exc.value
    msg = str(err)
    assert err.exit_code == 2
    assert msg.startswith(f"{path}:"), msg  # file:line:col first, for editors
    assert err.location.file == str(path)
    assert err.location.field == field, msg
    assert re.search(rf"\b{field}\b", msg) and text in msg, msg
    expected_line = 1 if where is None else _value_line(src, where[0])
    assert err.location.line == expected_line, msg
    assert f"{path}:{expected_line}:" in msg


@pytest.mark.parametrize("content,text", [
    ("", "exactly one YAML document"),
    ("alpha: [1, 2\n", "invalid YAML"),
    ("- 1\n- 2\n", "valid dictionary"),
    ("!!python/object:os.system {}\n", "not allowed"),
])
def test_malformed_style_files(tmp_path, content, text):
    path = tmp_path / "broken.yaml"
    path.write_text(content)
    with pytest.raises(InputError, match=re.escape(text)) as exc:
        load_style(path)
    assert str(path) in str(exc.value)


def test_missing_style_file(tmp_path):
    with pytest.raises(InputError, match="file not found") as exc:
        load_style(tmp_path / "nope.yaml")
    assert "nope.yaml" in str(exc.value)


def test_style_is_immutable():
    s = default_style()
    with pytest.raises(ValueError):
        s.alpha[0] = 1.0
    with pytest.raises(Exception):
        s.k_shoe = 3.0
    assert set(PER_DOF_FIELDS) <= set(Style.model_fields)


def test_learned_style_scales_its_springs_to_the_body_it_is_used_on():
    """A style learned on adult_male (73 kg) used on the child preset (23 kg): springs, damping and
    shoe scale by 23/73, as the default style's do; α, q̄ and h̄ carry over; same body: unchanged."""
    from scenegraph.model.body import make_character
    from scenegraph.world.scene import scale_style_to_body
    from scenegraph.model.style import Provenance

    learned = default_style(73.0).with_(name="w", q_rest=np.full(N_JOINT, 0.1),
                                        provenance=Provenance(clip="c.bvh", body="adult_male"))
    child = make_character("child")
    s = scale_style_to_body(learned, child)
    r = child.mass / 73.0
    assert r == pytest.approx(23.0 / 73.0)
    for f in ("ks1", "ks2", "kd"):
        assert np.allclose(getattr(s, f), r * getattr(learned, f))
    assert s.k_shoe == pytest.approx(r * learned.k_shoe)
    assert np.array_equal(s.alpha, learned.alpha) and np.array_equal(s.q_rest, learned.q_rest)
    assert s.h_rest == learned.h_rest and s.provenance == learned.provenance
    assert scale_style_to_body(learned, make_character("adult_male")) is learned
    assert scale_style_to_body(learned.with_(provenance=None), child).k_shoe == learned.k_shoe  # body unknown
