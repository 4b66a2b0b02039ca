"""The hook that runs ``compose audit`` on what ``compose run`` wrote (issue #15).

The stage audit reads only the stage.  It needs 120 Hz samples (finite differences of a
30 fps stage see UsdSkel's interpolation, not the motion), so the same scene is also
exported at 120 Hz into the run folder (``stage_120hz.usdc``), with compose's contact,
coupling and shoe-spring forces as debug force prims (``/World/Debug``), and that stage is audited: its
``residual_vs_stage_forces`` is what compose's own forces leave unexplained at 120 Hz.  Characters that touch are audited as one
system (``groups=auto``) and the contacts the scenario asks for — the hands of a coupling,
the tackler on its target — are listed in the stage (``allowedContacts``) so overlaps there
do not count.  The verdict joins the run report as ``stage_audit``; it does not change the
run's exit code (the run's own audit and goals do; see docs/audit.md).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["AUDIT_FPS", "allowed_contacts", "audit_run_stage", "force_arrows"]

AUDIT_FPS = 120.0


def allowed_contacts(scene) -> list[str]:
    """Overlap patterns ('charA/meshA~charB/meshB') of the contacts a scene asks for."""
    from scenegraph.export.usd import character_prim_name as prim
    out = []
    bodies = {c.name: c.character for c in scene.characters}
    for cpl in scene.couplings:
        hs = [(who, bodies[who].handle(h).body) for who, h in cpl.handles if who in bodies]
        for i, (a, ba) in enumerate(hs):
            for b, bb in hs[i + 1:]:
                if a != b:
                    out.append(f"{prim(a)}/{prim(a)}_{ba}~{prim(b)}/{prim(b)}_{bb}")
    for g in scene.goals:
        pair = g.touches()
        if pair is not None:
            out.append(f"{prim(pair[0])}/*~{prim(pair[1])}/*")
    return sorted(set(out))


def _interp_runs(times: np.ndarray, ht: np.ndarray, hf: np.ndarray) -> np.ndarray:
    """Forces (T, 3) at ``times``: linear between consecutive solver times of one contact
    run, zero elsewhere.  The solver reports a handle's force only at the collocation points
    where it is in contact, so a gap longer than 2.5 × the usual spacing (the median of the
    larger half of the gaps: the dense transcription's samples cluster near contact ends, and
    2.5 × the median of all gaps split real runs — a walk's heel lost 0.9 body weight on the
    stage) ends a run."""
    o = np.argsort(ht, kind="stable")
    ht, hf = ht[o], hf[o]
    V = np.zeros((len(times), 3))
    if len(ht) == 1:
        V[np.abs(times - ht[0]) < 1e-9] = hf[0]
        return V
    gaps = np.diff(ht)
    step = float(np.median(np.sort(gaps)[len(gaps) // 2:]))
    breaks = np.nonzero(gaps > 2.5 * step + 1e-9)[0]
    starts = np.r_[0, breaks + 1]
    ends = np.r_[breaks, len(ht) - 1]
    for a, b in zip(starts, ends):
        inside = (times >= ht[a] - 1e-9) & (times <= ht[b] + 1e-9)
        if b == a:
            V[inside] = hf[a]
            continue
        for d in range(3):
            V[inside, d] = np.interp(times[inside], ht[a:b + 1], hf[a:b + 1, d])
    return V


def force_arrows(scene, contact_forces: dict, fps: float) -> list:
    """compose's contact and coupling forces as debug force prims at every frame: each
    handle's force (N, world), linear between the solver's times within a contact run and
    zero outside (:func:`_interp_runs`), applied at the handle; and each heel's shoe spring
    (kind "shoe").  A style that changes over time is taken as the character's current one."""
    from scenegraph.model.kinematics import numeric_fk
    from scenegraph.export.usd import ForceArrow
    out = []
    for c in scene.characters:
        forces = (contact_forces or {}).get(c.name) or {}
        if not forces:
            continue
        times, q = c.motion.sample(fps)
        times = np.asarray(times, float)
        R, p = numeric_fk(c.character, np.asarray(q, float))
        names = [b.name for b in c.character.bodies]
        for handle, (ht, hf) in sorted(forces.items()):
            ht = np.asarray(ht, float)
            hf = np.asarray(hf, float).reshape(-1, 3)
            if len(ht) == 0:
                continue
            V = _interp_runs(times, ht, hf)
            h = c.character.handle(handle)
            bi = names.index(h.body)
            O = np.einsum("tij,j->ti", R[:, bi], np.asarray(h.point, float)) + p[:, bi]
            kind = "coupling" if handle.startswith("palm") else "contact"
            out.append(ForceArrow(f"{c.name}_{handle}", O, V, kind, 1e-3, float(times[0]), c.name))
        # the shoe springs (scenegraph/model/shoe.py): vertical, g(h̄ − h) k_shoe (h̄ − h) with h the
        # heel's height above the ground and g the smooth step, only in planned heel contact (gated)
        from scenegraph.model.shoe import shoe_force_numeric, shoe_gate
        k_shoe, h_rest = float(c.style.k_shoe), float(c.style.h_rest)
        gate = shoe_gate(c.character, c.footsteps, times, c.motion.start, c.motion.end, scene.ground)
        for i, side in enumerate(("l", "r")):
            h = c.character.handle(f"heel_{side}")
            bi = names.index(h.body)
            O = np.einsum("tij,j->ti", R[:, bi], np.asarray(h.point, float)) + p[:, bi]
            above = O[:, 2] - (0.0 if scene.ground.flat else scene.ground.height(O[:, 0], O[:, 1]))
            fz = gate[i] * shoe_force_numeric(above, k_shoe, h_rest)
            V = np.stack([np.zeros_like(fz), np.zeros_like(fz), fz], 1)
            out.append(ForceArrow(f"{c.name}_shoe_{side}", O, V, "shoe", 1e-3, float(times[0]), c.name))
    return out


