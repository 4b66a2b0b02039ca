"""Lowering: a Step over a Scene → the subproblems that solve it (one per character, or one
joint NLP for a hard coupling).  The only reader of a Step's free blocks and terms.

The contract (schedules/plan/step.py lists the vocabulary; tests/execution/test_contract.py checks both
sides): every free block and term the compiler writes is consumed here exactly as written,
and :func:`check_step` rejects a Step with anything this module does not handle.

* ``q``: the control points under the window (all of them for a whole-scene Step);
* ``timewarp``: the warp (the compiler frees it only over the whole scene);
* ``duration``: the end of the warp moves within ``Scene.duration_bounds`` (world s);
* ``footprints``: free footsteps inside the window move; the others are held;
* ``lambda``: contact coefficients (the transcription always frees them where a foot is planted);
* ``coupling_forces``: the hand force of a hard coupling (a joint solve, :mod:`scenegraph.problem.joint`);
* ``energy`` (1), ``dynamics`` (hard → full dynamics, relaxed → root residual relaxed),
  ``environment`` (ground, friction pyramid with the scenario's μ, no penetration, feet not
  crossing: always part of the transcription), ``start`` (a pelvis spring of exactly this
  weight at the start), ``boundary:start=hard`` / ``boundary:end=hard`` (held control points
  outside the window), ``boundary:end=free`` (a receding window: open end),
  ``goal:<name>`` (springs of exactly this weight, or hard targets), ``coupling:<name>``
  (a rubber band of this stiffness in N/m, or ``hard``: a joint solve).

Not a term but a fact of the scene: in a ``full`` Step of a scene with several characters,
the character's bodies are kept off the others' (:mod:`scenegraph.world.clearance`: body
spheres where the current motions come within 10 cm, as a one-sided least-squares term of
total weight ``CLEARANCE_WEIGHT``; between the two characters of a joint solve, hard rows),
except the contacts the scene asks for.

Times: a Step's window is in canonical seconds; the Subproblem's in world seconds of the
character's current motion.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from scenarios.errors import ComposeError
from scenegraph.model.clearance import CLEARANCE_WEIGHT
from scenegraph.model.footsteps import airborne_gaps
from scenegraph.problem.joint import JointCoupling, coupling_times
from scenegraph.model.body import N_DOF
from scenegraph.model.motion import Motion
from scenegraph.problem import HandleTarget, PoseTarget, Subproblem, VelocityTarget, window_mask
from scenegraph.problem.flight import momenta_fn
from scenegraph.problem.no_slip import NO_SLIP_WEIGHT
from scenegraph.problem.stance_frame import STANCE_FRAME_WEIGHT
from scenegraph.world.clearance import scene_clearance
from scenegraph.world.scene import CharacterState, Scene, coupling_springs, coupling_targets, goal_targets, handle_track
from scenegraph.model.style import Style

from schedules.plan.step import FREE, FULL, HARD, RELAXED, ROLES, STEP_KINDS, Step, vocabulary

__all__ = ["lower", "lower_joint", "check_step", "HANDLED", "Lowered", "STALL_ITERATIONS", "SOFT_PIN_HZ",
           "COUPLING_TARGET_HZ", "JOINT_COUPLING_HZ", "iteration_cap", "COUPLED_FULL_MAX_ITER", "gait_flights",
           "leap_flights_of"]

STALL_ITERATIONS = 25  # a full step whose objective is flat this long, constraints held, is done
SOFT_PIN_HZ = 120.0  # soft footprint springs of full steps: planted feet still between collocation points
COUPLING_TARGET_HZ = 60.0  # rubber-band target points per second (at 10 Hz the hands met at the
# target points and parted by up to 9 cm between them)
JOINT_COUPLING_HZ = 30.0  # hard hand-hold: coupling times (and force variables) per second
COUPLED_FULL_MAX_ITER = 100  # a coupled character's full step: one move of the alternation (thesis §6.4.3)

# What this module consumes (tests/execution/test_contract.py: must cover step.declared_vocabulary())
HANDLED = ({("kind", k) for k in (FULL, "timing")} | {("role", r) for r in ROLES}
           | {("free", b) for b in ("q", "timewarp", "duration", "footprints", "lambda", "coupling_forces")}
           | {("term", t) for t in ("energy=number", "dynamics=hard", "dynamics=relaxed", "environment=hard",
                                    "start=number", "boundary:start=hard", "boundary:end=hard",
                                    "boundary:end=free", "goal=number", "goal=hard", "coupling=number",
                                    "coupling=hard", "flight=hard")})


def check_step(step: Step) -> None:
    """ComposeError naming the Step and the item when it holds anything the lowering does not
    consume (a compiler/executor mismatch, never a user error)."""
    unknown = sorted(vocabulary(step) - HANDLED)
    if unknown:
        raise ComposeError(f"step {step.id!r}: the executor does not handle {', '.join(f'{a} {b}' for a, b in unknown)}"
                           " (schedules/execution/lower.py)")
    if step.term("energy") != 1.0:
        raise ComposeError(f"step {step.id!r}: energy weight {step.term('energy')!r}; the transcription "
                           "weighs the energy 1")
    if step.kind not in STEP_KINDS or step.term("dynamics") != (HARD if step.kind == FULL else RELAXED):
        raise ComposeError(f"step {step.id!r}: a {step.kind} step with dynamics={step.term('dynamics')!r}")
    if "duration" in step.free and "timewarp" not in step.free:
        raise ComposeError(f"step {step.id!r}: a free duration needs a free timewarp")


def _blend(a: Style, b: Style, w: float) -> Style:
    if w <= 0.0 or a is b:
        return a
    if w >= 1.0:
        return b
    return Style.from_vector((1 - w) * a.vector() + w * b.vector(), name=f"{a.name}>{b.name}@{w:.2f}")


def style_at(scene: Scene, who: str, step: Step, t: float) -> Style:
    """θ of ``who`` at canonical time ``t`` (s) from the Step's style timeline."""
    st = scene.character(who)
    tl = next((s for s in step.styles if s.character == who), None)
    if tl is None:
        return st.style
    s0, s1, w = tl.at(t)
    return _blend(st.style_of(s0), st.style_of(s1), w)


