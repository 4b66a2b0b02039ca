"""A Schedule as a Dask task graph, and the pure task functions that run in worker processes.

Translation (:func:`schedule_graph`): one task per Step (key ``step:<step id>``) and one per
character's kinematic pre-solve (key ``presolve:<character>``), plus one data node
``scene`` holding the Scene as built from the scenario.  The task of a Step depends on

* the tasks of **all its ancestors** in the schedule (the transitive closure of the
  schedule's edges: a Step reads the Scene as left by its ancestors, see
  :mod:`schedules.plan.step`), and
* the pre-solve tasks of every character it or an ancestor frees or observes.

Everything a task reads and writes is explicit data: its inputs are the Scene as built
(arrays of the initial motions, bodies, styles, goals) and the result dicts of those
tasks (control points, timewarp, footsteps and contact forces as numpy arrays and frozen
dataclasses); its output is a result dict of the same kind (what a checkpoint stores).
A task rebuilds its input Scene by applying the pre-solves (sorted by character) and then
its ancestors' results in the schedule's deterministic order (``Schedule.order()``), so
the same Step gets the same input — and IPOPT the same problem — on any scheduler and any
number of workers.  Compiled CasADi kernels are never part of the graph: every worker
process loads them from the disk cache of :mod:`scenegraph.model.codegen` (compiling them once
per machine when missing).

Before solving, a task looks its input up in the content-addressed step store
(:mod:`schedules.execution.step_store`): the key is a SHA-256 of everything the Step reads (see
:func:`step_key`), so an unchanged Step of an edited scene is not solved again.

A Step that fails (IPOPT failed, or a hard constraint group violated by more than
``VIOLATION_TOL``) returns its data with ``"failed": <message>``; its descendants then
return ``{"skipped": ...}`` without solving, and the driver raises ``StepFailed``.
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np

from schedules.execution.executor import FULL, VIOLATION_TOL, _apply, _merge_contacts, judge, presolve_character, solve_step
from schedules.plan.step import Schedule, Step

__all__ = ["SCENE_KEY", "step_task_key", "presolve_task_key", "schedule_graph", "step_inputs", "step_task",
           "presolve_task", "step_key", "presolve_key", "code_version", "Given", "apply_results",
           "STORE_FORMAT", "NOT_READ"]

SCENE_KEY = "scene"
STORE_FORMAT = 1  # bump when what a stored step result means changes


def step_task_key(step_id: str) -> str:
    return f"step:{step_id}"


def presolve_task_key(who: str) -> str:
    return f"presolve:{who}"


@dataclass(frozen=True)
class Given:
    """A result already known (resumed from the run folder): the graph holds it as data."""

    data: dict


def _given(box: Given) -> dict:
    return box.data


# --- hashing ------------------------------------------------------------------------------------


def _feed(h, obj: Any) -> None:
    """Feed a canonical byte form of plain data (numbers, strings, arrays, dataclasses,
    pydantic models, containers) into the hash ``h``."""
    if obj is None or isinstance(obj, bool):
        h.update(f"<{obj!r}>".encode())
    elif isinstance(obj, (int, np.integer)):
        h.update(f"i{int(obj)};".encode())
    elif isinstance(obj, (float, np.floating)):
        h.update(f"f{float(obj).hex()};".encode())
    elif isinstance(obj, str):
        b = obj.encode()
        h.update(f"s{len(b)}:".encode() + b)
    elif isinstance(obj, np.ndarray):
        a = np.ascontiguousarray(obj)
        if a.dtype.kind == "O":
            _feed(h, a.tolist())
        else:
            h.update(f"a{a.dtype.str}{a.shape}:".encode() + a.tobytes())
    elif isinstance(obj, (list, tuple)):
        h.update(f"l{len(obj)}[".encode())
        for x in obj:
            _feed(h, x)
        h.update(b"]")
    elif isinstance(obj, dict):
        h.update(f"d{len(obj)}{{".encode())
        for k in sorted(obj, key=repr):
            _feed(h, k)
            _feed(h, obj[k])
        h.update(b"}")
    elif is_dataclass(obj):
        h.update(f"D{type(obj).__name__}(".encode())
        for f in fields(obj):
            if f.name in NOT_READ:
                continue
            _feed(h, f.name)
            _feed(h, getattr(obj, f.name))
        h.update(b")")
    elif hasattr(obj, "model_dump"):  # pydantic (Style)
        h.update(f"M{type(obj).__name__}(".encode())
        _feed(h, obj.model_dump())
        h.update(b")")
    else:
        raise TypeError(f"cannot hash {type(obj).__name__} for the step store")


# Fields no solve reads, left out of every content address: ``where`` is a goal's or
# coupling's scenario location ``file:line:col goals[j] (name)``, used in reports and
# messages only.  With it in the key, a re-run of an edited copy of a scenario (another file
# name) or an edit that moved a goal's line re-solved every step (measured: 0 of 4 steps of
# an unchanged walker came from the store).
NOT_READ = frozenset({"where"})

_CODE: str | None = None


def code_version() -> str:
    """SHA-256 (first 16 hex digits) of the solver's source: every ``.py`` of ``scenegraph``
    and the modules of ``schedules`` that turn a Step into a solve (executor, step, lower,
    graph tasks), plus the CasADi and numpy versions."""
    global _CODE
    if _CODE is None:
        import casadi
        import scenegraph

        h = hashlib.sha256()
        schedules = Path(__file__).resolve().parents[1]
        root = schedules.parent
        files = sorted(Path(scenegraph.__file__).resolve().parent.rglob("*.py"))
        files += [schedules / n for n in ("execution/executor.py", "plan/step.py", "execution/lower.py",
                                          "execution/graph_tasks.py")]
        for p in files:
            h.update(p.relative_to(root).as_posix().encode())
            h.update(p.read_bytes())
        h.update(f"casadi {casadi.__version__} numpy {np.__version__} store {STORE_FORMAT}".encode())
        _CODE = h.hexdigest()[:16]
    return _CODE


def _read_set(scene, step: Step) -> tuple[str, ...]:
    return tuple(sorted(set(step.characters) | set(step.observes)))


def _scene_part(scene, names: tuple[str, ...]) -> list:
    """What a solve can read of ``scene`` for these characters: their whole state (body,
    styles, motion, footsteps, start), every goal and coupling that names one of them, the
    ground, duration and friction."""
    chars = [scene.character(n) for n in names]
    goals = [g for g in scene.goals if g.character in names or g.partner in names]
    coup = [c for c in scene.couplings if any(w in names for w, _ in c.handles)]
    return [scene.duration, scene.friction, scene.ground, chars, goals, coup]


def _settings(fail_capped: bool) -> list:
    return [code_version(), bool(fail_capped), os.environ.get("COMPOSE_MAX_ITER", ""), VIOLATION_TOL]


def step_key(scene, step: Step, contacts: dict, fail_capped: bool) -> str:
    """Content address of a Step's result: SHA-256 of its Step data, the state of every
    character it frees or observes in its input Scene, the goals/couplings/ground it can
    read, the contact forces it is warm-started from, and the code version and settings."""
    h = hashlib.sha256(b"compose-step\0")
    _feed(h, json.dumps(step.to_data(), sort_keys=True, default=repr))
    names = _read_set(scene, step)
    _feed(h, _scene_part(scene, names))
    _feed(h, {w: contacts.get(w) for w in step.characters})
    _feed(h, _settings(fail_capped))
    return h.hexdigest()


def presolve_key(scene, who: str) -> str:
    """Content address of a character's kinematic pre-solve (its state and the ground)."""
    h = hashlib.sha256(b"compose-presolve\0")
    _feed(h, who)
    _feed(h, [scene.ground, scene.character(who)])
    _feed(h, _settings(False))
    return h.hexdigest()


