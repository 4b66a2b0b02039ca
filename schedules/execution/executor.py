"""The executor: runs a Schedule over a Scene, step by step, with checkpoints.

Semantics (kept identical for every ``--jobs``):

* Steps run generation by generation (``Schedule.generations()``).  Every Step of a
  generation reads the same snapshot — the Scene after all earlier generations — and
  their results are merged into the Scene in the deterministic order of ``Step.sort_key``.
  With ``jobs > 1`` the Steps of a generation are solved in separate processes
  (``ProcessPoolExecutor``; IPOPT never runs in threads).  Steps of one generation for the
  same character (time-layered windows) only write the control points of their window.
* A Step frees each of its characters in turn (one ``Subproblem`` per character).  Before
  the first Step of a character the initial motion is made kinematically feasible once.
* Constraint times live in canonical time: after a Step that moved the timewarp, footstep
  times are carried along (world time of the same canonical time under the new warp).
* After every Step its result is written atomically to the run folder
  (``steps/NNN.npz`` + ``steps/NNN.json``, data only, their SHA-256 committed in
  ``manifest.json``; see :mod:`schedules.execution.checkpoints`), so ``resume=True`` replays finished
  Steps and solves only the rest.  A committed checkpoint that is truncated, edited or from
  another run is an error naming the file, never loaded.  The run folder is locked
  (:class:`~schedules.execution.checkpoints.RunLock`) while a run writes it.
* A Step fails if IPOPT does not report success or a hard constraint group is violated by
  more than ``VIOLATION_TOL``; the run stops with :class:`StepFailed` (exit code 1), naming
  the step and the violated groups.  Two exceptions: a *full* step that stopped unconverged
  (its iteration cap or a numerical breakdown, ``UNCONVERGED``) with every hard constraint
  satisfied is kept with a warning (unless ``fail_capped``),
  and a *timing* step that did not converge or violates a constraint is discarded (the full
  step after it starts from the state before it).  The run folder keeps every finished Step.
* SIGINT/SIGTERM stop the run at once (:mod:`schedules.execution.interrupts`): the interrupted step is
  not checkpointed, :class:`RunInterrupted` names it (exit code 130/143).  Any other exception
  raised inside a step (transcription, solver, a worker) becomes :class:`StepFailed`
  ``step N (<name>) failed: <ExcType>: <msg>`` (exit 1); its traceback is printed only under
  ``COMPOSE_DEBUG=1``.  Either way the finished steps' checkpoints are kept.

Test hook: ``COMPOSE_STOP_AFTER=N`` stops the process with exit code ``STOP_EXIT`` right
after the N-th newly solved Step has been written; ``COMPOSE_MAX_ITER=N`` caps IPOPT
iterations of every subproblem.
"""
from __future__ import annotations

import hashlib
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from scenarios.errors import ComposeError, InputError, Location
from scenegraph.model.footsteps import Footstep
from scenegraph.problem.joint import solve_joint
from scenegraph.model.motion import Motion
from scenegraph.problem import solve
from scenegraph.world.scene import Scene
from scenegraph.problem.synthesis import presolve_kinematics

from schedules.execution import interrupts
from schedules.execution.checkpoints import CheckpointError, Manifest, RunLock, checkpoint_names, read_checkpoint, write_checkpoint
from schedules.execution.lower import iteration_cap, leap_flights_of, lower, lower_joint
from schedules.plan.step import FULL, Schedule, Step
from schedules.execution.interrupts import RunInterrupted, catching_interrupts, crash_message, debug_enabled, format_traceback

__all__ = ["run_schedule", "StepFailed", "StepRecord", "RunResult", "STOP_EXIT", "VIOLATION_TOL",
           "run_fingerprint", "RunInterrupted"]

