"""``compose learn CLIP.bvh --frames A:B [--body PRESET] -o STYLE.yaml``: learn a style by NIO;
``compose learn A.bvh:A:B B.bvh:C:D … -o STYLE.yaml``: one style from several clips (or
segments) of one person (:mod:`scenegraph.nio.multi`)."""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from scenarios.errors import ComposeError, InputError

__all__ = ["register", "parse_frames", "parse_clip_spec", "clip_specs", "clip_target", "learn_from_bvh",
           "learn_from_clips"]

# `compose learn`'s estimator (issue #18, round 14): strength-referenced log-normal α prior and
# spring prior of weight 0.1, coarse ties (147 -> 59 free numbers), one-sided contacts.  Chosen
# on the two validation trials (07_01 -> 07_12, 16_18 straight -> turn), where it took the
# learned prediction from 24.9 to 9.9 deg and from 15.6 to 9.2 deg (docs/results.md, round 13).
DEFAULTS = {"alpha_prior": 0.1, "alpha_ref": "strength", "spring_prior": 0.1, "tie": "coarse", "contacts": "onesided"}


PROJECTION_ITER = 200  # IPOPT iterations of the projection of X_T onto its footsteps (clip_target)


def parse_frames(text: str) -> tuple[int, int]:
    """"A:B" → (A, B): source frames of the BVH file, B exclusive (Python slice style)."""
    try:
        a, b = (int(x) for x in str(text).split(":"))
    except ValueError:
        raise InputError(f"--frames must look like A:B (two integers), got {text!r}") from None
    if a < 0 or b <= a + 1:
        raise InputError(f"--frames {text}: need 0 <= A and at least 2 frames (B > A + 1)")
    return a, b


def parse_clip_spec(text: str) -> tuple[str, tuple[int, int] | None]:
    """"PATH:A:B" → (PATH, (A, B)); a plain "PATH" (no colon-separated frame range) → (PATH, None).

    A colon-separated tail that is not two integers is an error (``InputError``) naming the
    form expected, unless the whole text is an existing file."""
    text = str(text)
    if ":" not in text or Path(text).is_file():
        return text, None
    parts = text.rsplit(":", 2)
    if len(parts) != 3 or not parts[0]:
        raise InputError(f"clip {text!r}: expected PATH or PATH:A:B (frames A to B, B exclusive)")
    try:
        frames = parse_frames(f"{parts[1]}:{parts[2]}")
    except InputError as exc:
        raise InputError(f"clip {text!r}: expected PATH:A:B with integer frames A < B - 1 ({exc})") from None
    return parts[0], frames


def clip_specs(texts, frames_opt: str | None) -> list[tuple[str, tuple[int, int]]]:
    """The (path, frames) of every clip argument of ``compose learn``: each "PATH:A:B", or
    one plain "PATH" with ``--frames A:B``.  Errors (``InputError``): a clip without frames,
    ``--frames`` together with PATH:A:B, ``--frames`` for several clips, a clip given twice."""
    specs = [parse_clip_spec(t) for t in texts]
    if frames_opt is not None:
        if len(specs) > 1:
            raise InputError("--frames is for one clip: give each of several clips its frames as PATH:A:B")
        if specs[0][1] is not None:
            raise InputError(f"clip {texts[0]!r} has frames already: drop --frames {frames_opt}")
        specs = [(specs[0][0], parse_frames(frames_opt))]
    for text, (path, fr) in zip(texts, specs):
        if fr is None:
            raise InputError(f"clip {text!r}: no frames (use PATH:A:B, or --frames A:B with one clip)")
    seen = set()
    for path, fr in specs:
        key = (str(Path(path).resolve()), fr)
        if key in seen:
            raise InputError(f"clip {path}:{fr[0]}:{fr[1]} is given twice")
        seen.add(key)
    return specs


def _to_spacetime_steps(ch, steps, t0: float, t1: float):
    """Clip footsteps (scenegraph.mocap.contacts) → spacetime Footsteps with heel/ball phases."""
    from scenegraph.model.footsteps import Footstep

    foot_len = ch.handle("ball_l").point[0] - ch.handle("heel_l").point[0]
    out = []
    for st in steps:
        a, b = max(st.start, t0), min(st.end, t1)
        if b - a < 0.05:
            continue
        by = {c.handle: c for c in st.contacts}
        d = np.array([np.cos(st.heading), np.sin(st.heading)])
        if "ball" in by:
            pos = np.array(by["ball"].position[:2])
        elif "heel" in by:
            pos = np.array(by["heel"].position[:2]) + foot_len * d
        else:
            pos = np.array(st.position[:2])
        span = b - a

        def frac(c):
            if c is None:
                return None
            fa = float(np.clip((c.start - a) / span, 0.0, 1.0))
            fb = float(np.clip((c.end - a) / span, 0.0, 1.0))
            return (fa, fb) if fb - fa > 0.05 else None

        heel, ball = frac(by.get("heel")), frac(by.get("ball") or by.get("toe"))
        if heel is None and ball is None:
            ball = (0.0, 1.0)
        out.append(Footstep(st.side, (float(pos[0]), float(pos[1])), float(a), float(b), float(st.heading),
                            heel=heel, ball=ball))
    return tuple(sorted(out, key=lambda f: f.t0))