# --- the graph ------------------------------------------------------------------------------------


def schedule_graph(scene, schedule: Schedule, *, store: str | None = None, fail_capped: bool = False,
                   given: dict[str, dict] | None = None) -> dict:
    """The Dask task graph of ``schedule`` over ``scene`` (see the module docstring).

    ``given``: task key → result already known (resumed): such a task becomes plain data.
    ``store``: folder of the content-addressed step store (None: no store)."""
    given = given or {}
    order = schedule.order()
    index = {s.id: i for i, s in enumerate(order)}
    g = schedule.graph
    # pre-solves: every character some Step frees (as the plain executor does)
    chars = sorted({w for s in order for w in s.characters})
    dsk: dict = {SCENE_KEY: scene}
    for who in chars:
        k = presolve_task_key(who)
        dsk[k] = (_given, Given(given[k])) if k in given else (presolve_task, SCENE_KEY, who, store)
    for s in order:
        k = step_task_key(s.id)
        if k in given:
            dsk[k] = (_given, Given(given[k]))
            continue
        anc = sorted(_ancestors(g, s.id), key=index.get)
        anc_steps = tuple(schedule.step(a) for a in anc)
        who = sorted(w for w in set(s.characters) | set(s.observes)
                     | {w for a in anc_steps for w in a.characters} | {w for a in anc_steps for w in a.observes}
                     if w in chars)
        dsk[k] = (step_task, s, SCENE_KEY, tuple(who), [presolve_task_key(w) for w in who],
                  tuple(a.kind for a in anc_steps), [step_task_key(a) for a in anc], store, fail_capped)
    return dsk


