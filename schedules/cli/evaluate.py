"""``compose evaluate-style STYLE.yaml --test CLIP.bvh [--frames A:B] [--body PRESET] --report R.json``.

The held-out test of a learned style (issue #18, item 1): on a real trial the style was not
learned from, synthesise with the trial's own footsteps, contact timing and duration four
variants — learned, default, springs off (learned α; ks1, ks2, kd, k_shoe, h_rest zero) and
kinematic (the initial motion from the training clip's poses plus the kinematic pre-solve, no
dynamics) — and compare each with the real trial (scenegraph.nio.heldout's measures).  Every
number goes to one JSON report, written atomically; nothing is written on bad input.
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from scenarios.errors import ComposeError, InputError, Location

__all__ = ["register", "evaluate_style", "VARIANTS", "find_training_clip", "audit_entry"]

VARIANTS = ("learned", "default", "springs_off", "kinematic")
UNSCALED = (("s_max", 1e30),)  # IPOPT: no division of the convergence error by the multipliers' size
CONTACT_RULES = ("onesided", "central")
CONTACT_TERMS = ("scene", "plain")  # the syntheses' contact terms: a scene full step's, or synthesize's bare ones
BODIES = ("adult_male", "adult_female", "child")


def find_training_clip(name: str, test_clip: Path) -> Path | None:
    """The style's training clip (provenance ``clip``, a file name) beside the test clip, in
    $COMPOSE_SHARED_MOCAP, in the bundled scenarios/clips/, or in ../shared/mocap relative to
    the working directory or the repo."""
    env = os.environ.get("COMPOSE_SHARED_MOCAP")
    repo = Path(__file__).resolve().parents[2]
    roots = [test_clip.parent, *([Path(env)] if env else []), repo / "scenarios" / "clips",
             Path.cwd().parent / "shared" / "mocap", repo.parent / "shared" / "mocap"]
    for r in roots:
        if (r / Path(name).name).is_file():
            return r / Path(name).name
    return None


def _load_learned_style(path: Path):
    from scenegraph.model.style import load_style

    if not path.is_file():
        raise InputError(f"no such style file: {path}" if not path.exists() else f"{path} is not a file")
    style = load_style(path)  # located errors (file:line field)
    prov = style.provenance
    if prov is None or not prov.clip:
        raise InputError("a held-out test needs a learned style: this file has no provenance naming its "
                         "training clip (write one with `compose learn`)", Location(str(path), None, None, "provenance"))
    return style


def _stance_mask(t: np.ndarray, steps) -> np.ndarray:
    """(T, 2) [left, right]: inside a footstep's stance interval [t0, t1]."""
    m = np.zeros((len(t), 2), bool)
    for st in steps:
        k = 0 if st.foot == "l" else 1
        m[:, k] |= (t >= st.t0 - 1e-9) & (t <= st.t1 + 1e-9)
    return m


def _strides(steps, t_first: float) -> dict[str, list[tuple[float, float]]]:
    """Stride windows per foot ("l", "r") between that foot's strikes; a footstep that starts
    at the trial's first frame is no strike (the foot may have been down before)."""
    from scenegraph.nio.heldout import stride_windows

    return {foot: stride_windows([s.t0 for s in steps if s.foot == foot and s.t0 > t_first + 1e-6])
            for foot in ("l", "r")}


def _noise_floor(t, q, by_foot) -> dict[str, float] | None:
    """The noise floor per foot's strides (scenegraph.nio.heldout.noise_floor_deg), pooled as the
    RMS over the feet that have at least two strides; None if neither has."""
    from scenegraph.nio.heldout import noise_floor_deg

    parts = [nf for nf in (noise_floor_deg(t, q, w) for w in by_foot.values()) if nf is not None]
    if not parts:
        return None
    return {g: float(np.sqrt(np.mean([p[g] ** 2 for p in parts]))) for g in parts[0]}