def world_window(motion: Motion, duration: float, window: tuple[float, float]) -> tuple[float, float]:
    """Canonical seconds (world time of the initial uniform warp) → world time of ``motion``."""
    s = np.clip(np.array(window, float) / duration, 0.0, 1.0)
    t = motion.time(s)
    return float(t[0]), float(t[1])


# The knot-to-knot jerk penalty of full steps (scenegraph.problem.jerk): measured in round 13 on walk
# (E 405 -> 205, 120 Hz residual 0.0067 -> 0.0032 bw, but 60 -> 226 iterations), handhold (stage audit
# passes: overlap 0.559 -> 0.29 cm, the held arms no longer flail) and springy_run (stage CoP 2.28 ->
# 3.91 cm, worse) — not yet on the tackle scenes, the jumps or the crowd, whose exit codes it could
# change: off until every bundled scene is re-run with it (docs/results.md, round 13).  JERK_WEIGHT
# is the measured weight.  Round 14: knots next to contact changes exempt (springy_run exit 1 -> 0 with it
# on); on, two_tacklers' residuals and stage improve, the runs' worst CoP frame is ~1.9 cm worse; still off
# until walk, handhold, the jumps and the unmeasured scenes are re-run (docs/results.md, round 14).
FULL_STEP_JERK = 0.0


def iteration_cap(step: Step) -> int:
    """IPOPT iterations of a Step's subproblems: 100 (timing; a coupled full step), 300 (full)."""
    from schedules.plan.step import COUPLED
    if step.kind != FULL:
        return 100
    return COUPLED_FULL_MAX_ITER if COUPLED in step.schedules else 300


def gait_flights(footsteps, flights=()) -> tuple[tuple[float, float], ...]:
    """World s (lift-off, touch-down) of the footstep plan's own flights — a run's, a hop
    sequence's — that no jump goal's flight already covers.  In a full step they are flights
    like a jump's (thesis ch. 3: only gravity acts, so the transcription states ballistic
    momentum there, :mod:`scenegraph.problem.flight`); with the soft root residual alone a
    tackler's capped run left 0.06 body weight unexplained at a lift-off (docs/results.md)."""
    return tuple((a, b) for a, b in airborne_gaps(footsteps)
                 if not any(fa < b - 1e-6 and a < fb - 1e-6 for fa, fb in flights))