def _ancestors(g, node: str) -> set[str]:
    import networkx as nx

    return nx.ancestors(g, node)


# --- the task functions (run in worker processes) -----------------------------------------------


def _store(path: str | None):
    if not path:
        return None
    from schedules.execution.step_store import StepStore

    return StepStore(path)


def presolve_task(scene, who: str, store: str | None) -> dict:
    """A character's kinematic pre-solve (``executor.presolve_character``), via the store."""
    st = _store(store)
    key = presolve_key(scene, who) if st else None
    if st is not None:
        hit = st.get(key)
        if hit is not None:
            hit["stored"] = True
            return hit
    d = presolve_character(scene, who)
    if st is not None:
        st.put(key, d)
    return d


def apply_results(scene, presolves: dict[str, dict], steps: list[tuple[str, dict]]):
    """``scene`` with the successful pre-solves (sorted by character) and then the step
    results (in the order given; discarded ones skipped) applied; also the merged contact
    forces of the full steps: (scene, {character: {handle: (times, forces)}})."""
    from scenegraph.model.motion import Motion

    for who in sorted(presolves):
        d = presolves[who]
        if d["success"]:
            scene = scene.with_motion(who, Motion(np.asarray(d["ctrl"]), np.asarray(d["warp"])))
    contacts: dict = {}
    for kind, d in steps:
        if not d.get("discarded"):
            scene = _apply(scene, d)
        if kind == FULL:
            for who, c in d["characters"].items():
                contacts[who] = _merge_contacts(contacts.get(who), c["contact_forces"], c.get("window"))
    return scene, contacts


def step_inputs(scene, who: tuple[str, ...], presolves: list[dict], kinds: tuple[str, ...], ancestors: list[dict]):
    """The input Scene and contact forces of a Step (see :func:`apply_results`)."""
    return apply_results(scene, dict(zip(who, presolves)), list(zip(kinds, ancestors)))


def step_task(step: Step, scene, who: tuple[str, ...], presolves: list[dict], kinds: tuple[str, ...],
              ancestors: list[dict], store: str | None, fail_capped: bool) -> dict:
    """Solve one Step from explicit inputs (see the module docstring); returns its data."""
    bad = [a for a in ancestors if a.get("failed") or a.get("skipped")]
    if bad:
        return {"step": step.id, "characters": {}, "skipped": "an ancestor step failed"}
    cur, contacts = step_inputs(scene, who, presolves, kinds, ancestors)
    st = _store(store)
    key = step_key(cur, step, contacts, fail_capped) if st else None
    if st is not None:
        hit = st.get(key)
        if hit is not None:
            hit["stored"] = True
            return hit
    d = judge(step, solve_step(cur, step, (), contacts), fail_capped)
    if st is not None and not d.get("failed"):
        st.put(key, d)
    return d