def _training_features(style, test_clip: Path, onesided: bool = False) -> tuple[dict | None, str | None]:
    """The training clip's style features, or (None, why skipped)."""
    from scenegraph.mocap.contacts import detect_footsteps
    from scenegraph.nio.heldout import style_features
    from scenegraph.mocap.clip import load_clip

    from schedules.cli.learn import parse_frames

    prov = style.provenance
    path = find_training_clip(prov.clip, test_clip)
    if path is None:
        return None, f"training clip {prov.clip} not found (beside the test clip, $COMPOSE_SHARED_MOCAP, ../shared/mocap)"
    frames = parse_frames(prov.frames) if prov.frames else None
    clip = load_clip(path, frames=frames, preset=prov.body or "adult_male")
    t = np.asarray(clip.times, float)
    m = np.zeros((len(t), 2), bool)
    for st in detect_footsteps(clip, onesided=onesided):
        m[:, 0 if st.side == "l" else 1] |= (t >= st.start) & (t <= st.end)
    return {"file": str(path), "frames": prov.frames, "features": style_features(t, np.asarray(clip.q), m)}, None


def scene_contact_terms(mode: str = "scene") -> dict:
    """The Subproblem contact terms of a scene's full step (``schedules.execution.lower``): soft
    footprint springs at ``SOFT_PIN_HZ`` (120 Hz) between the hard constraint points, the planted
    foot's frame (``STANCE_FRAME_WEIGHT``, 1/(rad²·s)) and no slip of handles near the floor
    (``NO_SLIP_WEIGHT``, s/m²) sampled at 120 Hz; {} for "plain"."""
    if mode == "plain":
        return {}
    from scenegraph.problem.no_slip import NO_SLIP_WEIGHT
    from scenegraph.problem.stance_frame import STANCE_FRAME_WEIGHT

    from schedules.execution.lower import SOFT_PIN_HZ

    return {"soft_pin_hz": SOFT_PIN_HZ, "stance_frame_weight": STANCE_FRAME_WEIGHT, "no_slip_weight": NO_SLIP_WEIGHT,
            "contact_hz": SOFT_PIN_HZ}


def audit_entry(ch, audit, motion, steps, rate: float = 120.0) -> dict:
    """A variant's physics audit as the report holds it: the audit's figures, the stance slides
    as distances (scenegraph.nio.slide; ``planted_speed_max`` is the planted handles' largest
    *speed*, m/s), and the verdict with the tolerances of ``compose run`` (AUDIT_TOLERANCES:
    footsteps 5 mm, penetration 10 mm, friction, root residual 2 % bw, dense residual 0.05 bw at
    every 120 Hz frame) plus the stage audit's stance slide (5 mm).  Until round 13 the held-out
    verdict used ``Audit.passes()``'s defaults (footsteps and penetration 1 mm, no dense
    residual), stricter than any scene's and not what the project calls passing."""
    from scenegraph.nio.slide import slide_summary, stance_slides
    from scenegraph.stage_audit.verdict import Tolerances

    from schedules.cli.run import AUDIT_TOLERANCES

    tol = dict(AUDIT_TOLERANCES, stance_slide_tol=Tolerances().stance_slide_mm / 1000.0)
    t = np.linspace(motion.start, motion.end, max(2, int(round(motion.duration * rate)) + 1))
    slides = slide_summary(stance_slides(ch, t, motion.canonical(motion.to_canonical(t)), steps))
    a = audit.to_dict()
    checks = {"footstep": a["footstep_error_max"] <= tol["footstep_tol"],
              "penetration": a["penetration_max"] <= tol["penetration_tol"],
              "friction": a["friction_violation_max"] <= tol["friction_tol"],
              "root_residual": a["root_residual_rel"] <= tol["residual_rel_tol"],
              "dense_residual": a["dense_residual_max"] <= tol["dense_tol"],
              "stance_slide": slides["stance_slide_max_m"] <= tol["stance_slide_tol"]}
    return {**a, **slides,
            "tolerances": tol, "fails_on": [k for k, ok in checks.items() if not ok],
            "passes": bool(all(checks.values()))}