def start_velocity(st: CharacterState, weight: float, at: float | None = None) -> VelocityTarget:
    """The scene's start: the centre of mass's velocity (m/s, world) at world time ``at`` (default:
    the start of ``st``'s motion) pulled toward ``st``'s motion's there — the lowering passes the
    planned motion (:attr:`CharacterState.planned`), so every step holds the same entry — with ``weight`` (the
    start spring's, 1/m² there, (s/m)² here: 1 m/s counts like 1 m).  Without it the initial
    momentum is free, and a walk_to walker entered falling at 6.3 m/s, caught by 12 body weights
    of ground force in the first 0.05 s (two_walkers' bob, docs/results.md); a target on the
    pelvis's velocity alone left the limbs falling (4.1 m/s, 8 body weights)."""
    m = st.motion
    q, qd, _ = (np.asarray(a, float).reshape(-1, N_DOF)[0] for a in m.at([m.start]))
    _, P, _ = momenta_fn(st.character)(q, qd)
    v = np.asarray(P, float).ravel() / st.character.total_mass
    return VelocityTarget(m.start if at is None else float(at), tuple(float(a) for a in v), weight)


def leap_flights_of(scene: Scene, who: str) -> tuple[tuple[float, float], ...]:
    """World s (take-off, landing) of every jump and hop goal of ``who`` (the goals with a
    ``flight``), in time order: what the kinematic pre-solve holds ballistic when
    ``executor.PRESOLVE_FLIGHTS`` is on (off: measured, the iteration count did not fall reliably,
    docs/dynamic-motion.md round 13)."""
    return tuple(sorted(tuple(float(t) for t in g.flight) for g in scene.goals
                        if g.character == who and getattr(g, "flight", None) is not None))


def _goal_weights(step: Step) -> dict[str, float | str]:
    return {n.split(":", 1)[1]: w for n, w in step.terms if n.startswith("goal:")}