def _has_flight(steps, t0: float, t1: float, min_gap: float = 0.05) -> bool:
    """Whether no foot is on the ground for at least ``min_gap`` s somewhere inside the
    footsteps' span (a run has flight phases; a walk has double support)."""
    spans = sorted((max(st.t0, t0), min(st.t1, t1)) for st in steps)
    reach = spans[0][1]
    for a, b in spans[1:]:
        if a - reach >= min_gap:
            return True
        reach = max(reach, b)
    return False


def _steps_on_motion(ch, motion, steps):
    """Footsteps re-placed where ``motion`` puts the feet: per step the mean ball position and
    heel→ball heading over its planted interval (the detected positions come from the raw
    clip, and a reconstruction that misses them by centimetres is far from C)."""
    from dataclasses import replace

    from scenegraph.model.footsteps import contact_points
    from scenegraph.model.residual import handles_kernel

    out = []
    for st in steps:
        names = (f"heel_{st.foot}", f"ball_{st.foot}")
        hk = handles_kernel(ch, names)
        spans = [ab for _, ab, _ in contact_points(ch, st)]
        t = np.linspace(min(a for a, _ in spans), max(b for _, b in spans), 9)
        q = motion.canonical(motion.to_canonical(t))
        P = np.array([np.asarray(hk(qi)).ravel() for qi in q])  # (9, 6)
        heel, ball = P[:, 0:2].mean(axis=0), P[:, 3:5].mean(axis=0)
        d = ball - heel
        out.append(replace(st, position=(float(ball[0]), float(ball[1])),
                           heading=float(np.arctan2(d[1], d[0]))))
    return tuple(out)


def _widen(steps, half: float):
    """Clip footsteps with every contact interval widened by ``half`` s on both sides: a
    contact seen in frames a..b lasts from half a frame before a to half a frame after b, so
    two feet seen down in adjacent frames share that half-frame boundary (no flight)."""
    from dataclasses import replace

    out = []
    for st in steps:
        cs = tuple(replace(c, start=c.start - half, end=c.end + half) for c in st.contacts)
        out.append(replace(st, start=st.start - half, end=st.end + half, contacts=cs))
    return out