STOP_EXIT = 75  # exit code of the COMPOSE_STOP_AFTER test hook
VIOLATION_TOL = 1e-3  # m, m/s per kg for flight momenta (result.violation_scale): a hard group violated by more fails the step
FORMAT = 2  # run-folder format (1: pickled checkpoints, no longer read)
WARM_IPOPT = (("mu_strategy", "monotone"), ("mu_init", 1e-4))  # full steps warm-started from full steps
PRESOLVE_FLIGHTS = False  # True: the kinematic pre-solve holds the jump/hop flights' ballistic momentum rows too
# (lower.leap_flights_of).  Measured A/B, round 13 (docs/dynamic-motion.md): the full step then starts 2 kg·m/s
# instead of 290 from its flight rows, but the iteration count did not fall reliably — broad_jump 157 -> 103
# (E 2146 -> 1975, stage audit fail -> pass), twist_jump 101 -> 274 (E 1249 -> 698, shoulder line turns 113
# deg of 90: its slow test fails), a 1.5 m broad jump 127 -> 219 (E 3047 -> 3162), the sketched leap still capped at
# 300 (E 7465, audit fails) — and the pre-solve costs 13-32 s more CPU; off


class StepFailed(ComposeError):
    """A Step did not converge or violates hard constraints (exit code 1)."""

    exit_code = 1


@dataclass
class StepRecord:
    index: int
    id: str
    kind: str
    cycle: int
    characters: tuple[str, ...]
    status: str
    success: bool
    iterations: int
    seconds: float
    energy: float
    violations: dict
    presolve: dict | None = None
    per_character: dict = field(default_factory=dict)
    timing: dict = field(default_factory=dict)  # wall seconds by phase (problem.result.SolveTiming), summed

    def to_dict(self) -> dict:
        return {"index": self.index, "id": self.id, "kind": self.kind, "cycle": self.cycle,
                "characters": list(self.characters), "status": self.status, "success": self.success,
                "iterations": self.iterations, "seconds": round(self.seconds, 3), "energy": self.energy,
                "violations": self.violations, "presolve": self.presolve, "per_character": self.per_character,
                "timing": {k: round(v, 3) for k, v in self.timing.items()}}


@dataclass
class RunResult:
    scene: Scene
    records: list[StepRecord]
    seconds: float
    contact_forces: dict  # character -> contact forces of its last full step
    resumed: int = 0
    presolve: dict = field(default_factory=dict)  # character -> kinematic pre-solve summary


# --- helpers ----------------------------------------------------------------------------------

def run_fingerprint(scenario_text: str, schedule: Schedule) -> str:
    h = hashlib.sha256()
    h.update(scenario_text.encode())
    h.update(schedule.to_json().encode())
    h.update(str(FORMAT).encode())
    return h.hexdigest()[:20]


def _remap_footsteps(old: Motion, new: Motion, steps: tuple[Footstep, ...]) -> tuple[Footstep, ...]:
    if np.array_equal(np.asarray(old.warp), np.asarray(new.warp)):
        return steps
    out = []
    for f in steps:
        s = old.to_canonical([f.t0, f.t1])
        t = new.time(s)
        out.append(replace(f, t0=float(t[0]), t1=float(max(t[1], t[0] + 1e-3))))
    return tuple(out)


def _max_iter(default: int) -> int:
    v = os.environ.get("COMPOSE_MAX_ITER")
    return int(v) if v else default


def _hard_violations(viol: dict) -> dict:
    return {k: v for k, v in viol.items() if v > VIOLATION_TOL}


