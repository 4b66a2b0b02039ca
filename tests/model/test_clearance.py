"""Body spheres (issue #15, item 5): every drawn solid is inside its body's spheres, the
symbolic and numeric sphere centres agree, and the pair test finds close bodies and skips
asked-for contacts (fast: no solve)."""
from __future__ import annotations

import numpy as np

from scenegraph.model.body import drawn_shapes, make_character
from scenegraph.model.clearance import _samples, body_spheres, clearance_pairs, sphere_centers, sphere_centers_fn

CH = make_character()


def test_spheres_cover_every_drawn_solid():
    sp = body_spheres(CH)
    for b, shape in zip(CH.bodies, drawn_shapes(CH)):
        P = _samples(shape)
        mine = [s for s in sp if s.body == b.name]
        d = np.min([np.linalg.norm(P - np.asarray(s.point), axis=1) - s.radius for s in mine], axis=0)
        assert d.max() <= 1e-9, b.name
    q = np.zeros(35)
    q[2], q[3] = 1.0, 0.4
    assert np.allclose(np.asarray(sphere_centers_fn(CH)(q)).reshape(-1, 3), sphere_centers(CH, q[None])[0])


def test_clearance_pairs_find_close_bodies_and_skip_asked_for_contacts():
    qa = np.zeros((1, 35))
    qa[0, 2] = 1.0
    qb = qa.copy()
    qb[0, 1] = 0.3  # side by side, 30 cm apart: arms and pelvis within the margin
    cl = clearance_pairs(CH, qa, CH, qb, [0.0], other="b")
    sp = body_spheres(CH)
    assert cl and all(c.radius > 0 for c in cl)
    C = sphere_centers(CH, qa)[0]
    assert any(np.linalg.norm(C[c.sphere] - c.center) < c.radius for c in cl)  # some overlap now
    skip = frozenset((x.body, y.body) for x in sp for y in sp if "hand" in x.body or "hand" in y.body)
    cl2 = clearance_pairs(CH, qa, CH, qb, [0.0], skip=skip, other="b")
    assert len(cl2) < len(cl) and not any("hand" in sp[c.sphere].body or "hand" in c.other for c in cl2)
    far = qb.copy()
    far[0, 1] = 3.0
    assert clearance_pairs(CH, qa, CH, far, [0.0]) == ()