def lower(scene: Scene, step: Step, who: str, max_iter: int | None = None) -> tuple[Subproblem, np.ndarray | None]:
    """The Subproblem of ``who`` in ``step`` and the mask of the control points it writes back
    (None: all).  Hard couplings are not included here (:func:`lower_joint`)."""
    check_step(step)
    st = scene.character(who)
    m = st.motion
    whole = step.window[0] <= 1e-9 and step.window[1] >= scene.duration - 1e-9
    win = world_window(m, scene.duration, step.window)
    free = set()
    if "q" in step.free:
        free.add("q")
    if "timewarp" in step.free:
        if not whole:
            raise ComposeError(f"step {step.id!r}: a free timewarp in a windowed step (the compiler frees it "
                               "over the whole scene only)")
        free.add("warp")
    fix_end, end_bounds = True, None
    if "duration" in step.free:
        if scene.duration_bounds is None:
            raise ComposeError(f"step {step.id!r}: a free duration, but the Scene has no duration_bounds")
        fix_end, end_bounds = False, tuple(float(b) for b in scene.duration_bounds)
    steps = st.footsteps
    if "footprints" in step.free:
        free.add("footprints")
        # only footsteps entirely inside the window move; the rest are held where they are
        steps = tuple(f if (whole or (f.t0 >= win[0] - 1e-6 and f.t1 <= win[1] + 1e-6)) else replace(f, free=False)
                      for f in steps)
    targets, avoid = goal_targets(scene, who, _goal_weights(step), window=win)  # window: reaction time
    poses = tuple(t for t in targets if isinstance(t, PoseTarget))  # keyframes: partial pose springs
    targets = tuple(t for t in targets if not isinstance(t, PoseTarget))
    flights = tuple(scene.goal(n.split(":", 1)[1]).flight for n, v in step.terms
                    if n.startswith("flight:") and v == HARD and scene.goal(n.split(":", 1)[1]).character == who)
    if step.kind == FULL:
        flights += gait_flights(steps, flights)
    springs = ()
    for cname in step.couplings:
        w = step.term(f"coupling:{cname}")
        if w == HARD:
            continue  # lower_joint
        targets += coupling_targets(scene, who, cname, float(w), win, rate=COUPLING_TARGET_HZ)
        springs += coupling_springs(scene, who, cname, float(w), win)
    velocities = ()
    w_start = step.term("start")
    if w_start is not None and win[0] <= m.start + 1e-9:
        # held to the planned entry (the initial motion's), not the current motion's: re-anchored on
        # the current motion, each whole-scene step kept the last one's drift (hopscotch entered crouched)
        x, y, _ = st.start
        z = float(handle_track(st.planned, "pelvis", [st.planned.motion.start])[0][2])
        targets += (HandleTarget("pelvis", m.start, (x, y, z), float(w_start), name="start"),)
        velocities = (start_velocity(st.planned, float(w_start), at=m.start),)
    style = style_at(scene, who, step, step.window[0])
    style_end = style_at(scene, who, step, step.window[1])
    if style_end is style:
        style_end = None
    sp = Subproblem(st.character, style, m, steps, flights=flights, poses=poses, velocities=velocities,
                    window=None if whole else win, free=frozenset(free),
                    dynamics="full" if step.term("dynamics") == HARD else "relaxed", targets=targets, avoid=avoid,
                    springs=springs, style_end=style_end,
                    max_iter=iteration_cap(step) if max_iter is None else max_iter,
                    open_end=not whole and step.term("boundary:end") == FREE,
                    window_only=step.role == "receding", fix_end_time=fix_end, end_time_bounds=end_bounds,
                    label=step.id.replace("/", "_"), ground=scene.ground, stall_iterations=STALL_ITERATIONS,
                    soft_pin_hz=SOFT_PIN_HZ if step.kind == FULL else 0.0,
                    # contact semantics at 120 Hz (issue 15 item 3): planted feet keep their frame,
                    # handles near the floor do not slide (timing steps and pre-solves: off)
                    stance_frame_weight=STANCE_FRAME_WEIGHT if step.kind == FULL else 0.0,
                    no_slip_weight=NO_SLIP_WEIGHT if step.kind == FULL else 0.0, contact_hz=SOFT_PIN_HZ,
                    # no ringing between the evaluation points (issue 15): the jerk's knot-to-knot jumps
                    jerk_weight=FULL_STEP_JERK if step.kind == FULL else 0.0,
                    # decreasing horizon (tackle, dodge: running and dodging feet): the ground on
                    # a dense grid too, as synthesize does for runs — between the 30 Hz points a
                    # toe dipped 11–15 mm (audit gate 10 mm)
                    soft_ground_hz=SOFT_PIN_HZ if step.kind == FULL and step.role == "horizon" else 0.0,
                    # bodies apart: in full steps, this character's body spheres off every other
                    # character's (held at its current motion) where they come close
                    clearance=scene_clearance(scene, who, win) if step.kind == FULL and len(scene.characters) > 1
                    else (), clearance_weight=CLEARANCE_WEIGHT)
    mask = None if whole else window_mask(sp, m.n_ctrl)
    return sp, mask


@dataclass(frozen=True)
class Lowered:
    """A joint Step: the two characters (a, b) and the hard hand-hold between them."""

    characters: tuple[str, str]
    coupling: JointCoupling


def lower_joint(scene: Scene, step: Step) -> Lowered | None:
    """The joint problem of a Step with a hard coupling (``coupling:<name>=hard``), or None.

    The compiler emits hard couplings only for hand-holds between the two characters of a
    full step (it rejects the rest with a located error); both timewarps are held there.
    The coupling times are the coupling interval ∩ the window at JOINT_COUPLING_HZ (world s of
    the first character; both motions share world time)."""
    hard = [c for c in step.couplings if step.term(f"coupling:{c}") == HARD]
    if not hard:
        return None
    if "coupling_forces" not in step.free or step.kind != FULL or len(step.characters) != 2 or len(hard) != 1:
        raise ComposeError(f"step {step.id!r}: a hard coupling needs a full step of two characters with one "
                           "coupling and free coupling_forces")
    c = scene.coupling(hard[0])
    if c.type != "hand_hold":
        raise ComposeError(f"step {step.id!r}: hard coupling {c.name!r} is a {c.type}; only a hand_hold has a joint solve")
    a, b = step.characters
    ha = next(h for w, h in c.handles if w == a)
    hb = next(h for w, h in c.handles if w == b)
    win = world_window(scene.character(a).motion, scene.duration, step.window)
    lo, hi = max(c.interval[0], win[0]), min(c.interval[1], win[1])
    return Lowered((a, b), JointCoupling(ha, hb, coupling_times((lo, hi), JOINT_COUPLING_HZ), name=c.name))