def evaluate_style(style_path, test_path, frames: tuple[int, int] | None = None, body: str = "adult_male",
                   max_iter: int = 300, log=None, contacts: str = "onesided", constraint_hz: float = 30.0,
                   unscaled: bool = False, sensitivity: bool = False, hessian: str = "gauss_newton",
                   tol: float = 1e-4, variants: tuple[str, ...] = VARIANTS, contact_terms: str = CONTACT_TERMS[0]) -> dict:
    """The held-out report (a JSON-ready dict) of a learned style on a test trial.

    ``contacts``: "onesided" (default) detects the trial's and the training clip's contacts
    with one-sided speeds widened by half a frame (``schedules.cli.learn.clip_target``); "central" is
    the detection of the first measurements, which turned 07_12's brisk walk into a run.
    ``constraint_hz``: the footstep and ground constraint grid of every synthesis (Hz; the
    audit checks 120 Hz: at 30 Hz the feet miss by millimetres between the points).
    ``unscaled``: IPOPT's convergence test on the unscaled KKT error (``s_max`` 1e30): the footstep
    pins make IPOPT's footstep multipliers grow to ~1e14, and by default its error is divided by
    their mean size, so "Solve_Succeeded" can stop far from a KKT point (scenegraph.nio.sensitivity).
    ``sensitivity``: add dX*/dθ at the learned synthesis (:func:`_sensitivity`) to the report.
    ``hessian``: the dynamic syntheses' Hessian ("gauss_newton", the default, or "exact").
    ``tol``: IPOPT's tolerance of the dynamic syntheses (default 1e-4, the project's); below the
    default the "acceptable level" exit is switched off too, so a solve runs to tol or to ``max_iter``.
    ``variants``: the variants to synthesise and report (default all four); "learned" is always
    one of them (the kinematic variant is its pre-solve, the paired differences are against it).
    A subset screens estimators: the default style's synthesis does not depend on the learn.
    ``contact_terms``: "scene" (default since round 15) gives every dynamic synthesis the contact
    terms of a scene's full step (:func:`scene_contact_terms`: soft footprints, stance frame and no
    slip at 120 Hz), so a prediction is what ``compose run`` would make of the trial's footsteps and
    is judged by the audit ``compose run`` applies; "plain" is ``synthesize``'s bare footstep
    constraints at ``constraint_hz`` (rounds 11–14: feet 2–7 mm off their footprints between the
    30 Hz points, and the learned 07_12 prediction failed the audit there)."""
    if contact_terms not in CONTACT_TERMS:
        raise InputError(f"contact terms {contact_terms!r}: one of {', '.join(CONTACT_TERMS)}")
    variants_wanted = tuple(v for v in VARIANTS if v in set(variants) | {"learned", "kinematic"})
    unknown = sorted(set(variants) - set(VARIANTS))
    if unknown:
        raise InputError(f"variants {', '.join(unknown)}: unknown (one of {', '.join(VARIANTS)})")
    if contacts not in CONTACT_RULES:
        raise InputError(f"--contacts {contacts!r}: one of {', '.join(CONTACT_RULES)}")
    onesided = contacts == "onesided"
    from scenegraph.nio import heldout as H
    from scenegraph.model.audit import audit_motion
    from scenegraph.nio import example_of
    from scenegraph.model.gait import initial_motion
    from scenegraph.model.style import default_style
    from scenegraph.nio.plausibility import best_fit_root_residual
    from scenegraph.problem.synthesis import synthesize

    from schedules.cli.learn import clip_target

    say = log or (lambda s: None)
    style_path, test_path = Path(style_path), Path(test_path)
    learned = _load_learned_style(style_path)
    if not test_path.is_file():
        raise InputError(f"no such clip file: {test_path}" if not test_path.exists() else f"{test_path} is not a file")
    skipped: list[str] = []
    t_start = time.perf_counter()
    # the trial's footsteps, detected on the clip and placed where a spline fit of its IK puts the
    # feet (the Appendix A reconstruction is not needed here and did not converge on 07_12 30:246)
    ch, _, steps, clip = clip_target(test_path, frames or (None, None), body, reconstruct=False, feasible=False,
                                   onesided=onesided)
    t = np.asarray(clip.times, float)
    q_real = np.asarray(clip.q, float)
    t0, t1 = float(t[0]), float(t[-1])
    say(f"test trial: {len(t)} frames, {t1 - t0:.2f} s, {len(steps)} footsteps")

    train, why = _training_features(learned, test_path, onesided)
    if why:
        skipped.append(f"direction score: {why}")
    if learned.example is not None:
        example = learned.example.arrays()
        example_src = "style file (example poses)"
    elif train is not None:
        from schedules.cli.learn import parse_frames

        _, xt, tsteps, _ = clip_target(train["file"], parse_frames(learned.provenance.frames),
                                       learned.provenance.body or body, reconstruct=False, feasible=False,
                                       onesided=onesided)
        example = example_of(xt, tsteps).arrays()
        example_src = f"training clip {train['file']}"
    else:
        raise InputError(f"the style has no example poses and its training clip is not found ({why})",
                         Location(str(style_path), None, None, "provenance.clip"))

    M = len(learned.alpha)
    zero = np.zeros(M)
    styles = {"learned": learned, "default": default_style(ch.total_mass),
              "springs_off": learned.with_(ks1=zero, ks2=zero, kd=zero, k_shoe=0.0, h_rest=0.0, name="springs_off")}
    styles = {k: v for k, v in styles.items() if k in variants_wanted}
    motions, audits, solver = {}, {}, {}
    for name, st in styles.items():
        say(f"synthesising {name} (max {max_iter} iterations)")
        syn = synthesize(ch, st, steps, t0, t1, example=example, max_iter=max_iter, constraint_hz=constraint_hz,
                         ipopt_options=(UNSCALED if unscaled else ()) + ((("acceptable_iter", 0),) if tol < 1e-4 else ()),
                         hessian=hessian, tol=tol, **scene_contact_terms(contact_terms))
        motions[name], audits[name] = syn.result.motion, syn.audit
        solver[name] = {"success": bool(syn.result.success), "status": syn.result.status,
                        "iterations": int(syn.result.iterations), "seconds": round(syn.seconds, 2),
                        "energy": float(syn.result.energy)}
        if name == "learned":  # the kinematic variant: the same initial motion and pre-solve, no dynamics
            pre = syn.presolve
            motions["kinematic"] = pre.motion
            audits["kinematic"] = audit_motion(ch, learned, pre.motion, steps, pre.contact_forces or None)
            solver["kinematic"] = {"success": bool(pre.success), "status": pre.status,
                                   "iterations": int(pre.iterations), "seconds": round(pre.seconds, 2),
                                   "energy": None}
        say(f"  {name}: {syn.result.summary()}")

    inside = (t >= max(m.start for m in motions.values()) - 1e-9) & (t <= min(m.end for m in motions.values()) + 1e-9)
    tt, qr = t[inside], q_real[inside]
    stance = _stance_mask(tt, steps)
    by_foot = _strides(steps, t0)
    windows = sorted(by_foot["l"] + by_foot["r"])  # the bootstrap's units: every stride of either foot
    real_feat = H.style_features(tt, qr, stance)
    variants, per_stride, curves = {}, {}, {"real": qr}
    for name in variants_wanted:
        m = motions[name]
        qp = m.canonical(m.to_canonical(tt))
        curves[name] = qp
        feat = H.style_features(tt, qp, stance)
        per_stride[name] = H.per_stride_rms_deg(tt, qp, qr, windows)
        variants[name] = {
            "rms_deg": H.group_rms_deg(qp, qr),
            "dof_rms_deg": H.dof_rms_deg(qp, qr),
            "root_path_m": H.root_path_error_m(qp, qr),
            "features": feat,
            "feature_error": {k: feat[k] - real_feat[k] for k in H.FEATURE_NAMES},
            "direction": H.direction_score(train["features"], real_feat, feat) if train else None,
            "per_stride_rms_deg": per_stride[name],
            "audit": audit_entry(ch, audits[name], m, steps),
            "best_fit_root_residual": best_fit_root_residual(ch, styles.get(name, learned), m, steps).summary(),
            "solver": solver[name],
        }
    m0 = initial_motion(ch, steps, t0, t1, example=example)
    start = {"best_fit_root_residual": best_fit_root_residual(ch, learned, m0, steps).summary(),
             "what": "the initial motion before the kinematic pre-solve: the training clip's poses by leg phase, "
                     "the root through the test footprints' midpoints (scenegraph.model.gait.initial_motion)"}
    paired = {}
    for other in (v for v in ("default", "springs_off", "kinematic") if v in variants_wanted):
        paired[f"learned-{other}"] = {
            g: H.bootstrap_mean_ci(np.asarray(per_stride["learned"][g]) - np.asarray(per_stride[other][g]))
            for g in H.JOINT_GROUPS}
    noise = _noise_floor(tt, qr, by_foot)
    if noise is None:
        skipped.append("noise floor: no foot has two complete strides in the trial")
    if len(windows) < 3:
        skipped.append(f"bootstrap: only {len(windows)} stride(s); the intervals are not meaningful")
    skipped.append("plots: the ghost preview strip is not written (joint curves are, with matplotlib)")
    skipped.append("initial root state: the synthesis starts from the footprints' root path, not the trial's "
                   "first root state")
    return {
        "command": "evaluate-style",
        "style": {"file": str(style_path), "name": learned.name, "provenance": learned.provenance.model_dump()},
        "test": {"file": str(test_path), "frames": list(clip.frame_range), "body": body, "frames_used": int(len(tt)),
                 "fps": float(clip.fps), "duration_s": t1 - t0,
                 "footsteps": [{"foot": s.foot, "t0": s.t0, "t1": s.t1, "position": list(s.position)} for s in steps],
                 "strides": {f: [list(w) for w in ws] for f, ws in by_foot.items()}},
        "alignment": "by time: every variant plants the trial's own footsteps at the trial's times, so its "
                     "footfalls are the trial's",
        "initial_motion": example_src,
        "start": start,
        "max_iter": max_iter,
        "contacts": contacts,
        "constraint_hz": constraint_hz,
        "unscaled_convergence": unscaled,
        "hessian": hessian,
        "tol": tol,
        "contact_terms": {"mode": contact_terms, **scene_contact_terms(contact_terms)},
        "sensitivity": (_sensitivity(ch, styles, motions["learned"], steps, tt, constraint_hz, max_iter, say, qr)
                        if sensitivity else None),
        "groups": {g: [ch.dof_names[i] for i in H.group_indices(g)] for g in H.JOINT_GROUPS},
        "real": {"features": real_feat},
        "training": train,
        "noise_floor_deg": noise,
        "variants": variants,
        "paired_bootstrap_deg": paired,
        "skipped": skipped,
        "seconds": round(time.perf_counter() - t_start, 1),
        "_curves": {"t": tt, **curves},  # popped by the command for the plot, not written
    }


