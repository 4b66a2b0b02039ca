"""Stages detected from a rough sketch (thesis §3.4; issue 20 item 2): where a ``keyframes``
goal's keys say the character is in the air, a ``jump`` goal is added for that flight, so a
sketch without stated stages gets the same ground/flight machinery as stated leaps (footsteps
on the ground, ballistic momentum rows in flight, the warp held at the keys' times).

A flight is detected between two consecutive keys of the pelvis (keys with a ``position``,
in time order) when either

* **out of reach of the legs**: their horizontal distance d exceeds what ground-bound
  locomotion covers in the time between them, d > V_REACH · √(g · LEG · H) · Δt with H the
  character's stature, LEG = 0.530 (hip height / stature, Winter 2009 — the model's leg:
  thigh 0.245 + shank 0.246 + ankle 0.039) and FROUDE_RUN = 0.5: at Froude number
  v²/(g·L) ≈ 0.5 humans change from walking to running (Alexander 1989, Physiol. Rev. 69;
  Kram et al. 1997, J. Exp. Biol. 200), and a run has flight; for a 1.75 m adult that is
  2.13 m/s; or
* **free fall**: the pelvis's sketched vertical acceleration at a key (the second divided
  difference of its height over the key and its two neighbours) is ≤ −FREE_FALL · g with
  FREE_FALL = 0.5: no push of the legs makes the pelvis fall faster than half of g while
  on the ground for long (a walk's bob is ~0.05 g, a countermovement dip ~0.3 g), so
  the key is in the air; the flight then runs from the key before it to the key after it.

Consecutive detected intervals sharing a key merge into one flight.  Each flight becomes a
``jump`` goal (named ``<sketch>_flight_<i>``) taking off at the first key's time from where
the character stands (its start or the previous landing: a take-off pelvis leans ahead of the
feet, so its key does not say where they are), landing at the last key's time under that
key's pelvis (x, y), with the heading change between the keys as its turn when both give one.  Its fields are located at the keys that implied
them, so an impossible detected leap (e.g. under 0.3 s on the ground before it) is an error
at the sketch's keys.  Not detected: a character whose goals already state its contacts
(a ``jump``, ``hop`` or ``footprints`` goal), and a sketch with ``stages: none``.

This works on the parsed YAML data before validation (like :mod:`scenarios.repeat`), and
leaves anything malformed to the validation that follows.  Units: m, s, deg.
"""
from __future__ import annotations

import math
from typing import Any

__all__ = ["detect_flights", "add_sketch_stages", "LEG", "FROUDE_RUN", "FREE_FALL", "G", "reach_speed"]

G = 9.81  # m/s²
LEG = 0.530  # leg length (hip height) / stature, Winter 2009 (scenegraph.model.body: 0.245 + 0.246 + 0.039)
FROUDE_RUN = 0.5  # walk–run transition Froude number v²/(g L) (Alexander 1989; Kram et al. 1997)
FREE_FALL = 0.5  # a key whose sketched vertical acceleration is ≤ −0.5 g is in the air
PRESET_HEIGHTS = {"adult_male": 1.75, "adult_female": 1.65, "child": 1.20}  # m (as scenarios.schema)


def reach_speed(stature: float) -> float:
    """The fastest ground-bound (flight-free) pelvis speed (m/s) of a character ``stature`` m tall."""
    return math.sqrt(FROUDE_RUN * G * LEG * stature)


def _num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def detect_flights(keys: list[tuple[float, tuple[float, float, float], float | None, int]],
                   stature: float) -> list[dict]:
    """Flights of one sketch: ``keys`` = [(time s, pelvis (x, y, z) m, heading deg or None,
    index in the file)] with positions, any order.  Returns [{"keys": (i0, i1) file indices,
    "t": (t0, t1), "why": [...], "takeoff": pelvis (x, y) at the first key, "landing": (x, y),
    "turn_deg": float}]."""
    ks = sorted(keys, key=lambda k: k[0])
    v_max = reach_speed(stature)
    marks: list[tuple[int, int, str]] = []  # (a, b) positions in ks, reason
    for a in range(len(ks) - 1):
        (t0, p0, _, _), (t1, p1, _, _) = ks[a], ks[a + 1]
        dt = t1 - t0
        d = math.hypot(p1[0] - p0[0], p1[1] - p0[1])
        if dt > 1e-9 and d > v_max * dt:
            marks.append((a, a + 1, f"reach: {d:.3g} m in {dt:.3g} s, above the {v_max:.3g} m/s legs cover "
                                    f"without flight (Froude {FROUDE_RUN:g})"))
    for k in range(1, len(ks) - 1):
        (ta, pa, _, _), (tb, pb, _, _), (tc, pc, _, _) = ks[k - 1], ks[k], ks[k + 1]
        if tb - ta < 1e-9 or tc - tb < 1e-9:
            continue
        acc = 2.0 * ((pc[2] - pb[2]) / (tc - tb) - (pb[2] - pa[2]) / (tb - ta)) / (tc - ta)
        if acc <= -FREE_FALL * G:
            marks.append((k - 1, k + 1, f"free fall: vertical acceleration {acc:.3g} m/s² at {tb:g} s "
                                        f"(≤ −{FREE_FALL:g} g)"))
    marks.sort()
    merged: list[list] = []
    for a, b, why in marks:
        if merged and a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
            merged[-1][2].append(why)
        else:
            merged.append([a, b, [why]])
    out = []
    for a, b, why in merged:
        (t0, p0, h0, i0), (t1, p1, h1, i1) = ks[a], ks[b]
        out.append({"keys": (i0, i1), "t": (t0, t1), "why": why, "takeoff": (p0[0], p0[1]),
                    "landing": (p1[0], p1[1]), "turn_deg": (h1 - h0) if h0 is not None and h1 is not None else 0.0})
    return out