def solve_step(scene: Scene, step: Step, presolve: tuple[str, ...], contacts: dict | None = None) -> dict:
    """Solve one Step against ``scene`` (a snapshot); returns the data a checkpoint stores.

    Top-level and pure (given its arguments) so that it runs the same in a worker process.
    ``contacts`` (character → handle → (times, forces)): the contact forces so far, used as
    the λ warm start of decreasing-horizon (``role == "horizon"``) steps.
    """
    out: dict = {"step": step.id, "characters": {}}
    cur = scene
    pre_infos: dict = {}
    for who in step.characters:
        pre_info = None
        if who in presolve:
            st = cur.character(who)
            pre = presolve_kinematics(st.character, st.style, st.motion, st.footsteps, ground=cur.ground,
                                      flights=leap_flights_of(cur, who) if PRESOLVE_FLIGHTS else ())
            interrupts.check()
            pre_info = {"status": pre.status, "success": pre.success, "iterations": pre.iterations,
                        "seconds": pre.seconds}
            if pre.success:
                cur = cur.with_motion(who, pre.motion)
        pre_infos[who] = pre_info
        joint = lower_joint(cur, step)
        if joint is not None:  # a hard coupling: both characters in one NLP, solved below
            continue
        sp, mask = lower(cur, step, who, max_iter=_max_iter(iteration_cap(step)))
        if step.kind == FULL and contacts and contacts.get(who):
            # λ from the forces of the character's last full steps, not a constant share: a
            # decreasing-horizon window started at 100× its final objective and IPOPT left
            # for a far worse basin (tackler E 3.3e3 → 4.9e4; warm-started: 3.1e3, contact
            # within 0.3 mm); a walk_to_run window started at f = 7e4 and crept to its cap
            # and a warm start's barrier: monotone from μ = 1e-4 (the adaptive rule raised μ to
            # 0.1 at iteration 2 of a walk_to_run seam, which then ended in "Error in step
            # computation"; monotone: converged in 14 iterations)
            sp = replace(sp, contact_guess=contacts[who],
                         ipopt_options=sp.ipopt_options + WARM_IPOPT)
        res = solve(sp)
        interrupts.check()  # CasADi swallows a KeyboardInterrupt raised inside IPOPT's callbacks
        cur = _write_back(cur, who, sp, mask, res, pre_info, out)
    joint = lower_joint(cur, step)
    if joint is not None:
        (a, b), sps = joint.characters, {}
        for who in joint.characters:
            sps[who] = lower(cur, step, who, max_iter=_max_iter(iteration_cap(step)))
        jr = solve_joint(sps[a][0], sps[b][0], joint.coupling, names=(a, b))  # bodies apart between the two
        interrupts.check()
        for who, res in zip((a, b), jr.results):
            res = replace(res, violations={**res.violations, f"coupling:{joint.coupling.name}":
                                           float(jr.violations.get("coupling", 0.0))})
            cur = _write_back(cur, who, sps[who][0], sps[who][1], res, pre_infos.get(who), out)
    return out


def _write_back(cur: Scene, who: str, sp, mask, res, pre_info, out: dict) -> Scene:
    """Merge one character's Result into ``cur`` (only the window's control points) and record
    the checkpoint data of it in ``out``."""
    old = cur.character(who)
    motion = res.motion
    if mask is not None:  # write back only the window's control points
        ctrl = np.array(old.motion.ctrl, float)
        ctrl[mask] = np.asarray(res.motion.ctrl)[mask]
        motion = Motion(ctrl, np.asarray(res.motion.warp, float))
    free_flags = [f.free for f in old.footsteps]
    steps = tuple(replace(f, free=fl) for f, fl in zip(res.footsteps, free_flags))
    steps = _remap_footsteps(old.motion, motion, steps)
    out["characters"][who] = {
        "ctrl": np.asarray(motion.ctrl, float), "warp": np.asarray(motion.warp, float), "footsteps": steps,
        "mask": mask, "status": res.status, "success": bool(res.success), "iterations": res.iterations,
        "seconds": res.seconds + (pre_info["seconds"] if pre_info else 0.0), "energy": res.energy,
        "violations": {k: float(v) for k, v in res.violations.items()}, "presolve": pre_info,
        "contact_forces": res.contact_forces, "window": sp.window,
        "timing": res.timing.as_dict() if res.timing is not None else {},
    }
    return cur.with_motion(who, motion, steps)


