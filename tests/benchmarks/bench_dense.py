"""Benchmark (issue #15 item 2): compose's own equations of motion at 120 Hz, from a run folder.

    python tests/benchmarks/bench_dense.py SCENARIO RUN_DIR [--rate 120] [--detail]

Reads the run folder's committed checkpoints (``compose run SCENARIO --run-dir RUN_DIR``),
takes each character's last motion, footsteps and contact forces (windowed steps merged as
the executor does) and evaluates the root residual with
:func:`scenegraph.model.dense_audit.dense_residual` at ``--rate`` Hz over the whole motion.
It splits the frames into: *transition* (within 40 ms of a contact handle's touch-down or
lift-off), *flight* (no handle planted), *shoe* (a heel within 5 mm of its shoe spring's rest
height outside a planted heel interval) and *stance* (the rest), and prints the worst and
RMS residual (body weights) of each.  Last line::

    scene=<name> dense_residual_max_bw=<float> dense_residual_rms_bw=<float> flight_max_bw=<float> transition_max_bw=<float> stance_max_bw=<float> energy=<float> dense_energy=<float>

``energy`` is the solver's own (its quadrature: on its grid); ``dense_energy`` is ∫ Σ α Q_m² dt
by the trapezoid rule at ``--rate`` Hz with the forces read the same way — comparable
between transcriptions.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def final_states(scenario: str, run_dir: Path) -> tuple[object, dict]:
    """(scene, {character: (motion, footsteps, contact forces, energy)}) of a run folder."""
    from scenarios.loader import load_scenario
    from scenegraph.model.motion import Motion
    from scenegraph.world.scene import build_scene
    from schedules.execution.checkpoints import Manifest, checkpoint_names, read_checkpoint
    from schedules.execution.executor import _merge_contacts

    scene = build_scene(load_scenario(scenario))
    man = Manifest.load(run_dir)
    out: dict = {}
    for name in checkpoint_names(run_dir):
        data = read_checkpoint(man, run_dir, name)
        if data is None or "characters" not in data:
            continue
        for who, c in data["characters"].items():
            if "ctrl" not in c or not isinstance(c.get("contact_forces"), dict):
                continue
            old = out.get(who)
            forces = _merge_contacts(old[2] if old else None, c["contact_forces"], c.get("window"))
            out[who] = (Motion(np.asarray(c["ctrl"], float), np.asarray(c["warp"], float)),
                        tuple(c["footsteps"]), forces, float(c.get("energy", np.nan)))
    return scene, out


def classify(ch, footsteps, times, ground, window=0.04) -> dict[str, np.ndarray]:
    from scenegraph.model.footsteps import contact_points
    planted = np.zeros(len(times), bool)
    near = np.zeros(len(times), bool)
    for step in footsteps:
        for _, (ta, tb), _ in contact_points(ch, step, None, ground):
            planted |= (times >= ta - 1e-9) & (times <= tb + 1e-9)
            for te in (ta, tb):
                near |= np.abs(times - te) <= window
    return {"flight": ~planted, "transition": planted & near, "stance": planted & ~near}


def main(argv=None) -> int:
    from scenegraph.model.dense_audit import dense_residual
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario")
    ap.add_argument("run_dir")
    ap.add_argument("--rate", type=float, default=120.0)
    ap.add_argument("--detail", action="store_true", help="print the 12 worst frames")
    args = ap.parse_args(argv)
    scene, states = final_states(args.scenario, Path(args.run_dir))
    worst = {"all": 0.0, "flight": 0.0, "transition": 0.0, "stance": 0.0}
    rms2, n, energy, dense_energy = 0.0, 0, 0.0, 0.0
    for c in scene.characters:
        if c.name not in states:
            print(f"{c.name}: no solved state in {args.run_dir}")
            continue
        motion, steps, forces, e = states[c.name]
        energy += e
        d = dense_residual(c.character, c.style, motion, steps, forces, args.rate, scene.ground)
        dense_energy += d.energy
        parts = classify(c.character, steps, d.times, scene.ground)
        line = [f"{c.name}: max {d.force_max_bw:.3f} bw at {d.worst_time():.3f} s, rms {d.force_rms_bw:.3f}, "
                f"moment max {d.moment_max_bw_m:.3f} bw·m"]
        for k, sel in parts.items():
            if sel.any():
                line.append(f"{k} ({sel.sum()} frames) max {d.force_bw[sel].max():.3f} rms "
                            f"{np.sqrt(np.mean(d.force_bw[sel] ** 2)):.3f}")
                worst[k] = max(worst[k], float(d.force_bw[sel].max()))
        print("; ".join(line))
        if args.detail:
            for i in np.argsort(-d.force_bw)[:12]:
                kind = next(k for k, sel in parts.items() if sel[i])
                print(f"   t={d.times[i]:.3f} {kind:10s} |F0|={d.force_bw[i]:.3f} bw  Q0={np.round(d.root[:, i], 1)}")
        worst["all"] = max(worst["all"], d.force_max_bw)
        rms2 += float(np.sum(d.force_bw ** 2))
        n += len(d.force_bw)
    print(f"scene={args.scenario} dense_residual_max_bw={worst['all']:.4g} "
          f"dense_residual_rms_bw={np.sqrt(rms2 / max(n, 1)):.4g} flight_max_bw={worst['flight']:.4g} "
          f"transition_max_bw={worst['transition']:.4g} stance_max_bw={worst['stance']:.4g} energy={energy:.4g} "
          f"dense_energy={dense_energy:.4g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