def clip_target(path, frames: tuple[int, int], body: str = "adult_male", ctrl_hz: float = 10.0,
                reconstruct: bool = True, feasible: bool = True, onesided: bool = False,
                height: float | None = None, mass: float | None = None):
    """(character, X_T motion, footsteps, clip) for NIO from a BVH file's frames [A, B).

    X_T: the smooth reconstruction (Appendix A; a plain spline fit if ``reconstruct`` is
    False); footsteps C: detected on the clip and re-placed where the reconstruction puts the
    feet.  With ``feasible`` (default) X_T is then moved onto C (resampled to the synthesis
    resolution and projected by :func:`scenegraph.nio.feasible_target`: exact footsteps, root
    residual softly zero, 0.7° RMS from the reconstruction on 07_01), because NIO compares
    X_T with motions that satisfy C.  With ``onesided`` the contacts are detected with
    one-sided speeds (:func:`scenegraph.mocap.contacts.point_speed`) and widened by half a frame
    (:func:`_widen`): without it a brisk walk (07_12, 1.9 m/s, 30 fps) comes out as a run
    with 0.07–0.1 s flight phases and ball-only contacts.  ``height`` (m) / ``mass`` (kg): the
    character's (default: the clip's estimated stature, the preset's body-mass index)."""
    from scenegraph.mocap.contacts import detect_footsteps
    from scenegraph.mocap.clip import load_clip
    from scenegraph.model.motion import Motion

    p = Path(path)
    if not p.is_file():
        raise InputError(f"no such clip file: {path}")
    clip = load_clip(p, frames=frames, preset=body, height=height, mass=mass)
    times = np.asarray(clip.times, float)
    if reconstruct:  # Appendix A: smooth, root residual softly zero
        from scenegraph.mocap.clip import reconstruct_clip

        motion = reconstruct_clip(clip, ctrl_hz=ctrl_hz).motion
    else:
        motion = Motion.from_samples(times, np.asarray(clip.q, float),
                                     n_ctrl=max(6, int(round((times[-1] - times[0]) * ctrl_hz)) + 3))
    found = detect_footsteps(clip, onesided=onesided)
    if onesided:
        found = _widen(found, 0.5 / clip.fps)
    steps = _to_spacetime_steps(clip.character, found, times[0], times[-1])
    if not steps:
        raise InputError(f"{path} frames {frames[0]}:{frames[1]}: no foot contacts detected")
    if _has_flight(steps, times[0], times[-1]):
        # a run: ball contacts only, as the synthesis plants running feet (footsteps.RUN_BALL).
        # With the detected heel phases the projection below failed on 09_11 (4.4 cm left
        # after 400 iterations; ball only: exact in 42 iterations)
        from dataclasses import replace

        from scenegraph.model.footsteps import RUN_BALL
        steps = tuple(replace(st, heel=None, ball=RUN_BALL) for st in steps)
    steps = _steps_on_motion(clip.character, motion, steps)
    if feasible:
        from scenegraph.nio import feasible_target, joint_rms_deg, resample

        res = feasible_target(clip.character, resample(motion), steps, max_iter=PROJECTION_ITER)
        # a projection stopped early can be far from the clip (08_02 at 400 iterations: 15.7°
        # away, converged at 544: 0.56°), so it must stay near the clip; and it must hold C.
        # It need not reach IPOPT's tolerance: with the dense dynamics the projection of 07_01
        # 64:201 stalls there (objective 40.3892 at 150 iterations, 40.3884 at 400 and still
        # not converged at 1500 — 1145 s; C to 1e-8 m, 2.15° from the reconstruction, measured)
        dev = joint_rms_deg(res.motion, motion)
        viol = max(res.violations.values(), default=0.0)
        held = viol <= 1e-3 if res.success else (res.status.startswith("Maximum_Iterations") and viol <= 1e-5)
        if not held or dev > 3.0:
            raise InputError(f"{path} frames {frames[0]}:{frames[1]}: the reconstruction cannot be moved onto "
                             f"its footsteps ({res.summary()}; {dev:.1f}° RMS from the reconstruction)")
        motion = res.motion
    return clip.character, motion, steps, clip


def save_learned(res, out, clip_name, frames: tuple[int, int] | None, body: str, resynth: dict | None = None,
                 resynth_warm: dict | None = None, resynth_example: dict | None = None) -> None:
    """Write a learned style with its provenance (and, when measured, the re-synthesis RMS).
    ``clip_name``: the clip's file name (with ``frames``), or a list of (file name, frames) of
    several clips (``frames`` None)."""
    from scenegraph.model.style import Provenance, save_style

    prov = res.style.provenance.model_dump() if res.style.provenance else {}
    if resynth:  # measured by tests/benchmarks/bench_nio.py (NIO.resynthesize, 300 iterations)
        prov["resynth_rms_deg"] = dict(resynth)
    if resynth_warm:
        prov["resynth_warm_rms_deg"] = dict(resynth_warm)
    if resynth_example:  # nio.resynthesize_from_example: the paper's initial motion
        prov["resynth_example_rms_deg"] = dict(resynth_example)
    style = res.style.model_copy(update={"provenance": Provenance(**prov)})
    if isinstance(clip_name, str):
        clip_name = [(clip_name, frames)]
    if len(clip_name) == 1:
        (name, fr), = clip_name
        clips = f"{name} --frames {fr[0]}:{fr[1]}"
    else:
        clips = " ".join(f"{name}:{fr[0]}:{fr[1]}" for name, fr in clip_name)
    save_style(style, out, header=f"# learned by: compose learn {clips} "
                                  f"--body {body}{_option_flags(prov)} -o {Path(out).name}\n")