def presolve_character(scene: Scene, who: str) -> dict:
    """Make a character's initial motion satisfy its footsteps and the ground (no dynamics)."""
    st = scene.character(who)
    pre = presolve_kinematics(st.character, st.style, st.motion, st.footsteps, ground=scene.ground,
                              flights=leap_flights_of(scene, who) if PRESOLVE_FLIGHTS else ())
    interrupts.check()
    return {"step": f"presolve:{who}", "ctrl": np.asarray(pre.motion.ctrl, float),
            "warp": np.asarray(pre.motion.warp, float), "status": pre.status, "success": bool(pre.success),
            "iterations": pre.iterations, "seconds": pre.seconds,
            "violations": {k: float(v) for k, v in pre.violations.items()}}


def _apply(scene: Scene, data: dict) -> Scene:
    for who, d in data["characters"].items():
        old = scene.character(who)
        ctrl = np.asarray(d["ctrl"], float)
        steps = tuple(d["footsteps"])
        if d["mask"] is not None:  # merge: only the window's control points ...
            merged = np.array(old.motion.ctrl, float)
            merged[d["mask"]] = ctrl[d["mask"]]
            ctrl = merged
            # ... and only the footprints this step could move (steps of one generation start
            # from the same snapshot: the others' footprints must not be reset to it)
            win = d.get("window")
            if win is not None and len(steps) == len(old.footsteps):
                steps = tuple(n if (n.t0 >= win[0] - 1e-6 and n.t1 <= win[1] + 1e-6) else o
                              for o, n in zip(old.footsteps, steps))
        scene = scene.with_motion(who, Motion(ctrl, np.asarray(d["warp"], float)), steps)
    return scene


def _merge_contacts(old: dict | None, new: dict, window) -> dict:
    """Contact forces of a windowed step replace the old ones inside its window only (outside
    it the motion is unchanged, and so are the forces that balance it)."""
    if window is None or not old:
        return new
    out = {}
    for h in sorted(set(old) | set(new)):
        ts, fs = [], []
        if h in old:
            t, f = old[h]
            keep = (t < window[0] - 1e-9) | (t > window[1] + 1e-9)
            ts.append(t[keep])
            fs.append(np.asarray(f).reshape(-1, 3)[keep])
        if h in new:  # a windowed subproblem reports forces at all its points: keep its window's
            t, f = np.asarray(new[h][0], float), np.asarray(new[h][1]).reshape(-1, 3)
            inside = (t >= window[0] - 1e-9) & (t <= window[1] + 1e-9)
            ts.append(t[inside])
            fs.append(f[inside])
        t, f = np.concatenate(ts), np.concatenate(fs)
        o = np.argsort(t, kind="stable")
        out[h] = (t[o], f[o])
    return out


def _record(index: int, step: Step, data: dict) -> StepRecord:
    chars = data["characters"]
    statuses = [c["status"] for c in chars.values()]
    viol: dict = {}
    for c in chars.values():
        for k, v in c["violations"].items():
            viol[k] = max(viol.get(k, 0.0), v)
    pre = {w: c["presolve"] for w, c in chars.items() if c["presolve"]}
    return StepRecord(index, step.id, step.kind, step.cycle, step.characters,
                      ("discarded: " if data.get("discarded") else "")
                      + (statuses[0] if len(set(statuses)) == 1 else ";".join(statuses)),
                      all(c["success"] for c in chars.values()), sum(c["iterations"] for c in chars.values()),
                      sum(c["seconds"] for c in chars.values()), float(sum(c["energy"] for c in chars.values())),
                      viol, pre or None,
                      {w: {k: c.get(k) for k in ("status", "iterations", "seconds", "energy", "timing")}
                       for w, c in chars.items()},
                      _sum_timings([c.get("timing") or {} for c in chars.values()]))