def _stature(c: dict) -> float | None:
    body = c.get("body") if isinstance(c.get("body"), dict) else {}
    h = body.get("height")
    if _num(h):
        return float(h)
    return PRESET_HEIGHTS.get(body.get("preset", "adult_male"))


def add_sketch_stages(data: Any, positions: dict) -> tuple[Any, dict, list[dict]]:
    """``data`` with a ``jump`` goal appended for every flight detected in a sketch (module
    docstring), ``positions`` extended to locate them at their keys, and the detected stages
    [{"goal", "sketch", "character", "keys", "t", "why", ...}] for the run report."""
    if not isinstance(data, dict) or not isinstance(data.get("goals"), list) \
            or not isinstance(data.get("characters"), list):
        return data, positions, []
    goals = data["goals"]
    chars = {c.get("name"): c for c in data["characters"] if isinstance(c, dict)}
    stated = {g.get("character") for g in goals if isinstance(g, dict)
              and g.get("type") in ("jump", "hop", "footprints")}
    names = {g.get("name") for g in goals if isinstance(g, dict)}
    added, stages = [], []
    for j, g in enumerate(goals):
        if not (isinstance(g, dict) and g.get("type") == "keyframes" and isinstance(g.get("keys"), list)):
            continue
        who = g.get("character")
        if who in stated or who not in chars or g.get("stages", "detect") != "detect":
            continue
        H = _stature(chars[who])
        keys = []
        for i, k in enumerate(g["keys"]):
            if not isinstance(k, dict):
                continue
            t, p, h = k.get("time"), k.get("position"), k.get("heading")
            if _num(t) and isinstance(p, list) and len(p) == 3 and all(_num(x) for x in p):
                keys.append((float(t), tuple(float(x) for x in p), float(h) if _num(h) else None, i))
        if H is None or len(keys) < 2:
            continue
        sketch = g.get("name") or f"keyframes_{j}"
        for n, f in enumerate(detect_flights(keys, H)):
            name = f"{sketch}_flight_{n}"
            while name in names:
                name += "_"
            names.add(name)
            i0, i1 = f["keys"]
            added.append(((j, i0, i1), {
                "type": "jump", "name": name, "character": who,
                "takeoff": {"time": f["t"][0]},
                "landing": {"position": [f["landing"][0], f["landing"][1]], "time": f["t"][1]},
                "turn_deg": f["turn_deg"]}))
            stages.append({"goal": name, "sketch": sketch, "character": who, "keys": [i0, i1],
                           "t": list(f["t"]), "why": f["why"], "pelvis_at_takeoff": list(f["takeoff"]),
                           "landing": list(f["landing"]), "turn_deg": f["turn_deg"]})
    if not added:
        return data, positions, []
    data = dict(data)
    data["goals"] = list(goals)
    positions = dict(positions)
    for (j, i0, i1), jump in added:
        n = len(data["goals"])
        data["goals"].append(jump)
        kp = ("goals", j, "keys")
        at0 = positions.get(kp + (i0,), positions.get(("goals", j)))
        at1 = positions.get(kp + (i1,), at0)
        if at0 is None:
            continue
        base = ("goals", n)
        for path, at in ((base, at0), (base + ("takeoff",), at0), (base + ("takeoff", "time"), at0), (base + ("landing",), at1),
                         (base + ("landing", "position"), at1), (base + ("landing", "time"), at1),
                         (base + ("turn_deg",), at1)):
            positions[path] = at
    return data, positions, stages