def _sensitivity(ch, styles: dict, motion, steps, times, constraint_hz: float, max_iter: int, say,
                 q_real=None) -> dict:
    """dX*/dθ at the learned synthesis (scenegraph.nio.sensitivity): re-solved from it with the exact
    Hessian and the unscaled convergence test (at most ``max_iter`` iterations), then the KKT
    system at that point; with the first-order change towards the default and springs-off styles
    and the actual group RMS between the learned synthesis and the re-solved point."""
    from scenegraph.nio import sensitivity as S
    from scenegraph.nio.heldout import group_rms_deg
    from scenegraph.problem import Subproblem

    learned = styles["learned"]
    sp = Subproblem(ch, learned, motion, steps, free=frozenset({"q"}), hessian="exact", max_iter=max_iter,
                    tol=1e-6, constraint_hz=constraint_hz, label="sensitivity",
                    ipopt_options=UNSCALED + (("acceptable_iter", 0),))
    say(f"sensitivity: re-solving the learned synthesis with the exact Hessian (max {max_iter} iterations)")
    pt, b = S.solve_kkt(sp)
    sens = S.kkt_sensitivity(b.nlp, pt, learned.vector(), times)
    q0 = motion.canonical(motion.to_canonical(times))
    q1 = pt.motion.canonical(pt.motion.to_canonical(times))
    rep = S.sensitivity_report(sens, learned.vector(), {k: v for k, v in styles.items() if k != "learned"}, learned)
    rep["resolve"] = {"status": pt.status, "iterations": pt.iterations, "violation": pt.violation,
                      "moved_from_synthesis_deg": group_rms_deg(q1, q0),
                      "rms_vs_real_deg": group_rms_deg(q1, q_real) if q_real is not None else None,
                      "ipopt_max_multiplier": float(np.abs(pt.lam_g).max(initial=0.0))}
    return rep