def _sum_timings(parts: list[dict]) -> dict:
    out: dict = {}
    for t in parts:
        for k, v in t.items():
            out[k] = out.get(k, 0.0) + float(v)
    return out



def _guarded(at: tuple[int, str], run_dir: Path, log, fn):
    """``fn()``; an unexpected exception (not a :class:`ComposeError`) becomes the failure of
    step ``at`` — ``step N (<name>) failed: <ExcType>: <msg>`` on one line, exit code 1 — with
    the traceback on ``log`` only under ``COMPOSE_DEBUG=1`` (``compose --debug``).  A stop
    request recorded while ``fn`` ran (see :mod:`schedules.execution.interrupts`) raises
    ``KeyboardInterrupt``, so an interrupted solve is never checkpointed."""
    try:
        out = fn()
    except (ComposeError, KeyboardInterrupt):
        raise
    except Exception as exc:
        interrupts.check()  # an exception caused by the interrupt is the interrupt
        if debug_enabled():
            print(format_traceback(exc), end="", file=log, flush=True)
        raise StepFailed(f"step {at[0]} ({at[1]}) failed: {crash_message(exc)}; finished steps are kept in "
                         f"{run_dir}") from exc
    interrupts.check()
    return out


def _fmt_s(s: float) -> str:
    s = max(0.0, s)
    return f"{int(s // 60)}m{int(s % 60):02d}s" if s >= 60 else f"{s:.0f}s"


# --- the run --------------------------------------------------------------------------------

def _remove_temporaries(run_dir: Path) -> None:
    """Temporary files of atomic writes cut short by a SIGKILL (never at a final path; the
    caller holds the run lock, so no live writer owns them)."""
    for folder in (run_dir, run_dir / "steps"):
        if folder.is_dir():
            for p in folder.glob(".*.tmp"):
                if p.is_file():
                    p.unlink()


def prepare_run_dir(run_dir: Path, fingerprint: str, resume: bool) -> tuple[Manifest, dict | None]:
    """Create or check the run folder; returns (manifest to commit new checkpoints to, the
    manifest data read on resume or None).  Without resume, old checkpoints are removed."""
    man = run_dir / "manifest.json"
    _remove_temporaries(run_dir)
    if resume and man.exists():
        old = Manifest.load(run_dir)
        if old.get("format") != FORMAT:
            raise InputError(f"--resume: the run folder {run_dir} has format {old.get('format')!r} "
                             f"(this compose reads format {FORMAT}; format 1 held pickled checkpoints, which are "
                             "never loaded); remove it or run without --resume", Location(str(man)))
        if old.get("fingerprint") != fingerprint:
            raise InputError(f"--resume: the run folder {run_dir} belongs to a different scenario or schedule "
                             f"(fingerprint {old.get('fingerprint')} != {fingerprint}); "
                             "remove it or run without --resume", Location(str(man)))
        committed = {k: v for k, v in old.get("checkpoints", {}).items()}
        return Manifest(run_dir, FORMAT, fingerprint, committed), old
    # commit the empty manifest first, then remove the old files: a kill in between must not
    # leave a manifest naming checkpoints that are gone (--resume would refuse the folder)
    manifest = Manifest(run_dir, FORMAT, fingerprint)
    manifest.save()
    steps = run_dir / "steps"
    if steps.is_dir():
        for pattern in ("*.pkl", "*.npz", "*.json", ".*.tmp"):
            for p in steps.glob(pattern):
                p.unlink()
    return manifest, None


