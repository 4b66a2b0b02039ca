"""Where do the feet of a stage slide, and why (issue #15 item 3)?  Reads only the stage.

    python tests/benchmarks/where_feet_slide.py STAGE.usda [--fps 120] [--json OUT.json]

Per character and foot, every **stance** — a run of frames in which the foot's or toes' mesh
has a vertex within ``--tol`` (5 mm, the stage audit's contact band) of the ground, at least
``--min-stance`` s long — with its frames and the stage audit's own measure (the largest
horizontal travel of one contact vertex during its contact run), and the causes, each as an
equivalent travel in mm so they can be compared:

* **swivel**: the foot mesh's yaw (about the vertical) ranges over Δψ in the frames of the
  stance where the foot mesh itself rests on a patch of its sole (vertices in the band spanning
  at least 1 cm; not a rim point as the foot lands or leaves); its
  sole, L long, moves up to L·Δψ at the far end;
* **roll**: the foot's lateral axis tilts over a range Δφ about the long axis (same frames); the sole's
  edge (W/2 from its middle) moves W/2·Δφ;
* **glide**: while the foot lies flat (vertices of its rear and front quarters both in the
  band) its rigid translation at the sole's centre, largest horizontal distance from the
  flat phase's first frame;
* **skid**: in the frames around touch-down and lift-off, how far a vertex below 10 mm moves
  horizontally while it is in that band (largest over the vertices), and its largest speed;
* **toe dip**: the toes mesh's deepest point below the ground during the stance, and at which frame.

The foot's rotation each frame is fitted to its mesh's vertices (Kabsch against the first
frame: the mesh is rigid).  The cause with the largest figure is named first.  No solver
module is imported: this is a check of the stage, like ``compose audit``.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from scenegraph.stage_audit.checks import heights_above_ground  # noqa: E402
from scenegraph.stage_audit.reader import read_stage  # noqa: E402

SKID_BAND = 0.010  # m: the no-slip band of the solver (H_NO_SLIP), measured on the mesh
SKID_FRAMES = 6
PATCH = 0.01  # m: the foot rests on its sole when its vertices in the band span this much  # frames before a stance's first and after its last frame searched for a skid


def _rotations(P: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations of a rigid vertex set P (T, N, 3) relative to its first frame (Kabsch)."""
    A = P[0] - P[0].mean(axis=0)
    out = np.zeros((P.shape[0], 3, 3))
    for t in range(P.shape[0]):
        B = P[t] - P[t].mean(axis=0)
        U, _, Vt = np.linalg.svd(B.T @ A)
        d = np.sign(np.linalg.det(U @ Vt))
        out[t] = U @ np.diag([1.0, 1.0, d]) @ Vt
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.nonzero(d == 1)[0], np.nonzero(d == -1)[0] - 1))