PLOT_DOFS = ("hip_flex_l", "knee_flex_l", "ankle_flex_l", "waist_flex", "waist_lat", "chest_flex",
             "shoulder_flex_l", "elbow_flex_l")


def plot_curves(curves: dict, path: Path) -> bool:
    """Joint curves (deg over s) of the real trial and the four variants for a few DOFs of each
    group, one panel per DOF, written atomically as PNG; False if matplotlib is missing."""
    try:
        from matplotlib.figure import Figure
    except ImportError:
        return False
    import io

    from scenarios.atomic import atomic_write
    from scenegraph.model.body import JOINT_DOF_NAMES, N_ROOT

    fig = Figure(figsize=(12, 8), dpi=80)
    axes = fig.subplots(2, 4).ravel()
    for ax, dof in zip(axes, PLOT_DOFS):
        j = N_ROOT + JOINT_DOF_NAMES.index(dof)
        for name in ("real", *(v for v in VARIANTS if v in curves)):
            ax.plot(curves["t"], np.degrees(curves[name][:, j]), lw=2.5 if name == "real" else 1.2,
                    color="k" if name == "real" else None, label=name)
        ax.set_title(dof, fontsize=9)
        ax.set_xlabel("s", fontsize=8)
    axes[0].set_ylabel("deg")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    atomic_write(path, buf.getvalue())
    return True


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def _cmd_evaluate(args) -> int:
    from scenarios.atomic import atomic_write

    from schedules.cli.learn import parse_frames

    # every argument is checked before anything is read or solved
    frames = parse_frames(args.frames) if args.frames else None
    if args.body not in BODIES:
        raise InputError(f"--body {args.body!r}: unknown preset (one of {', '.join(BODIES)})")
    if args.max_iter < 1:
        raise InputError(f"--max-iter {args.max_iter}: must be at least 1")
    bad = sorted(set(args.variants.split(",")) - set(VARIANTS))
    if bad:
        raise InputError(f"--variants {args.variants}: unknown {', '.join(bad)} (one of {', '.join(VARIANTS)})")
    if not 0.0 < args.tol <= 1.0:
        raise InputError(f"--tol {args.tol}: must lie in (0, 1]")
    if not 1.0 <= args.constraint_hz <= 240.0:
        raise InputError(f"--constraint-hz {args.constraint_hz}: must lie in [1, 240]")
    report = Path(args.report)
    if report.suffix.lower() != ".json":
        raise InputError(f"--report {args.report}: must end in .json")
    if report.parent and not report.parent.exists():
        raise InputError(f"--report {args.report}: folder {report.parent} does not exist")
    if not Path(args.test).is_file():
        raise InputError(f"no such clip file: {args.test}")
    print(f"compose evaluate-style: {args.style} on {args.test}", file=sys.stderr, flush=True)
    try:
        rep = evaluate_style(args.style, args.test, frames, args.body, args.max_iter,
                             log=lambda s: print(f"  {s}", file=sys.stderr, flush=True), contacts=args.contacts,
                             constraint_hz=args.constraint_hz, unscaled=args.unscaled_convergence,
                             sensitivity=args.sensitivity, hessian=args.hessian, tol=args.tol,
                             variants=tuple(args.variants.split(",")), contact_terms=args.contact_terms)
    except ComposeError:
        raise
    except (ValueError, OSError) as exc:
        raise InputError(f"{args.test}: {exc}") from None
    curves = rep.pop("_curves")
    plot = report.with_suffix(".curves.png")
    rep["plot"] = str(plot) if plot_curves(curves, plot) else None
    if rep["plot"] is None:
        rep["skipped"].append("plots: matplotlib is not installed (pip install compose-motion[plots])")
    atomic_write(report, json.dumps(_jsonable(rep), indent=1))
    for name, v in rep["variants"].items():
        r = v["rms_deg"]
        print(f"{name:12s} all {r['all']:6.2f}  legs {r['legs']:6.2f}  trunk {r['pelvis_trunk']:6.2f}  "
              f"arms {r['arms']:6.2f} deg  root {v['root_path_m']['rms']:.3f} m  "
              f"audit {'pass' if v['audit']['passes'] else 'FAIL ' + ','.join(v['audit']['fails_on'])} "
              f"(footstep {1e3 * v['audit']['footstep_error_max']:.1f} mm, "
              f"slide {1e3 * v['audit']['stance_slide_max_m']:.1f} mm)", file=sys.stderr)
    print(f"wrote {report}", file=sys.stderr)
    return 0