def _resumed(old: dict | None, run_dir: Path, name: str, log) -> dict | None:
    """A verified checkpoint of a resumed run, or None (not resuming, not committed, or rejected).

    A committed checkpoint that fails its check (truncated, edited, foreign, or not data-only:
    :class:`CheckpointError`) is never loaded: it is reported and its step is solved again, and
    so is every later step (their checkpoints are dropped from ``old``, which is mutated), since
    they were computed from a result this run can no longer vouch for."""
    if old is None:
        return None
    try:
        d = read_checkpoint(old, run_dir, name)
    except CheckpointError as exc:
        print(f"    checkpoint rejected, never loaded: {exc}; solving its step and every later step again",
              file=log, flush=True)
        old["checkpoints"] = {}
        return None
    if d is None and name in checkpoint_names(run_dir):
        print(f"    {run_dir / 'steps' / name}.json was not committed to the manifest (interrupted while "
              "writing): solving its step again", file=log, flush=True)
    return d


def _resumed_step(old: dict | None, run_dir: Path, number: int, step_id: str, fingerprint: str,
                  log) -> dict | None:
    """The verified checkpoint of step ``number`` (1-based) on resume, or None; a checkpoint of
    another step or run is refused with its location."""
    f = run_dir / "steps" / f"{number:03d}.json"
    d = _resumed(old, run_dir, f.stem, log)
    if d is not None and (d.get("step") != step_id or d.get("fingerprint") != fingerprint):
        raise InputError(f"--resume: checkpoint does not belong to step {step_id!r}", Location(str(f)))
    return d


# IPOPT stops that end without convergence but can leave a feasible iterate behind (``solve``
# returns the best feasible iterate it passed): the iteration cap, and numerical breakdowns of
# the step computation or the line search.  Seen: handhold's child window with one MUMPS thread
# (OMP_NUM_THREADS=1, as on Dask workers) ended Restoration_Failed after 56 iterations with every
# constraint held, and the whole run failed; walk_to_run's seam Error_In_Step_Computation.
UNCONVERGED = {"Maximum_Iterations_Exceeded": "reached its iteration cap",
               "Restoration_Failed": "ended in a failed restoration phase",
               "Error_In_Step_Computation": "could not compute a step",
               "Search_Direction_Becomes_Too_Small": "stopped on a vanishing search direction"}


def judge(step: Step, d: dict, fail_capped: bool) -> dict:
    """The acceptance policy (plain and Dask executors) on a solved Step's data, in place: a timing step that
    failed or violates a hard group gets ``discarded``; a full step that failed gets ``failed``
    (the message) — except that one stopped unconverged (``UNCONVERGED``) with every hard group
    held is accepted unless ``fail_capped``, marked ``capped`` (kept as feasible, not
    converged; its status stays in the report)."""
    rec = _record(0, step, d)
    # a timing step is a warm start for the full step after it, used only when it converged (capped
    # ones left feet sliding by up to 0.5 m between collocation points); a full step that stopped
    # unconverged but holds every constraint is kept: the final audit and goals judge the run
    bad = _hard_violations(rec.violations)
    chars = d["characters"].values()
    capped = not rec.success and all(c["success"] or c["status"] in UNCONVERGED for c in chars)
    accepted = rec.success or (capped and step.kind == FULL and not fail_capped)
    if step.kind == FULL and capped and accepted and not bad:
        d["capped"] = True
    if step.kind != FULL and (not accepted or bad):
        d["discarded"] = True
        d["discard_reason"] = f"{rec.status}; " + ", ".join(f"{k}={v:.3g}" for k, v in sorted(bad.items()))
    elif not accepted or bad:
        groups = ", ".join(f"{k}={v:.3g}" for k, v in sorted(bad.items(), key=lambda kv: -kv[1])) \
            or "none above tolerance"
        d["failed"] = (f"step {step.id!r} failed: IPOPT status {rec.status} after {rec.iterations} iterations; "
                       f"violated constraint groups: {groups} (tolerance {VIOLATION_TOL:g})")
    return d


def kept_warning(step_id: str, status: str) -> str:
    """The line printed for a full step kept as feasible, not converged (``status``: the step
    record's, ``;``-joined over its characters)."""
    why = "; ".join(dict.fromkeys(UNCONVERGED[s] for s in status.split(";") if s in UNCONVERGED)) or status
    return f"    warning: {step_id} {why}; kept as feasible, not converged"