def _option_flags(prov: dict) -> str:
    """The `compose learn` options a provenance records, as command-line flags: the non-default
    NIO options, and the estimator's (prior, ties, contacts) always."""
    from scenegraph.model.body import N_JOINT

    flags = ""
    if str(prov.get("counterexamples", "")).startswith("spacetime"):
        flags += " --counterexamples ipopt"
    if prov.get("hessian"):
        flags += f" --hessian {prov['hessian']}"
    if prov.get("alpha_floor"):
        flags += f" --alpha-floor {prov['alpha_floor'] * N_JOINT:g}"
    # the estimator's options always (their defaults changed in round 14: a provenance without
    # them was learned with no prior, no ties and central contacts)
    w, tie = float(prov.get("alpha_prior") or 0.0), prov.get("tie") or "none"
    flags += f" --alpha-prior {w:g}"
    if prov.get("alpha_ref"):
        flags += f" --alpha-ref {prov['alpha_ref']}"
    elif w > 0 or tie != "none":
        flags += " --alpha-ref uniform"
    flags += f" --spring-prior {float(prov.get('spring_prior') or 0.0):g} --tie {tie}"
    flags += f" --contacts {prov.get('contacts') or 'central'}"
    return flags


def learn_from_bvh(path, frames: tuple[int, int], body: str = "adult_male", out=None, name=None,
                   progress=None, onesided: bool = False, **run_kw):
    """Learn a style from frames [A, B) of one BVH clip: :func:`learn_from_clips` with one clip."""
    return learn_from_clips([(path, frames)], body, out, name, progress, onesided, **run_kw)


def learn_from_clips(specs, body: str = "adult_male", out=None, name=None, progress=None, onesided: bool = False,
                     **run_kw):
    """Learn one style from the (path, (A, B)) clips ``specs`` of one person (the first clip's
    character — its stature and mass — for all of them); returns (result, (character, X_T,
    footsteps, clip) of the first clip).  Writes ``out`` when given."""
    from scenegraph.nio import learn_multi

    targets, first = [], None
    for path, frames in specs:
        kw = {} if first is None else {"height": first[0].height, "mass": first[0].total_mass}
        ch, motion, steps, clip = clip_target(path, frames, body, onesided=onesided, **kw)
        first = first or (ch, motion, steps, clip)
        targets.append((motion, steps))
    names = [Path(p).name for p, _ in specs]
    ranges = [f"{a}:{b}" for _, (a, b) in specs]
    res = learn_multi(first[0], targets, name=name or Path(out or specs[0][0]).stem, clip=names, frames=ranges,
                      body=body, callback=progress, **run_kw)
    if onesided:  # the provenance records the contact rule (evaluate-style and the header read it)
        from scenegraph.model.style import Provenance

        prov = {**res.style.provenance.model_dump(), "contacts": "onesided"}
        from dataclasses import replace as _replace

        res = _replace(res, style=res.style.model_copy(update={"provenance": Provenance(**prov)}))
    if out is not None:
        save_learned(res, out, [(n, fr) for n, (_, fr) in zip(names, specs)], None, body)
    return res, first


def _cmd_learn(args) -> int:
    from scenegraph.model.body import N_JOINT

    from schedules.cli.preview import output_path

    specs = clip_specs(args.clip, args.frames)
    # every argument is checked before the clips are read and NIO runs for minutes
    if args.alpha_prior < 0:
        raise InputError(f"--alpha-prior {args.alpha_prior}: must be >= 0")
    if args.spring_prior < 0:
        raise InputError(f"--spring-prior {args.spring_prior}: must be >= 0")
    if args.alpha_ref is None:
        args.alpha_ref = DEFAULTS["alpha_ref"] if args.alpha_prior > 0 or args.tie != "none" else "uniform"
    elif args.alpha_ref != "uniform" and args.alpha_prior == 0 and args.tie == "none":
        raise InputError(f"--alpha-ref {args.alpha_ref}: has an effect only with --alpha-prior W > 0 or a --tie")
    if not 0.0 <= args.alpha_floor <= 1.0:
        raise InputError(f"--alpha-floor {args.alpha_floor}: must lie in [0, 1] (units of 1/M; Σα = 1)")
    if args.max_iter < 1:
        raise InputError(f"--max-iter {args.max_iter}: must be at least 1")
    if len(specs) > 1 and args.counterexamples != "local":
        raise InputError("several clips learn with local counterexamples only (drop --counterexamples ipopt)")
    out = output_path(args.output, Path(specs[0][0]).with_suffix(".yaml"), "-o/--output", (".yaml", ".yml"))
    for path, _ in specs:
        clip = Path(path)
        if not clip.is_file():
            raise InputError(f"no such clip file: {path}" if not clip.exists() else f"{path} is not a file")
        if out.resolve() == clip.resolve():
            raise InputError(f"-o/--output {out}: is the clip {path} itself")
    t0 = time.perf_counter()

    def progress(rec):
        print(f"  iter {rec.iteration:3d}  G = {rec.G:.6g}  D = {rec.D:.3g}  "
              f"E(X_T) = {rec.E_target:.6g}  E(X_S) = {rec.E_counter:.6g}  beta = {rec.beta:g}  "
              f"[{rec.seconds:.0f} s]", file=sys.stderr, flush=True)

    what = ", ".join(f"{p} frames {a}:{b}" for p, (a, b) in specs)
    print(f"compose learn: {what}, body {args.body}", file=sys.stderr, flush=True)
    try:
        res, _ = learn_from_clips(specs, args.body, args.output, progress=progress,
                                max_iter=args.max_iter, local=args.counterexamples == "local",
                                hessian=args.hessian, alpha_floor=args.alpha_floor / N_JOINT,
                                prior_weight=args.alpha_prior, tie=args.tie, alpha_ref=args.alpha_ref,
                                spring_prior=args.spring_prior, onesided=args.contacts == "onesided")
    except ComposeError:
        raise
    except (ValueError, OSError) as exc:
        raise InputError(f"{', '.join(p for p, _ in specs)}: {exc}") from None
    print(f"compose learn: G {res.g_initial:.6g} -> {res.g_final:.6g} in {res.iterations} iterations "
          f"({res.stop_reason}), {time.perf_counter() - t0:.0f} s; wrote {args.output}", file=sys.stderr)
    return 0


