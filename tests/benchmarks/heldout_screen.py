"""Screen `compose learn` options on bench_heldout's two trials (issue #18, round 15), cheaper than the bench.

    CT=scene|plain python tests/benchmarks/heldout_screen.py OUT SPEC ...
    SPEC = name:alpha_prior:spring_prior:alpha_trust:multi[:speed,turn]   e.g. ref:0.1:0.1:reference:0

Each trial's training target (``clip_target``, one-sided contacts) is built once and shared by every
SPEC; each SPEC learns with ``learn_multi`` (strength reference, coarse ties, at most 200 iterations:
``compose learn``'s defaults but the named options; ``multi`` 1 adds bench_heldout's second segment)
and then runs ``evaluate_style`` for the learned variant only (its kinematic pre-solve comes with it):
the default variant does not depend on the learn, so it is the bench's.  SPEC ``dir:D`` evaluates the
styles a ``bench_heldout.py --out D`` run wrote (D/{speed,turn}_style.yaml), ``ship`` the shipped walk on
07_12.  Clips: bench_heldout's (``COMPOSE_SHARED_MOCAP`` or ../shared/mocap).
One ``RESULT`` line per variant and trial; reports (JSON, with per-DOF RMS) in OUT."""
import json, os, sys, time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_heldout import SECOND, TRIALS, _mocap_dir
from schedules.cli.evaluate import evaluate_style, _jsonable
from schedules.cli.learn import clip_target, save_learned
from scenegraph.nio import learn_multi
from scenegraph.model.style import Provenance
M = _mocap_dir(None)
TR = {name: (train, tf, test, sf, SECOND[name]) for name, train, tf, test, sf in TRIALS}
CT = os.environ.get("CT", "scene")
out = Path(sys.argv[1]); out.mkdir(parents=True, exist_ok=True)
targets = {}
def target(trial, second=False):
    key = (trial, second)
    if key not in targets:
        train, tf, _, _, sec = TR[trial]
        kw = {}
        if second:
            ch0 = target(trial)[0]
            kw = {"height": ch0.height, "mass": ch0.total_mass}
        t0 = time.perf_counter()
        targets[key] = clip_target(M / train, sec if second else tf, "adult_male", onesided=True, **kw)
        print(f"target {trial} {'second' if second else 'first'} {time.perf_counter()-t0:.0f} s", flush=True)
    return targets[key]
def evaluate(name, trial, sp, learn):
    _, _, test, sf, _ = TR[trial]
    t0 = time.perf_counter()
    rep = evaluate_style(sp, M / test, sf, "adult_male", 300, variants=("learned",), contact_terms=CT)
    rep.pop("_curves"); rep["learn"] = learn
    (out / f"{name}_{trial}.json").write_text(json.dumps(_jsonable(rep), indent=1))
    for k, v in rep["variants"].items():
        r = v["rms_deg"]; a = v["audit"]
        print(f"RESULT {name} {trial} {k:10s} all {r['all']:.2f} legs {r['legs']:.2f} trunk {r['pelvis_trunk']:.2f} arms {r['arms']:.2f} "
              f"t+a {r['trunk_arms']:.2f} root {v['root_path_m']['rms']:.3f} audit {a['passes']} {a['fails_on']} "
              f"dir {(v['direction'] or {}).get('score')} {v['solver']['status']} {v['solver']['iterations']} it "
              f"eval {time.perf_counter()-t0:.0f} s learn {learn}", flush=True)
for spec in sys.argv[2:]:
    name, *rest = spec.split(":")
    trials = ["speed", "turn"]
    if name.startswith("ship"):
        evaluate(name, "speed", Path(__file__).resolve().parents[2] / "scenarios" / "styles" / "walk.yaml", None)
        continue
    if name == "dir":  # the styles a bench_heldout.py --out D run learned
        for trial in trials:
            evaluate(f"dir_{Path(rest[0]).name}", trial, Path(rest[0]) / f"{trial}_style.yaml", None)
        continue
    prior, spring, trust, multi = float(rest[0]), float(rest[1]), rest[2], rest[3] == "1"
    if len(rest) > 4:
        trials = rest[4].split(",")
    for trial in trials:
        train, tf, _, _, sec = TR[trial]
        ch, motion, steps, clip = target(trial)
        clips, names, frames = [(motion, steps)], [train], [f"{tf[0]}:{tf[1]}"]
        if multi:
            _, m2, s2, _ = target(trial, True)
            clips.append((m2, s2)); names.append(train); frames.append(f"{sec[0]}:{sec[1]}")
        t0 = time.perf_counter()
        kw = {"alpha_trust": trust} if trust != "absolute" else {}
        res = learn_multi(ch, clips, name=f"{name}_{trial}", clip=names, frames=frames, body="adult_male",
                          max_iter=200, prior_weight=prior, alpha_ref="strength", spring_prior=spring, tie="coarse", **kw)
        prov = {**res.style.provenance.model_dump(), "contacts": "onesided"}
        res = replace(res, style=res.style.model_copy(update={"provenance": Provenance(**prov)}))
        sp = out / f"{name}_{trial}.yaml"
        save_learned(res, sp, [(n, tuple(map(int, f.split(":")))) for n, f in zip(names, frames)], None, "adult_male")
        learn = {"s": round(time.perf_counter() - t0, 1), "g": [res.g_initial, res.g_final], "it": res.iterations,
                 "stop": res.stop_reason}
        print(f"learned {name} {trial} {learn}", flush=True)
        evaluate(name, trial, sp, learn)