def run_schedule(scene: Scene, schedule: Schedule, *, run_dir: str | os.PathLike, fingerprint: str,
                 jobs: int = 1, resume: bool = False, fail_capped: bool = False, log=None) -> RunResult:
    """Run every Step of ``schedule`` over ``scene``; see the module docstring.

    A full step must end with every hard constraint satisfied.  One that reached its
    iteration cap that way is kept (feasible, not converged: ``solve`` returns its best
    feasible iterate, its status stays in the report and a warning line is printed; the audit
    tells how good it is) unless ``fail_capped``.  Gauss–Newton creeps on large-residual
    problems (0.1–0.2 % per iterate for hundreds of iterates), and the thesis cuts the moves
    of decreasing-horizon and coupled schedules short on purpose (coupled full steps are
    capped at COUPLED_FULL_MAX_ITER)."""
    log = sys.stderr if log is None else log  # bound at call time (a test may swap sys.stderr)
    run_dir = Path(run_dir)
    with catching_interrupts(), RunLock(run_dir):
        return _run_locked(scene, schedule, run_dir, fingerprint, jobs, resume, fail_capped, log)


def _run_locked(scene: Scene, schedule: Schedule, run_dir: Path, fingerprint: str, jobs: int, resume: bool,
                fail_capped: bool, log) -> RunResult:
    manifest, old = prepare_run_dir(run_dir, fingerprint, resume)
    order = schedule.order()
    index = {s.id: i for i, s in enumerate(order)}
    first_of: dict[str, str] = {}
    for s in order:
        for who in s.characters:
            first_of.setdefault(who, s.id)
    n = len(order)
    stop_after = int(os.environ.get("COMPOSE_STOP_AFTER", "0") or 0)
    t_start = time.perf_counter()
    records: dict[int, StepRecord] = {}
    contact: dict = {}
    solved_now = 0
    resumed = 0
    done = 0
    solve_seconds = 0.0
    pool = ProcessPoolExecutor(max_workers=jobs, initializer=interrupts.ignore_interrupts_in_worker) \
        if jobs > 1 else None
    presolved: dict = {}
    finished = False
    at = (0, "start")  # (1-based step number, name) being worked on: named by an interrupt or a crash
    try:
        # 0. one kinematic pre-solve per character, before its first step (checkpointed too)
        names = list(first_of)
        loaded, todo_pre = {}, []
        for who in names:
            d = _resumed(old, run_dir, f"000_{who}", log)
            if d is not None:
                loaded[who] = d
            else:
                todo_pre.append(who)
        futs = {who: pool.submit(presolve_character, scene, who) for who in todo_pre} \
            if pool is not None and len(todo_pre) > 1 else {}
        fresh = {}
        for who in todo_pre:
            at = (0, f"presolve {who}")
            fresh[who] = _guarded(at, run_dir, log, futs[who].result if who in futs
                                  else (lambda who=who: presolve_character(scene, who)))
        for who in names:
            d = loaded.get(who) or fresh[who]
            if who in fresh:
                d["fingerprint"] = fingerprint
                write_checkpoint(manifest, f"000_{who}", d)
            elif d.get("fingerprint") != fingerprint or d.get("step") != f"presolve:{who}":
                raise InputError(f"--resume: checkpoint of the pre-solve of {who!r} does not belong to this run",
                                 Location(str(run_dir / "steps" / f"000_{who}.json")))
            print(f"[0/{n}] presolve {who}: {d['status']}, {d['iterations']} it, {d['seconds']:.1f} s"
                  + (" (resumed)" if who in loaded else ""), file=log, flush=True)
            presolved[who] = {k: d[k] for k in ("status", "success", "iterations", "seconds", "violations")}
            if d["success"]:
                scene = scene.with_motion(who, Motion(np.asarray(d["ctrl"]), np.asarray(d["warp"])))
        for gen in schedule.generations():
            gen = sorted(gen, key=lambda s: index[s.id])
            snapshot = scene
            results: dict[str, dict] = {}
            todo = []
            for s in gen:
                d = _resumed_step(old, run_dir, index[s.id] + 1, s.id, fingerprint, log)
                if d is not None:
                    results[s.id] = d
                    resumed += 1
                    done += 1
                    print(f"[{index[s.id] + 1}/{n}] {s.id}: resumed from "
                          f"{run_dir / 'steps' / f'{index[s.id] + 1:03d}.json'}", file=log, flush=True)
                else:
                    todo.append(s)
            pre = {s.id: () for s in todo}  # kinematic pre-solves ran before the first generation
            if pool is not None and len(todo) > 1:
                futures = [(s, pool.submit(solve_step, snapshot, s, pre[s.id], contact)) for s in todo]
                pending = [(s, fu.result) for s, fu in futures]
            else:
                pending = [(s, (lambda s=s: solve_step(snapshot, s, pre[s.id], contact))) for s in todo]
            for s, get in pending:
                t0 = time.perf_counter()
                at = (index[s.id] + 1, s.id)
                d = _guarded(at, run_dir, log, get)
                d["fingerprint"] = fingerprint
                results[s.id] = d
                rec = _record(index[s.id], s, d)
                done += 1
                solve_seconds += time.perf_counter() - t0
                elapsed = time.perf_counter() - t_start
                new_done = max(1, done - resumed)
                eta = elapsed / new_done * (n - done)
                print(f"[{index[s.id] + 1}/{n}] {s.id} (cycle {s.cycle}, {s.kind}): {rec.status}, "
                      f"{rec.iterations} it, E={rec.energy:.4g}, {rec.seconds:.1f} s; "
                      f"elapsed {_fmt_s(elapsed)}, ETA {_fmt_s(eta)}", file=log, flush=True)
                judge(s, d, fail_capped)
                if d.get("capped"):
                    print(kept_warning(s.id, rec.status), file=log, flush=True)
                if d.get("discarded"):  # the full step after it starts from the state before it
                    print(f"    {s.id}: timing result discarded ({d['discard_reason']})", file=log, flush=True)
                elif d.get("failed"):
                    raise StepFailed(f"{d['failed']}; finished steps are kept in {run_dir}")
                write_checkpoint(manifest, f"{index[s.id] + 1:03d}", d)
                solved_now += 1
                if stop_after and solved_now >= stop_after:
                    print(f"compose: COMPOSE_STOP_AFTER={stop_after}: stopping after step {s.id!r}", file=log,
                          flush=True)
                    log.flush()
                    os._exit(STOP_EXIT)
            for s in gen:  # merge in the deterministic order
                d = results[s.id]
                if not d.get("discarded"):
                    scene = _apply(scene, d)
                records[index[s.id]] = _record(index[s.id], s, d)
                if s.kind == FULL:
                    for who, c in d["characters"].items():
                        contact[who] = _merge_contacts(contact.get(who), c["contact_forces"], c.get("window"))
        finished = True
        interrupts.set_phase(f"the audit and export (all {n} steps are checkpointed)")
    except KeyboardInterrupt:  # SIGINT/SIGTERM (interrupts.catching_interrupts): the step's result is not kept
        raise RunInterrupted(at[0], at[1], interrupts.requested()) from None
    finally:
        if pool is not None:
            if not finished:  # do not wait minutes for workers' solves whose results are not wanted
                for proc in list((getattr(pool, "_processes", None) or {}).values()):
                    proc.terminate()
            pool.shutdown(wait=True, cancel_futures=True)
    return RunResult(scene, [records[i] for i in sorted(records)], time.perf_counter() - t_start, contact, resumed,
                     presolved)