def register(sub) -> None:
    p = sub.add_parser("learn", help="learn a physical style from BVH clips (Nonlinear Inverse Optimization)",
                       description="Learn a physical style θ from frames A:B (B exclusive) of a BVH clip, or "
                                   "from several clips (or segments) of one person given as PATH:A:B "
                                   "(one NIO: the sum of the clips' G), and write it as a style YAML file "
                                   "with its provenance.")
    p.add_argument("clip", metavar="CLIP.bvh[:A:B]", nargs="+",
                   help="a clip with --frames A:B, or one or more PATH:A:B (the first gives the example poses)")
    p.add_argument("--frames", default=None, metavar="A:B", help="source frames A to B (exclusive) of a single clip")
    p.add_argument("--body", default="adult_male", choices=("adult_male", "adult_female", "child"),
                   help="body preset (default adult_male)")
    p.add_argument("-o", "--output", required=True, metavar="STYLE.yaml")
    p.add_argument("--max-iter", type=int, default=200, help="safety limit on NIO iterations (default 200)")
    p.add_argument("--counterexamples", choices=("local", "ipopt"), default="local",
                   help="local: one Gauss-Newton step from X_T (default); ipopt: spacetime solves")
    p.add_argument("--hessian", choices=("gauss_newton", "exact"), default="gauss_newton",
                   help="Hessian of the IPOPT counterexample solves (default gauss_newton)")
    p.add_argument("--alpha-floor", type=float, default=0.0, metavar="F",
                   help="every muscle weight alpha_j >= F/M (default 0: a muscle may cost nothing)")
    # defaults: the estimator that won on both validation trials of issue #18 (round 13,
    # docs/learning.md); the paper's plain NIO is --alpha-prior 0 --spring-prior 0 --tie none
    p.add_argument("--alpha-prior", type=float, default=DEFAULTS["alpha_prior"], metavar="W",
                   help="log-normal prior on alpha around its reference, weight W in units of the initial G "
                        f"(default {DEFAULTS['alpha_prior']:g}; 0: none)")
    p.add_argument("--alpha-ref", choices=("uniform", "strength"), default=None,
                   help="centre of the alpha prior and initial alpha: uniform 1/M or strength (proportional to "
                        "1/strength^2 of each joint; the default when a prior or a tie is on, else uniform)")
    p.add_argument("--spring-prior", type=float, default=DEFAULTS["spring_prior"], metavar="W",
                   help="quadratic prior on the springs around their Eq. 22 values, weight W in units of the "
                        f"initial G (default {DEFAULTS['spring_prior']:g}; 0: none)")
    p.add_argument("--tie", choices=("none", "lr", "groups", "coarse"), default=DEFAULTS["tie"],
                   help="hold equal: lr = alpha and springs of left/right DOF pairs; groups = lr plus one alpha per "
                        "joint group; coarse = groups plus one factor per group on the springs (59 free numbers) "
                        f"(default {DEFAULTS['tie']})")
    p.add_argument("--contacts", choices=("central", "onesided"), default=DEFAULTS["contacts"],
                   help="contact detection on the clip: one-sided speeds widened by half a frame (default; what "
                        "evaluate-style uses), or central speed differences (the styles shipped before round 14)")
    p.set_defaults(func=_cmd_learn)