def _foot_axes(P0: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Forward and lateral unit axes (world, first frame) of a foot mesh's sole and its length and width (m):
    the principal horizontal axis of its vertices (forward: the mesh's long axis)."""
    xy = P0[:, :2] - P0[:, :2].mean(axis=0)
    w, V = np.linalg.eigh(xy.T @ xy)
    f = np.r_[V[:, 1], 0.0]
    lat = np.r_[-f[1], f[0], 0.0]
    return f, lat, float(np.ptp(xy @ V[:, 1])), float(np.ptp(xy @ V[:, 0]))


def diagnose(stage, fps: float = 120.0, tol: float = 0.005, min_stance: float = 0.05) -> list[dict]:
    """One record per (character, foot, stance); see the module docstring."""
    smp = read_stage(stage, fps)
    dt = 1.0 / smp.fps
    out = []
    for c in smp.characters:
        M = c.meshes
        for side in ("l", "r"):
            idx = {kind: [i for i, n in enumerate(M.names) if n.endswith(f"{kind}_{side}")] for kind in ("foot", "toes")}
            if not idx["foot"]:
                continue
            vf = np.flatnonzero(np.isin(M.vert_mesh, idx["foot"]))
            vt = np.flatnonzero(np.isin(M.vert_mesh, idx["toes"]))
            vall = np.r_[vf, vt]
            Pf, Pa = M.points[:, vf], M.points[:, vall]
            hf = heights_above_ground(Pf, smp.ground)
            ha = heights_above_ground(Pa, smp.ground)
            ht = heights_above_ground(M.points[:, vt], smp.ground) if len(vt) else np.zeros((len(smp.times), 0))
            R = _rotations(Pf)
            f0, _, L, W = _foot_axes(Pf[int(np.argmax((hf < tol).sum(axis=1)))])  # length, width: flattest frame
            f0, _, _, _ = _foot_axes(Pf[0])
            along = (Pf[0, :, :2] - Pf[0, :, :2].mean(axis=0)) @ f0[:2]
            rear, front = along < np.quantile(along, 0.25), along > np.quantile(along, 0.75)
            down = (ha < tol).any(axis=1)
            for a, b in _runs(down):
                if (b - a + 1) * dt < min_stance:
                    continue
                # the stage audit's measure: a vertex's largest travel within its own contact run
                slide, worst = 0.0, None
                for j in range(ha.shape[1]):
                    for ra, rb in _runs(ha[a:b + 1, j] < tol):
                        xy = Pa[a + ra:a + rb + 1, j, :2]
                        d = float(np.linalg.norm(xy - xy[0], axis=1).max())
                        if d > slide:
                            slide, worst = d, (a + ra, a + rb)
                rec = {"character": c.name, "foot": side, "t0": round(float(smp.times[a]), 4),
                       "t1": round(float(smp.times[b]), 4), "frames": [int(a), int(b)],
                       "slide_mm": round(1e3 * slide, 2),
                       "slide_frames": [int(worst[0]), int(worst[1])] if worst else None}
                seg = slice(a, b + 1)
                # frames the foot rests on a patch of its sole (band vertices spanning >= PATCH), not
                # touching with a rim point as it lands or leaves (a rotation about that point slides nothing)
                on = [t for t in range(a, b + 1) if (hf[t] < tol).sum() >= 2
                      and np.ptp(Pf[t, hf[t] < tol, :2], axis=0).max() >= PATCH]
                dyaw = droll = 0.0
                if on:  # axes of the foot at its flattest frame (most vertices down), carried by the fitted rotations
                    ref = max(on, key=lambda t: int((hf[t] < tol).sum()))
                    f_r, l_r, _, _ = _foot_axes(Pf[ref])
                    rel = np.einsum("tij,kj->tik", R[on], R[ref])  # R_t R_ref^T
                    fwd = np.einsum("tij,j->ti", rel, f_r)
                    lat = np.einsum("tij,j->ti", rel, l_r)
                    dyaw = float(np.ptp(np.unwrap(np.arctan2(fwd[:, 1], fwd[:, 0]))))
                    droll = float(np.ptp(np.arcsin(np.clip(lat[:, 2], -1, 1))))
                flat = (hf[seg][:, rear] < tol).any(axis=1) & (hf[seg][:, front] < tol).any(axis=1)
                glide = 0.0
                for fa, fb in _runs(flat):
                    ctr = Pf[a + fa:a + fb + 1].mean(axis=1)[:, :2]
                    glide = max(glide, float(np.linalg.norm(ctr - ctr[0], axis=1).max()))
                skid, skid_speed, skid_frame = 0.0, 0.0, None
                for lo, hi in ((max(0, a - SKID_FRAMES), a + SKID_FRAMES), (b - SKID_FRAMES, min(len(smp.times) - 1, b + SKID_FRAMES))):
                    w = slice(max(lo, 0), hi + 1)
                    band = ha[w] < SKID_BAND
                    xy = Pa[w, :, :2]
                    for j in np.flatnonzero(band.any(axis=0)):
                        for ra, rb in _runs(band[:, j]):
                            if rb > ra:
                                tr = float(np.linalg.norm(xy[ra:rb + 1, j] - xy[ra, j], axis=1).max())
                                v = float(np.linalg.norm(np.diff(xy[ra:rb + 1, j], axis=0), axis=1).max()) / dt
                                if tr > skid:
                                    skid, skid_speed, skid_frame = tr, v, int(w.start + ra)
                dip = float(-ht[seg].min()) if ht.shape[1] else 0.0
                causes = {"swivel_mm": 1e3 * L * dyaw, "roll_mm": 1e3 * 0.5 * W * droll, "glide_mm": 1e3 * glide,
                          "skid_mm": 1e3 * skid, "toe_dip_mm": 1e3 * max(dip, 0.0)}
                rec.update({k: round(v, 2) for k, v in causes.items()})
                rec.update({"swivel_deg": round(math.degrees(dyaw), 2), "roll_deg": round(math.degrees(droll), 2),
                            "skid_speed_mps": round(skid_speed, 3), "skid_frame": skid_frame,
                            "toe_dip_frame": int(a + np.argmin(ht[seg].min(axis=1))) if ht.shape[1] else None,
                            "cause": max(causes, key=causes.get).replace("_mm", "")})
                out.append(rec)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stage")
    ap.add_argument("--fps", type=float, default=120.0)
    ap.add_argument("--tol", type=float, default=0.005, help="contact band (m)")
    ap.add_argument("--min-stance", type=float, default=0.05, help="shortest stance (s)")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    recs = diagnose(a.stage, a.fps, a.tol, a.min_stance)
    for r in recs:
        print(f"{r['character']} foot {r['foot']} frames {r['frames'][0]}-{r['frames'][1]} "
              f"({r['t0']:.3f}-{r['t1']:.3f} s): slide {r['slide_mm']:.2f} mm (frames {r['slide_frames']}); "
              f"cause {r['cause']}: swivel {r['swivel_mm']:.2f} mm ({r['swivel_deg']:.2f} deg) "
              f"roll {r['roll_mm']:.2f} mm ({r['roll_deg']:.2f} deg) glide {r['glide_mm']:.2f} mm "
              f"skid {r['skid_mm']:.2f} mm ({r['skid_speed_mps']:.2f} m/s at frame {r['skid_frame']}) "
              f"toe dip {r['toe_dip_mm']:.2f} mm (frame {r['toe_dip_frame']})")
    if a.json:
        Path(a.json).write_text(json.dumps(recs, indent=1) + "\n", encoding="utf-8")
    worst = max(recs, key=lambda r: r["slide_mm"]) if recs else None
    print(f"stances={len(recs)} slide_max_mm={worst['slide_mm'] if worst else 0:.2f} "
          f"worst_cause={worst['cause'] if worst else '-'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
