"""``audit_stage``: every check on one stage, per character (or group) and frame, with a
summary and a verdict against documented tolerances (docs/audit.md).

A **system** is what the momentum checks look at: each character on its own, or a group of
characters taken together (``groups``; "auto" joins characters whose meshes come within
``contact_tol`` of each other in any frame), so that forces between them — held hands, a
carried partner — cancel.  Penetration and stance sliding are per character.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from scenarios.errors import InputError

from scenegraph.stage_audit.checks import contact_support, heights_above_ground, overlaps, stance_runs
from scenegraph.stage_audit.momenta import G, momenta
from scenegraph.stage_audit.reader import StageSamples, read_stage

__all__ = ["AuditSettings", "Tolerances", "audit_stage", "audit_samples", "SUMMARY_KEYS", "summary_line"]


@dataclass(frozen=True)
class Tolerances:
    """What a stage must meet to pass (the fidelity issue's goals)."""

    penetration_mm: float = 2.0  # deepest vertex below the ground
    stance_slide_mm: float = 5.0  # horizontal travel of a vertex during one stance
    flight_wrench_rms_bw: float = 0.05  # RMS external force needed in free flight
    flight_torque_rms_bw_rg: float = 0.05  # RMS torque about the COM in free flight, bw × gyration radius
    cop_outside_cm: float = 1.0  # centre of pressure outside the support polygon
    dense_residual_bw: float = 0.05  # force no contact could supply, any frame
    interpenetration_cm: float = 0.5  # bodies of different characters overlapping


@dataclass(frozen=True)
class AuditSettings:
    """``contact_tol`` m: a vertex this close to the ground touches it; ``min_stance`` s: a
    shorter touch is a scuff, not a stance; ``mu``: Coulomb friction (compose's 0.8);
    ``min_normal_bw``: below this normal force the centre of pressure and friction use are
    not computed (finite-difference noise); ``groups``: tuples of character names, or
    ("auto",); ``allowed_contacts``: overlap patterns 'charA/meshA~charB/meshB'."""

    contact_tol: float = 0.005
    min_stance: float = 0.05
    mu: float = 0.8
    min_normal_bw: float = 0.05
    groups: tuple = ()
    allowed_contacts: tuple[str, ...] = ()
    tolerances: Tolerances = field(default_factory=Tolerances)


SUMMARY_KEYS = ("penetration_max_mm", "stance_slide_max_mm", "flight_wrench_rms_bw", "cop_outside_max_cm",
                "dense_residual_max_bw", "interpenetration_max_cm")


def summary_line(rep: dict) -> str:
    """One line of an audit report: verdict, frames, fps and the summary figures."""
    s = rep["summary"]
    return (f"audit: {rep['verdict']} frames={rep['frames']} fps={rep['fps']:g} "
            + " ".join(f"{k}={float(s[k]):.4g}" for k in SUMMARY_KEYS))


def _r(x, nd=4):
    if x is None:
        return None
    x = float(x)
    return None if not math.isfinite(x) else round(x, nd)


def _groups(samples: StageSamples, settings: AuditSettings, pairs) -> list[tuple[str, ...]]:
    names = [c.name for c in samples.characters]
    if settings.groups == ("auto",) or "auto" in settings.groups:
        parent = {n: n for n in names}

        def find(x):
            while parent[x] != x:
                x = parent[x]
            return x
        for p in pairs:
            if p.near.any():
                parent[find(p.a)] = find(p.b)
        comp: dict[str, list[str]] = {}
        for n in names:
            comp.setdefault(find(n), []).append(n)
        return [tuple(v) for v in comp.values()]
    used, out = set(), []
    for g in settings.groups:
        g = tuple(g)
        for n in g:
            if n not in names:
                raise InputError(f"--group: no character {n!r} in {samples.path} (characters: {', '.join(names)})")
            if n in used:
                raise InputError(f"--group: character {n!r} is in two groups")
            used.add(n)
        out.append(g)
    return out + [(n,) for n in names if n not in used]


def audit_samples(samples: StageSamples, settings: AuditSettings = AuditSettings()) -> dict:
    """The audit report (a JSON-ready dict) of sampled stage geometry."""
    tol = settings.tolerances
    dt = 1.0 / samples.fps
    T = len(samples.times)
    chars = {c.name: c for c in samples.characters}
    allowed = tuple(settings.allowed_contacts) + tuple(samples.allowed_contacts)
    pairs = overlaps(samples.characters, settings.contact_tol, allowed)
    mom = {n: momenta(c.meshes.points, c.meshes.tris, c.meshes.tri_mesh, c.meshes.vert_mesh, c.meshes.density, dt)
           for n, c in chars.items()}
    heights = {n: heights_above_ground(c.meshes.points, samples.ground) for n, c in chars.items()}
    near = {n: np.zeros(T, bool) for n in chars}
    for p in pairs:
        near[p.a] |= p.near
        near[p.b] |= p.near
    min_frames = max(2, int(math.ceil(settings.min_stance * samples.fps - 1e-9)))

    report_chars = {}
    for n, c in chars.items():
        h = heights[n]
        pen = np.maximum(0.0, -h.min(axis=1))
        stances, scuffs = stance_runs(c.meshes.points, h, settings.contact_tol, min_frames, dt)
        worst = max(stances, key=lambda s: s[3]) if stances else None
        masses = {nm: _r(m, 4) for nm, m in zip(c.meshes.names, c.meshes.mass)}
        report_chars[n] = {
            "mass_kg": _r(c.mass, 4),
            "mesh_mass_kg": masses,
            "mass_sources": sorted(set(c.meshes.mass_source)),
            "massless_meshes": list(c.meshes.massless),
            "penetration_max_mm": _r(pen.max() * 1000, 3),
            "penetration_worst_time": _r(samples.times[int(np.argmax(pen))], 4),
            "penetration_worst_mesh": c.meshes.names[int(c.meshes.vert_mesh[int(np.argmin(h[int(np.argmax(pen))]))])],
            "stances": len(stances),
            "stance_slide_max_mm": _r((worst[3] if worst else 0.0) * 1000, 3),
            "stance_slide_worst": None if not worst else {
                "mesh": c.meshes.names[int(c.meshes.vert_mesh[worst[0]])], "vertex": worst[0],
                "t0": _r(samples.times[worst[1]]), "t1": _r(samples.times[worst[2]])},
            "scuffs": len(scuffs),
            "scuff_speed_max_mps": _r(max((s[3] for s in scuffs), default=0.0), 3),
            "frames": {"penetration_mm": [_r(x * 1000, 3) for x in pen]},
        }

    systems = {}
    for g in _groups(samples, settings, pairs):
        M = mom[g[0]]
        for n in g[1:]:
            M = M + mom[n]
        mass = float(np.nanmedian(M.mass))
        bw = mass * G
        pts = np.concatenate([chars[n].meshes.points for n in g], axis=1)
        hh = np.concatenate([heights[n] for n in g], axis=1)
        incontact = (hh < settings.contact_tol).any(axis=1)
        touching = np.zeros(T, bool)
        for p in pairs:  # touching a character outside the group
            if (p.a in g) != (p.b in g):
                touching |= p.near
        pad = np.convolve(incontact.astype(int), np.ones(3, int), mode="same") > 0
        free = ~pad & ~touching
        valid = np.all(np.isfinite(M.force), axis=1)
        free &= valid
        fr = {k: [] for k in ("t", "contact", "free_flight", "force_bw", "torque_com_bw_m", "cop", "cop_outside_cm",
                              "cop_moment_outside_bw_m", "friction_use", "residual_bw")}
        cop_out, resid, fric = [], [], []
        worst_cop = None  # (distance cm, t, normal bw, moment bw m) of the frame farthest outside
        for k in range(T):
            if not valid[k]:
                continue
            F, tO = M.force[k], M.torque_origin[k]
            fr["t"].append(_r(samples.times[k], 5))
            fr["contact"].append(bool(incontact[k]))
            fr["free_flight"].append(bool(free[k]))
            fr["force_bw"].append([_r(x / bw, 6) for x in F])
            fr["torque_com_bw_m"].append([_r(x / bw, 6) for x in M.torque_com[k]])
            cop, out, cmom, use, res = None, None, None, None, None
            if incontact[k]:
                sel = hh[k] < settings.contact_tol
                sf = contact_support(F, tO, pts[k, sel], samples.ground, settings.mu, settings.min_normal_bw * bw)
                cop = None if sf.cop is None else [_r(x) for x in sf.cop]
                out = None if sf.cop is None else sf.outside * 100
                cmom = None if sf.cop is None else sf.moment_outside / bw
                use = sf.friction_use
                res = sf.cone_excess / bw
            elif free[k]:
                res = float(np.linalg.norm(F)) / bw
            fr["cop"].append(cop)
            fr["cop_outside_cm"].append(_r(out, 3))
            fr["cop_moment_outside_bw_m"].append(_r(cmom, 6))
            fr["friction_use"].append(_r(use, 3))
            fr["residual_bw"].append(_r(res))
            if out is not None:
                cop_out.append(out)
                if worst_cop is None or out > worst_cop[0]:
                    worst_cop = (out, samples.times[k], sf.normal_force / bw, cmom)
            if res is not None:
                resid.append(res)
            if use is not None and math.isfinite(use):
                fric.append(use)
        flight_F = np.linalg.norm(M.force[free], axis=1) / bw if free.any() else np.zeros(0)
        rg = float(np.nanmedian(M.gyration_radius))
        flight_tau = np.linalg.norm(M.torque_com[free], axis=1) / (bw * rg) if free.any() else np.zeros(0)
        Hc = M.ang_momentum_com[free]
        sysrep = {
            "characters": list(g), "mass_kg": _r(mass), "body_weight_N": _r(bw, 2),
            "frames_audited": int(valid.sum()), "contact_frames": int((incontact & valid).sum()),
            "free_flight_frames": int(free.sum()), "coupled_frames": int((touching & ~incontact & valid).sum()),
            "flight_wrench_rms_bw": _r(np.sqrt(np.mean(flight_F ** 2)) if len(flight_F) else 0.0),
            "flight_wrench_max_bw": _r(flight_F.max() if len(flight_F) else 0.0),
            "gyration_radius_m": _r(rg, 6), "flight_torque_rms_bw_rg": _r(np.sqrt(np.mean(flight_tau ** 2)) if len(flight_tau) else 0.0),
            "flight_ang_momentum_drift": _r(float(np.linalg.norm(Hc.max(0) - Hc.min(0))) if len(Hc) else 0.0),
            "cop_outside_max_cm": _r(max(cop_out, default=0.0), 3),
            "cop_outside_worst": None if worst_cop is None else {
                "t": _r(worst_cop[1], 5), "normal_bw": _r(worst_cop[2]), "moment_bw_m": _r(worst_cop[3], 6)},
            "cop_moment_outside_max_bw_m": _r(max((m for m in fr["cop_moment_outside_bw_m"] if m is not None),
                                                  default=0.0), 6),
            "friction_use_max": _r(max(fric, default=0.0), 3),
            "dense_residual_max_bw": _r(max(resid, default=0.0)),
            "frames": fr,
        }
        forces = [f for f in samples.debug_forces if f[0] in g]
        if forces:  # compose's own contact/coupling forces on the stage: the rest is root residual
            Fs = sum(f[3] for f in forces)
            r = np.linalg.norm(M.force - Fs, axis=1)[valid] / bw
            sysrep["residual_vs_stage_forces_max_bw"] = _r(r.max(), 6)
            sysrep["residual_vs_stage_forces_rms_bw"] = _r(np.sqrt(np.mean(r ** 2)))
        systems["+".join(g)] = sysrep

    pair_rep = {f"{p.a}~{p.b}": {"overlap_max_cm": _r(p.depth.max() * 100, 3),
                                 "asked_for_overlap_max_cm": _r(p.depth_allowed.max() * 100, 3),
                                 "worst_time": _r(samples.times[int(np.argmax(p.depth))]),
                                 "worst_meshes": p.where[int(np.argmax(p.depth))] or None,
                                 "near_frames": int(p.near.sum())} for p in pairs}
    summary = {
        "penetration_max_mm": max(r["penetration_max_mm"] for r in report_chars.values()),
        "stance_slide_max_mm": max(r["stance_slide_max_mm"] for r in report_chars.values()),
        "flight_wrench_rms_bw": max(s["flight_wrench_rms_bw"] for s in systems.values()),
        "cop_outside_max_cm": max(s["cop_outside_max_cm"] for s in systems.values()),
        "cop_moment_outside_max_bw_m": max(s["cop_moment_outside_max_bw_m"] for s in systems.values()),
        "dense_residual_max_bw": max(s["dense_residual_max_bw"] for s in systems.values()),
        "interpenetration_max_cm": max((p["overlap_max_cm"] for p in pair_rep.values()), default=0.0),
        "friction_use_max": max(s["friction_use_max"] for s in systems.values()),
        "flight_torque_rms_bw_rg": max(s["flight_torque_rms_bw_rg"] for s in systems.values()),
        "free_flight_frames": sum(s["free_flight_frames"] for s in systems.values()),
        "residual_vs_stage_forces_max_bw": max((s["residual_vs_stage_forces_max_bw"] for s in systems.values()
                                                if "residual_vs_stage_forces_max_bw" in s), default=None),
        "mass_kg": {n: r["mass_kg"] for n, r in report_chars.items()},
    }
    limits = {"penetration_max_mm": tol.penetration_mm, "stance_slide_max_mm": tol.stance_slide_mm,
              "flight_wrench_rms_bw": tol.flight_wrench_rms_bw,
              "flight_torque_rms_bw_rg": tol.flight_torque_rms_bw_rg, "cop_outside_max_cm": tol.cop_outside_cm,
              "dense_residual_max_bw": tol.dense_residual_bw, "interpenetration_max_cm": tol.interpenetration_cm}
    failures = [f"{k} = {summary[k]:g} > {v:g}" for k, v in limits.items() if summary[k] > v]
    notes = []
    if samples.fps > samples.stage_fps * (1 + 1e-9):
        notes.append(f"audited at {samples.fps:g} fps, above the stage's {samples.stage_fps:g} time codes per second: "
                     "between samples the motion is UsdSkel's interpolation, and its accelerations are not physical")
    if samples.fps < 60:
        notes.append(f"audited at {samples.fps:g} fps: finite differences smooth impacts; 120 fps or more is advised")
    return {
        "stage": samples.path, "fps": samples.fps, "stage_fps": samples.stage_fps, "frames": len(samples.times),
        "t0": _r(samples.times[0], 5), "t1": _r(samples.times[-1], 5),
        "up_axis": samples.up_axis, "meters_per_unit": samples.meters_per_unit,
        "ground": "flat z = 0" if samples.ground.flat else f"z = 0 and {len(samples.ground.triangles)} ramp triangles",
        "settings": {**{k: v for k, v in asdict(settings).items() if k != "tolerances"},
                     "allowed_contacts": list(allowed)},
        "tolerances": limits,
        "characters": report_chars, "systems": systems, "pairs": pair_rep,
        "summary": summary, "passes": not failures, "verdict": "pass" if not failures else "fail",
        "failures": failures, "notes": notes,
    }


def audit_stage(path, fps: float | None = None, settings: AuditSettings = AuditSettings()) -> dict:
    """Read the stage at ``path`` (see :func:`~scenegraph.stage_audit.reader.read_stage`) at
    ``fps`` and audit it (see :func:`audit_samples`)."""
    return audit_samples(read_stage(path, fps), settings)