def audit_run_stage(scene, out_path: Path, fps: float, run_dir: Path, metadata: dict, log=None,
                    contact_forces: dict | None = None) -> dict:
    """Audit the stage a run wrote (at 120 Hz, see the module doc); returns the report's
    ``stage_audit`` entry: the summary, the verdict, the failures and the audited file.  An
    error inside the audit is recorded (``error``) and printed, never raised: the run's
    stage and report are already good."""
    try:
        rep = _audit(scene, out_path, fps, run_dir, metadata, contact_forces)
    except Exception as exc:  # noqa: BLE001 - a finished run must still write its report
        if log is not None:
            print(f"compose: warning: stage audit not done: {exc}", file=log, flush=True)
        return {"passes": None, "verdict": "error", "error": f"{type(exc).__name__}: {exc}"}
    if log is not None:
        from scenegraph.stage_audit import summary_line
        print(f"compose: stage {summary_line(rep)}", file=log, flush=True)
    return {"stage": rep["stage"], "fps": AUDIT_FPS, "passes": rep["passes"], "verdict": rep["verdict"],
            "failures": rep["failures"], "summary": rep["summary"],
            "systems": {k: {kk: vv for kk, vv in v.items() if kk != "frames"} for k, v in rep["systems"].items()},
            "pairs": rep["pairs"]}


def _audit(scene, out_path, fps, run_dir, metadata, contact_forces) -> dict:
    from scenegraph.stage_audit import AuditSettings, audit_stage
    from scenegraph.export.usd import CharacterTrack, export_usd
    path = Path(out_path)
    arrows = force_arrows(scene, contact_forces, AUDIT_FPS)
    if abs(float(fps) - AUDIT_FPS) > 1e-9 or arrows:
        tracks = []
        for c in scene.characters:
            times, q = c.motion.sample(AUDIT_FPS)
            tracks.append(CharacterTrack(c.name, c.character, np.asarray(q, float), float(times[0])))
        path = export_usd(Path(run_dir) / "stage_120hz.usdc", tracks, AUDIT_FPS, metadata=metadata,
                          ground=scene.ground, debug_forces=arrows)
    return audit_stage(path, AUDIT_FPS, AuditSettings(groups=("auto",)))