def register(sub) -> None:
    p = sub.add_parser("evaluate-style", help="held-out test of a learned style on another real trial",
                       description="Synthesise a test trial's own footsteps with the learned style, the default "
                                   "style, the learned style with springs off and the kinematic answer, and "
                                   "compare each with the real trial (joint RMS by group, style features, "
                                   "audits, noise floor, bootstrap over strides) in a JSON report.")
    p.add_argument("style", metavar="STYLE.yaml")
    p.add_argument("--test", required=True, metavar="CLIP.bvh", help="the held-out real trial")
    p.add_argument("--frames", default=None, metavar="A:B", help="source frames A to B (exclusive) of the test clip")
    p.add_argument("--body", default="adult_male", help="body preset (adult_male, adult_female, child)")
    p.add_argument("--report", required=True, metavar="R.json")
    p.add_argument("--max-iter", type=int, default=300, help="IPOPT iteration cap per synthesis (default 300)")
    p.add_argument("--contacts", default="onesided", choices=CONTACT_RULES,
                   help="contact detection: one-sided speeds widened by half a frame (default), or the "
                        "central differences of the first measurements")
    p.add_argument("--constraint-hz", type=float, default=30.0, metavar="HZ",
                   help="footstep and ground constraint grid of the syntheses (default 30; the audit checks 120)")
    p.add_argument("--unscaled-convergence", action="store_true",
                   help="IPOPT's convergence test on the unscaled KKT error (s_max 1e30; see docs/learning.md)")
    p.add_argument("--sensitivity", action="store_true",
                   help="add dX*/dtheta at the learned synthesis (implicit-function theorem) to the report")
    p.add_argument("--tol", type=float, default=1e-4,
                   help="IPOPT tolerance of the dynamic syntheses (default 1e-4; smaller also disables the "
                        "'acceptable level' exit)")
    p.add_argument("--hessian", choices=("gauss_newton", "exact"), default="gauss_newton",
                   help="Hessian of the dynamic syntheses (default gauss_newton)")
    p.add_argument("--contact-terms", choices=CONTACT_TERMS, default=CONTACT_TERMS[0],
                   help="contact terms of the dynamic syntheses: a scene full step's (scene, default: soft "
                        "footprints, stance frame and no slip at 120 Hz) or synthesize's bare constraints (plain)")
    p.add_argument("--variants", default=",".join(VARIANTS), metavar="A,B",
                   help="variants to synthesise (default all four; learned and kinematic always)")
    p.set_defaults(func=_cmd_evaluate)
