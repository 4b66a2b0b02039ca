"""Measures on a character's current motion (world frame, z up, m, s): handle tracks, body
frames, the torso surface, what a tackle or an avoid achieved, and how far a soft target may
pull in one solve.  Pure numpy over :class:`~scenegraph.world.scene.CharacterState`-like objects
(``.character``, ``.motion``); the goal records (:mod:`scenegraph.world.goals`) and the run report
use them.
"""
from __future__ import annotations

import functools

import numpy as np

from scenegraph.model.body import Character
from scenegraph.model.kinematics import handle_positions_fn, numeric_fk

__all__ = ["handle_track", "body_frames", "chest_front", "torso_distance", "tackle_measure", "avoid_measure",
           "reach_budget", "clamp", "horizontal_unit", "ray_to_surface", "TORSO_BODIES", "REACH_ACCEL"]

REACH_ACCEL = 1.0          # m/s²: a tackle/avoid target asks for at most ½ a τ² of displacement, τ the
#                            time from the start of the optimised window to the goal (reaction time)
TORSO_BODIES = ("thorax", "abdomen")
CharacterState = object  # duck type: anything with .character and .motion (scene.CharacterState)


@functools.lru_cache(maxsize=64)
def _hfn(ch: Character, names: tuple[str, ...]):
    return handle_positions_fn(ch, names)


def handle_track(state: CharacterState, handle: str, times) -> np.ndarray:
    """World positions (len(times), 3) of a handle along the character's current motion."""
    fn = _hfn(state.character, (handle,))
    q, _, _ = state.motion.at(np.clip(np.asarray(times, float), state.motion.start, state.motion.end))
    q = np.atleast_2d(q)
    return np.array([np.asarray(fn(qi)).ravel() for qi in q])


def _body_index(ch: Character, name: str) -> int:
    return [b.name for b in ch.bodies].index(name)


def body_frames(state: CharacterState, body: str, times) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (n, 3, 3) and ellipsoid centres (n, 3) of one body along the motion."""
    ch = state.character
    q, _, _ = state.motion.at(np.clip(np.asarray(times, float), state.motion.start, state.motion.end))
    R, p = numeric_fk(ch, np.atleast_2d(q))
    i = _body_index(ch, body)
    b = ch.bodies[i]
    return R[:, i], p[:, i] + np.einsum("nij,j->ni", R[:, i], np.asarray(b.center))


def chest_front(state: CharacterState, times) -> np.ndarray:
    """(n, 3) the front of the thorax ellipsoid (its +x semi-axis end): a tackler's contact point."""
    R, c = body_frames(state, "thorax", times)
    a = state.character.body("thorax").semi_axes[0]
    return c + a * R[:, :, 0]


def ray_to_surface(R: np.ndarray, c: np.ndarray, semi, direction: np.ndarray) -> np.ndarray:
    """Where the ray from an ellipsoid's centre along ``direction`` (world) leaves it."""
    d = R.T @ direction
    return c + direction / max(float(np.linalg.norm(d / np.asarray(semi))), 1e-9)


def torso_distance(state: CharacterState, point, t: float) -> float:
    """Signed distance (m, < 0 inside) of a world point from the torso (thorax ∪ abdomen
    ellipsoids) at time t, measured along the ray from each ellipsoid's centre (exact on the
    surface, an upper bound of the Euclidean distance off it)."""
    point = np.asarray(point, float)
    best = np.inf
    for body in TORSO_BODIES:
        R, c = body_frames(state, body, [t])
        x = R[0].T @ (point - c[0])
        n = float(np.linalg.norm(x))
        k = float(np.linalg.norm(x / np.asarray(state.character.body(body).semi_axes)))
        best = min(best, n * (1.0 - 1.0 / k) if k > 1e-12 else -float(min(state.character.body(body).semi_axes)))
    return best


def horizontal_unit(v, fallback=(1.0, 0.0)) -> np.ndarray:
    v = np.asarray(v, float)[:2]
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-9 else np.asarray(fallback, float)


def tackle_measure(attacker: CharacterState, target: CharacterState, t: float, h: float = 0.01) -> dict:
    """What a tackle achieved at time t: the attacker's contact point (front of the chest)
    against the target's torso surface, and the closing speed — the contact point's velocity
    relative to the target's thorax centre along the horizontal line between them (backward
    difference over ``h``; the impact is usually the last instant of the scenario)."""
    ta = [t - h, t]
    front = chest_front(attacker, ta)
    _, c_t = body_frames(target, "thorax", ta)
    _, c_a = body_frames(attacker, "thorax", ta)
    u = horizontal_unit(c_t[1] - c_a[1])
    rel_v = ((front[1] - front[0]) - (c_t[1] - c_t[0])) / h
    palms = handle_track(attacker, "palm_l", [t])[0], handle_track(attacker, "palm_r", [t])[0]
    return {"contact_distance": float(torso_distance(target, front[1], t)),
            "closing_speed": float(np.dot(rel_v[:2], u)),
            "contact_point": front[1].tolist(),
            "chest_to_chest": float(np.linalg.norm(c_t[1] - c_a[1])),
            "palm_distances": [float(torso_distance(target, p, t)) for p in palms]}


def avoid_measure(me: CharacterState, other: CharacterState, t: float) -> float:
    """Clearance of an avoid goal: the smaller distance of my pelvis and chest from the
    other's chest at time t (the sphere's centre)."""
    o = handle_track(other, "chest", [t])[0]
    return min(float(np.linalg.norm(handle_track(me, hd, [t])[0] - o)) for hd in ("pelvis", "chest"))


def reach_budget(g, me: CharacterState, window: tuple[float, float] | None) -> float:
    """How far (m) a soft tackle/avoid target may ask a handle to move in one solve: ½ REACH_ACCEL τ²,
    τ = the goal time minus the start of the optimised window (the reaction time left).  Later
    cycles of the decreasing horizon have less time to react; asking for more than a body can
    do in that time would only buy large, implausible forces (and stall the solver)."""
    t0 = me.motion.start if window is None else window[0]
    tau = max(float(g.time) - float(t0), 0.0)
    return 0.5 * REACH_ACCEL * tau * tau


def clamp(current: np.ndarray, wanted: np.ndarray, budget: float) -> np.ndarray:
    d = wanted - current
    n = float(np.linalg.norm(d))
    return wanted if n <= budget else current + d * (budget / n)
