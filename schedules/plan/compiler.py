"""The schedule compiler: from a scenario's structure to a Schedule (thesis §6.4, §6.5).

How the schedule is chosen (``schedule.kind: auto``, the default):

1. Characters interact through couplings (hand_hold, carry) and adversarial goals
   (tackle, avoid).  Each connected component of that interaction graph is an independent
   branch of the schedule: no edges between branches, so they may run in parallel.
2. Per branch:
   * a tackle/avoid pair in it → **decreasing horizon**: characters alternate, those that
     plan last (``plans_last``; default the attacker) after the others; in cycle k the
     optimised interval is [t_e·(1 − 2^(1−k)), T] with t_e the latest adversarial time, so
     the time left before the event halves every cycle; couplings inside the branch are
     rubber bands whose stiffness rises every cycle; timing steps in the first cycle only
     (later windows start inside the motion, where the timewarp is held);
   * otherwise a coupling in it → **coupled characters**: characters alternate (sorted
     names; ``solves_per_cycle`` repeats some), each coupling a rubber band whose stiffness
     rises every cycle (``stiffness_start``, ``+stiffness_increase``, ``×stiffness_factor``);
     timing steps in the first cycle only;
   * otherwise one character alone.
   Single and coupled branches are **time-layered** when the duration exceeds
   ``max_window`` or a style changes over time: windows abut at every style change and
   are split to at most ``max_window``; each cycle solves the windows, then a seam window C
   straddling every boundary; θ is interpolated linearly across the seam (or across the
   style change's ``blend``).  When the duration fits one window (the layers come from a
   style change), the branch is first solved whole (timing and full), then its windows and
   seams get full steps only, one cycle unless ``cycles`` says otherwise.  One character
   alone, longer than ``max_window``, with one style (and no ``seam`` given) gets
   **receding windows** instead: windows of ``max_window`` overlapping by half, solved one
   after another, each from the solved motion before it with its end free
   (``boundary:end=free``); one cycle unless ``cycles`` says otherwise.  Windows and seams
   are full steps (a window holds the global timewarp).
3. A subproblem over the whole scene of a scenario with ``timing: free`` uses the **timewarp**
   schedule: a ``timing`` Step (timewarp, duration and free placements, dynamics relaxed) then a
   ``full`` Step (dynamics hard).  Elsewhere it is one ``full`` Step with the timewarp held (the
   footstep plan and the gait generator time the motion): a timing step reached its
   100-iteration cap and was discarded in every bundled run measured (rounds 13–14,
   docs/results.md "Timing steps"), so it cost 30–40 % of a run and changed nothing.
   ``schedule.timewarp: true`` asks for timing steps everywhere, ``false`` for none (the full
   step then frees the timewarp itself, :func:`_free`).

An explicit ``schedule.kind`` overrides step 2: ``timewarp`` solves each branch jointly in
one subproblem (couplings hard: the full steps solve the two hand-holding characters in one
NLP with the hand force as a variable, scenegraph/problem/joint.py; the timing step times each
character alone), ``time_layered`` solves each branch jointly per window,
``coupled`` and ``decreasing_horizon`` put *all* characters in one branch of that kind.

Edges are derived from data dependencies in program order: a Step runs after every earlier
Step of its branch that writes what it reads or writes, or reads what it writes (characters
× overlapping windows); the graph is then transitively reduced.  Ties are broken by
sorted names, so the same scenario always gives the same graph.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import networkx as nx

from scenarios.errors import InputError
from scenarios.schema import (FootprintsGoal, HandHold, HopGoal, JumpGoal, Scenario, ScheduleSpec, StyleChangeGoal,
                              TackleGoal)
from scenarios.weights import START_WEIGHT

from schedules.plan.step import (COUPLED, DECREASING_HORIZON, FREE, FULL, HARD, JOINT, RELAXED, TIME_LAYERED, TIMEWARP, TIMING,
                   Group, Schedule, Step, StyleTimeline)

__all__ = ["compile_schedule", "timing_steps", "DEFAULT_CYCLES", "layer_windows", "receding_windows", "MIN_WINDOW", "MAX_STEPS"]

DEFAULT_CYCLES = {TIME_LAYERED: 2, COUPLED: 4, DECREASING_HORIZON: 3}
EPS = 1e-9
# Narrowest window a Step may optimise (s).  A windowed Step frees only the control points whose
# support lies inside its window (problem.window_mask); motions have 24 control points per
# second (gait.initial_motion) and a cubic B-spline point spans 4 knot intervals (1/6 s), so
# 0.2 s frees at least one point and holds 6 collocation points at 30 Hz.  A style change
# 0.05 s after the start compiled a 0.05 s seam and died in CasADi ("Degenerate map operation").
MIN_WINDOW = 0.2
MAX_STEPS = 2000  # steps of one schedule (the bundled scenarios have at most a few dozen)


@dataclass
class _Block:
    """One subproblem before it is split into timing/full Steps."""

    characters: tuple[str, ...]
    window: tuple[float, float]
    cycle: int
    role: str
    label: str
    schedules: tuple[str, ...]
    observes: tuple[str, ...] = ()
    couplings: str = "spring"  # "spring" (rubber band at `stiffness`) or "hard"
    stiffness: float | None = None
    seam: float | None = None
    repeat: int = 1
    kinds: tuple[str, ...] | None = None  # Step kinds of the block; None: the timewarp schedule's
    steps: list[Step] = field(default_factory=list)

    def reads(self) -> set[str]:
        return set(self.characters) | set(self.observes)

    def writes(self) -> set[str]:
        return set(self.characters)


def _overlap(a: tuple[float, float], b: tuple[float, float]) -> bool:
    return a[0] < b[1] - EPS and b[0] < a[1] - EPS


def _interval_meets(iv: tuple[float, float], w: tuple[float, float]) -> bool:
    return iv[0] <= w[1] + EPS and w[0] <= iv[1] + EPS


def _fmt(t: float) -> str:
    return f"{t:g}"


# --- windows --------------------------------------------------------------------------------


def layer_windows(T: float, boundaries: list[float], max_window: float,
                  seam: float | None = None) -> tuple[list[tuple[float, float]], list[tuple[float, float, float]]]:
    """Windows abutting at ``boundaries`` (and split to ≤ max_window), and seams (c0, c1, t).

    The seam window C around a boundary t between windows [a, t] and [t, b] has half-width
    min(t − a, b − t)/2, or ``seam``/2 clipped to that range.
    """
    cuts = sorted({0.0, T, *[b for b in boundaries if EPS < b < T - EPS]})
    points: list[float] = [0.0]
    for a, b in zip(cuts, cuts[1:]):
        n = max(1, math.ceil((b - a) / max_window - 1e-9))
        points += [a + (b - a) * k / n for k in range(1, n + 1)]
    windows = list(zip(points, points[1:]))
    seams = []
    for (a, t), (_, b) in zip(windows, windows[1:]):
        h = min(t - a, b - t) / 2.0
        if seam is not None:
            h = min(seam / 2.0, min(t - a, b - t))
        seams.append((t - h, t + h, t))
    return windows, seams


def receding_windows(T: float, max_window: float) -> list[tuple[float, float]]:
    """Windows of length ``max_window`` (s) over [0, T] that overlap by half, in time order.

    Solved one after another, each starts from the solved motion before it and leaves its
    end free, so every window costs the same and the whole scene costs n ≈ 2T/max_window
    of them: linear in T."""
    if T <= max_window + EPS:
        return [(0.0, T)]
    n = math.ceil((T - max_window) / (max_window / 2.0) - 1e-9) + 1
    step = (T - max_window) / (n - 1)
    return [(k * step, min(T, k * step + max_window)) for k in range(n)]


# --- the scenario's structure ----------------------------------------------------------------


@dataclass
class _Structure:
    scn: Scenario
    spec: ScheduleSpec
    names: list[str]
    graph: nx.Graph  # characters; edges carry "couplings" and "adversarial" name lists
    goals_of: dict[str, list[tuple[str, object]]]
    couplings_of: dict[str, list[tuple[str, object, list[str]]]]
    plans_last: set[str]
    style_changes: dict[str, list[StyleChangeGoal]]


def _structure(scn: Scenario) -> _Structure:
    spec = scn.schedule or ScheduleSpec()
    names = sorted(scn.character_names)
    g = nx.Graph()
    g.add_nodes_from(names)

    def link(a: str, b: str, key: str, label: str):
        if not g.has_edge(a, b):
            g.add_edge(a, b, couplings=[], adversarial=[])
        g.edges[a, b][key].append(label)

    goals_of: dict[str, list] = {n: [] for n in names}
    style_changes: dict[str, list] = {n: [] for n in names}
    pair_last: dict[frozenset, list[tuple[str | None, str]]] = {}
    for gname, goal in scn.named_goals():
        pair = getattr(goal, "opponents", None)  # adversarial kinds: (default planner-last, the other)
        if pair is not None:
            goals_of[goal.attacker if isinstance(goal, TackleGoal) else goal.character].append((gname, goal))
            link(pair[0], pair[1], "adversarial", gname)
            pair_last.setdefault(frozenset(pair), []).append((goal.plans_last, pair[0]))
        elif isinstance(goal, StyleChangeGoal):
            style_changes[goal.character].append(goal)
        else:
            goals_of[goal.character].append((gname, goal))
    couplings_of: dict[str, list] = {n: [] for n in names}
    for i, (cname, c) in enumerate(scn.named_couplings()):
        members = sorted(scn.coupling_characters(i))
        for m in members:
            couplings_of[m].append((cname, c, members))
        for a_i, a in enumerate(members):
            for b in members[a_i + 1:]:
                link(a, b, "couplings", cname)
    for v in style_changes.values():
        v.sort(key=lambda s: s.time)
    # per adversarial pair: the explicit plans_last (validated consistent), else the attacker
    # (tackle) or the one avoided (avoid)
    plans_last: set[str] = set()
    for choices in pair_last.values():
        explicit = sorted({c for c, _ in choices if c is not None})
        plans_last.add(explicit[0] if explicit else sorted(d for _, d in choices)[0])
    return _Structure(scn, spec, names, g, goals_of, couplings_of, plans_last, style_changes)


def _style_timeline(st: _Structure, ch: str, seams: dict[float, tuple[float, float]]) -> StyleTimeline:
    """θ keys of one character; blends span the seam window at each change (or ``blend``)."""
    T = st.scn.duration
    spec_ch = st.scn.character(ch)
    keys: list[tuple[float, str]] = [(0.0, spec_ch.style)]
    changes = st.style_changes[ch]
    current = spec_ch.style
    times = [0.0] + [c.time for c in changes] + [T]
    for k, c in enumerate(changes):
        if c.blend is not None:
            b0, b1 = c.time - c.blend / 2.0, c.time + c.blend / 2.0
        elif c.time in seams:
            b0, b1 = seams[c.time]
        else:
            h = min(c.time - times[k], times[k + 2] - c.time) / 2.0
            b0, b1 = c.time - h, c.time + h
        b0 = max(b0, keys[-1][0], 0.0)
        b1 = min(max(b1, b0), T)
        keys += [(b0, current), (b1, c.style)]
        current = c.style
    # drop a leading duplicate (0, s), (0, s)
    out: list[tuple[float, str]] = []
    for k in keys:
        if not out or out[-1] != k:
            out.append(k)
    return StyleTimeline(ch, tuple((float(t), s) for t, s in out))


# --- blocks → steps -----------------------------------------------------------------------------


def _free_footprints(st: _Structure, ch: str, window: tuple[float, float]) -> bool:
    """Footprints are free unless the character's explicit footprints span the whole window."""
    spans = [(min(fp.time[0] for fp in g.steps), max(fp.time[1] for fp in g.steps))
             for _, g in st.goals_of[ch] if isinstance(g, FootprintsGoal)]
    return not any(a <= window[0] + EPS and window[1] - EPS <= b for a, b in spans)


def _terms(st: _Structure, b: _Block, kind: str) -> tuple[tuple[str, object], ...]:
    T = st.scn.duration
    w = b.window
    terms: list[tuple[str, object]] = [("energy", 1.0), ("dynamics", RELAXED if kind == TIMING else HARD),
                                       ("environment", HARD)]
    if w[0] <= EPS:
        terms.append(("start", START_WEIGHT))
    else:
        terms.append(("boundary:start", HARD))
    if w[1] < T - EPS:
        terms.append(("boundary:end", FREE if b.role == "receding" else HARD))
    goals: dict[str, object] = {}
    couplings: dict[str, object] = {}
    for ch in b.characters:
        for gname, goal in st.goals_of[ch]:
            if goal.active(w):  # the goal kind's plan facts (scenarios/schema.py)
                if goal.plan_weight is not None:  # None: no solver term (a leap without an obstacle)
                    goals[f"goal:{gname}"] = goal.plan_weight
                if isinstance(goal, (JumpGoal, HopGoal)):  # its flight stage is ballistic
                    goals[f"flight:{gname}"] = HARD
        for cname, c, members in st.couplings_of[ch]:
            if not _interval_meets(c.interval, w):
                continue
            if b.couplings != "hard":
                couplings[f"coupling:{cname}"] = b.stiffness
            elif kind == FULL:  # a joint solve (scenegraph/problem/joint.py) holds the timewarp: full steps
                couplings[f"coupling:{cname}"] = HARD  # only; the timing step times each character alone
    terms += sorted(goals.items()) + sorted(couplings.items())
    return tuple(terms)


def timing_steps(scn: Scenario) -> bool:
    """Whether whole-scene subproblems of ``scn`` get a timing step before their full step:
    ``schedule.timewarp`` when it is given, else only with ``timing: free`` (a free duration
    needs a free timewarp, and only a timing step frees it then).  Measured (docs/results.md,
    round 14): with the duration fixed every bundled timing step ended at its cap and was
    discarded — IPOPT does not converge on the relaxed problem, with the warp free or held."""
    spec = scn.schedule or ScheduleSpec()
    return spec.timewarp if spec.timewarp is not None else scn.timing == "free"


def _free(st: _Structure, b: _Block, kind: str, has_hard_coupling: bool) -> tuple[str, ...]:
    """The free blocks of a Step, each one the executor frees exactly (step.FREE_BLOCKS).

    The timewarp is free in timing steps (and in full steps with ``schedule.timewarp: false``;
    without timing steps by default, full steps hold it) over the whole scene only: a windowed
    step holds the one warp its neighbours see.  A character
    with a gait change keeps its warp too: its footstep plan times the walk and the run (a
    free warp compressed the walk and stretched the run into one energy-optimal speed); so
    does a character whose jumps or hops give their times (a free warp moved run_and_leap's
    landing away from its given time).
    ``duration`` (``timing: free``) rides on a free timewarp; λ is free in every step."""
    free = ["q"]
    whole = b.window[0] <= EPS and b.window[1] >= st.scn.duration - EPS
    gait_change = any(c.gait is not None for ch in b.characters for c in st.style_changes[ch])
    # a character whose leaps have given times keeps its warp too: the take-off and landing happen then
    timed_leaps = any(isinstance(g, (JumpGoal, HopGoal)) and g.character in b.characters
                      and (g.takeoff.time is not None or g.landing.time is not None) for g in st.scn.goals)
    warp_step = kind == TIMING or st.spec.timewarp is False
    if warp_step and whole and not gait_change and not timed_leaps:
        free.append("timewarp")
        if st.scn.timing == "free":
            free.append("duration")
    if any(_free_footprints(st, ch, b.window) for ch in b.characters):
        free.append("footprints")
    free.append("lambda")
    if has_hard_coupling:
        free.append("coupling_forces")
    return tuple(free)


def _steps_of(st: _Structure, b: _Block, group: str, styles: dict[str, StyleTimeline]) -> list[Step]:
    timewarp = timing_steps(st.scn)
    kinds = list(b.kinds) if b.kinds is not None else [TIMING, FULL] if timewarp else [FULL]
    chars = "+".join(b.characters)
    rep = f"#{b.repeat}" if b.repeat > 1 else ""
    out = []
    for kind in kinds:
        terms = _terms(st, b, kind)
        hard_coupling = any(n.startswith("coupling:") and v == HARD for n, v in terms)
        has_spring = any(n.startswith("coupling:") and v != HARD for n, v in terms)
        out.append(Step(
            id=f"{chars}/c{b.cycle}/{b.label}{rep}/{kind}",
            kind=kind,
            characters=b.characters,
            window=(float(b.window[0]), float(b.window[1])),
            free=_free(st, b, kind, hard_coupling),
            terms=terms,
            cycle=b.cycle,
            schedules=b.schedules + ((TIMEWARP,) if timewarp else ()),
            role=b.role,
            group=group,
            observes=b.observes,
            styles=tuple(styles[c] for c in b.characters),
            seam=b.seam,
            stiffness=b.stiffness if has_spring else None,
            repeat=b.repeat,
        ))
    return out


# --- per-branch programs -------------------------------------------------------------------------


def _observed(st: _Structure, ch: str, members: list[str], window: tuple[float, float]) -> tuple[str, ...]:
    """Partners and opponents of ``ch`` in the branch whose motion enters its subproblem."""
    out = set()
    for _, c, ms in st.couplings_of[ch]:
        if _interval_meets(c.interval, window):
            out |= set(ms)
    for a, b, data in st.graph.edges(ch, data=True):
        if data["adversarial"]:
            out.add(b if a == ch else a)
    out.discard(ch)
    return tuple(sorted(out & set(members)))


def _solve_order(st: _Structure, members: list[str], adversarial: bool) -> list[str]:
    """Adversaries: those who plan last go last.  Coupled characters: those solved more often
    per cycle (``solves_per_cycle``) go first, so they also make the first move toward the
    partner and do most of the adapting (thesis §6.4.3); then by name."""
    if not adversarial:
        return sorted(members, key=lambda n: (-st.spec.solves_per_cycle.get(n, 1), n))
    return sorted(members, key=lambda n: (n in st.plans_last, n))


def _program(st: _Structure, members: list[str], mode: str) -> tuple[list[_Block], Group]:
    """Blocks in program order for one branch; mode: single|coupled|adversarial|joint|joint_layered."""
    scn, spec = st.scn, st.spec
    T = scn.duration
    reasons: list[str] = []
    changes = sorted({c.time for m in members for c in st.style_changes[m]})
    for m in members:
        for c in st.style_changes[m]:
            reasons.append(f"style of {m} changes to {c.style!r} at {_fmt(c.time)} s")
    edges = [(min(a, b), max(a, b), d) for a, b, d in st.graph.subgraph(members).edges(data=True)]
    for a, b, d in sorted(edges, key=lambda e: (e[0], e[1])):
        for cn in d["couplings"]:
            reasons.append(f"coupling {cn!r} links {a} and {b}")
        for gn in d["adversarial"]:
            reasons.append(f"adversarial goal {gn!r} between {a} and {b}")

    layered = mode == "joint_layered" or (mode in ("single", "coupled") and (T > spec.max_window + EPS or changes))
    # one character, long, one style: receding windows (each from the solved motion before
    # it, end free).  Windows solved side by side from the kinematic initial motion held
    # boundary states that no physical motion meets (a 4.8 s walk: window energy 1.6e4,
    # stalled), and the seams and cycles that repair them multiply the cost.
    receding = layered and mode == "single" and not changes and spec.seam is None
    if layered:
        if T > spec.max_window + EPS:
            reasons.append(f"duration {_fmt(T)} s exceeds max_window {_fmt(spec.max_window)} s")
        if receding:
            windows, seams = receding_windows(T, spec.max_window), []
            reasons.append("receding windows: each starts from the solved motion before it, its end free")
        else:
            windows, seams = layer_windows(T, changes, spec.max_window, spec.seam)
    else:
        windows, seams = [(0.0, T)], []
    if spec.timewarp is None and not timing_steps(scn):
        reasons.append("no timing step: the duration is fixed, so the footstep plan's timewarp is held "
                       "(timing: free or schedule.timewarp: true adds one)")
    if mode == "adversarial" and (changes or T > spec.max_window + EPS):
        reasons.append("not time-layered: the decreasing horizon already restricts the windows")

    kinds: list[str] = []
    if mode == "coupled":
        kinds.append(COUPLED)
    if mode == "adversarial":
        kinds.append(DECREASING_HORIZON)
    if mode in ("joint", "joint_layered") and len(members) > 1:
        kinds.append(JOINT)
    if layered:
        kinds.append(TIME_LAYERED)
    alternating = mode in ("coupled", "adversarial")
    if mode == "adversarial":
        cycles = spec.cycles or DEFAULT_CYCLES[DECREASING_HORIZON]
    elif mode == "coupled":
        cycles = spec.cycles or DEFAULT_CYCLES[COUPLED]
    elif layered:
        cycles = spec.cycles or (1 if receding else DEFAULT_CYCLES[TIME_LAYERED])
    else:
        cycles = 1
    order = _solve_order(st, members, mode == "adversarial") if alternating else sorted(members)
    if alternating:
        k1, kn = spec.stiffness(1), spec.stiffness(cycles)
        if any(d["couplings"] for _, _, d in edges):
            reasons.append(f"rubber-band couplings: stiffness {k1:g} → {kn:g} N/m over {cycles} cycles")
    if mode == "adversarial":
        last = [m for m in order if m in st.plans_last]
        reasons.append(f"plans last: {', '.join(last) or order[-1]}")

    t_event = max([g.time for m in members for _, g in st.goals_of[m] if hasattr(g, "opponents")],
                  default=T)
    reps = {m: spec.solves_per_cycle.get(m, 1) if mode == "coupled" else 1 for m in members}
    sched = tuple(kinds)
    blocks: list[_Block] = []
    window_kinds = None
    if len(windows) > 1:
        # a window holds the timewarp (one spline over the whole scene, which its neighbours
        # see), so a timing step there could only relax the dynamics: windows and seams are
        # full steps, timed by the footstep plan (such timing steps reached their cap and
        # were discarded in 3 of 6 windows of a 5 s walk, costing as much as the full steps)
        window_kinds = (FULL,)
    if layered and len(windows) > 1 and T <= spec.max_window + EPS:
        # The whole branch fits one window (the layers come from a style change): solve it
        # whole first — timing (the timewarp is global: a windowed step holds the warp its
        # neighbours see) and full dynamics — so that the windows start from, and hold
        # boundary states of, a physically valid motion; then each window with its own
        # style and the seams with θ blended across them.  Windows started from the
        # kinematic initial motion, or from the relaxed timing solve, were pinned to
        # boundary states with root residuals of ~2 mg and ended at energies of 10⁴–10⁵.
        reasons.append("solved whole first (timing and full), then full steps per window and seam")
        window_kinds = (FULL,)
        if spec.cycles is None:
            cycles = 1
        whole = [tuple(sorted(members))] if mode == "joint_layered" else [(m,) for m in order]
        for chars in whole:
            blocks.append(_Block(chars, (0.0, T), 1, "whole", "whole", sched, couplings="hard"
                                 if mode == "joint_layered" else "spring",
                                 observes=_observed(st, chars[0], members, (0.0, T)) if alternating else (),
                                 stiffness=spec.stiffness(1) if alternating else None))
    for cycle in range(1, cycles + 1):
        stiffness = spec.stiffness(cycle) if alternating else None
        cycle_kinds = window_kinds
        if mode == "coupled" and timing_steps(scn) and cycle > 1:
            # the timing is settled in the first cycle; later cycles refine with full dynamics
            # as the band stiffens (their timing steps stopped at the iteration cap and were
            # discarded in 5 of 6 handhold solves while costing as much as the full steps)
            cycle_kinds = (FULL,)
        if mode == "adversarial" and timing_steps(scn) and cycle > 1:
            # a decreasing-horizon window after the first starts inside the motion: the executor
            # holds the timewarp there, so a timing step would only relax the dynamics — its
            # result, kept when it converged, warm-started the full step far from physical
            # (tackle: dodger E 1.0e3 → 1.4e4 after a converged 0.125 m dodge, then no
            # convergence in the next cycle); the timing is settled in the first cycle
            cycle_kinds = (FULL,)
        if mode == "adversarial":
            t0 = t_event * (1.0 - 2.0 ** (1 - cycle))
            slots = [((t0, T), "horizon", "horizon", None)]
        else:
            role = "receding" if receding else "window"
            slots = [(w, "whole" if len(windows) == 1 else role, "whole" if len(windows) == 1 else f"w{i}", None)
                     for i, w in enumerate(windows)]
            slots += [((c0, c1), "seam", f"seam{i}", t) for i, (c0, c1, t) in enumerate(seams)]
        for window, role, label, seam_t in slots:
            if alternating:
                for r in range(1, max(reps.values()) + 1):
                    for m in order:
                        if reps[m] >= r:
                            blocks.append(_Block((m,), window, cycle, role, label, sched,
                                                 observes=_observed(st, m, members, window),
                                                 stiffness=stiffness, seam=seam_t, repeat=r, kinds=cycle_kinds))
            elif mode in ("joint", "joint_layered"):
                blocks.append(_Block(tuple(sorted(members)), window, cycle, role, label, sched,
                                     couplings="hard", seam=seam_t, kinds=window_kinds))
            else:
                blocks.append(_Block((members[0],), window, cycle, role, label, sched, seam=seam_t,
                                     kinds=window_kinds))
    name = "+".join(sorted(members))
    group = Group(name, tuple(sorted(members)), sched + ((TIMEWARP,) if timing_steps(scn) else ()),
                  tuple(reasons), tuple(order))
    return blocks, group


def _edges(blocks: list[_Block]) -> list[tuple[str, str]]:
    """Data-dependency edges between blocks in program order (last step → first step)."""
    edges: list[tuple[str, str]] = []
    for j, b in enumerate(blocks):
        for a in blocks[:j]:
            if not _overlap(a.window, b.window):
                continue
            if (a.writes() & b.reads()) or (a.reads() & b.writes()):
                edges.append((a.steps[-1].id, b.steps[0].id))
        edges += [(x.id, y.id) for x, y in zip(b.steps, b.steps[1:])]
    return edges


def _check_size(scn: Scenario, steps: list[Step]) -> None:
    """At most MAX_STEPS steps (each one a solve of seconds to minutes), else an InputError
    located at what multiplies them: ``schedule.cycles``, ``schedule.max_window``, or the duration."""
    if len(steps) <= MAX_STEPS:
        return
    from scenarios.errors import InputError

    spec = scn.schedule
    path = ("schedule", "cycles") if spec is not None and spec.cycles is not None else \
        ("schedule", "max_window") if spec is not None and "max_window" in spec.model_fields_set else ("duration",)
    raise InputError(f"the schedule would have more than {MAX_STEPS} steps ({len(steps)} already, "
                     f"{len(scn.characters)} character(s), {scn.duration:g} s); every step is a solve of seconds to "
                     "minutes: use fewer cycles, a longer max_window, fewer characters or a shorter scene",
                     scn.location(path))


def _check_windows(scn: Scenario, steps: list[Step]) -> None:
    """Every Step's window spans at least MIN_WINDOW, else an InputError located at the field
    that made it narrow: the nearest style change (its seam window is half the shorter
    neighbouring window on each side), else ``schedule.seam`` / ``schedule.max_window``, else
    the nearest goal time (decreasing-horizon windows end at the latest adversarial time)."""
    for s in steps:
        w0, w1 = s.window
        if w1 - w0 >= MIN_WINDOW - EPS:
            continue
        mid = 0.5 * (w0 + w1)
        why = (f"step {s.id} would optimise the window [{w0:.4g}, {w1:.4g}] s, {w1 - w0:.3g} s wide; a window "
               f"needs at least {MIN_WINDOW:g} s (24 spline control points per second, each spanning 1/6 s: "
               "a narrower window frees no control point)")
        changes = [(abs(g.time - mid), j, g) for j, g in enumerate(scn.goals)
                   if isinstance(g, StyleChangeGoal) and g.character in s.characters]
        spec = scn.schedule
        if changes:
            _, j, g = min(changes, key=lambda c: (c[0], c[1]))
            room = min(g.time, scn.duration - g.time)
            raise InputError(f"a style change at {g.time:g} s is too close to the "
                             f"{'start' if g.time <= scn.duration - g.time else 'end'} of the scene "
                             f"({room:.3g} s away) to fit its seam window: {why}; move it at least "
                             f"{MIN_WINDOW:g} s inside (0, {scn.duration:g}) s",
                             scn.location(("goals", j, "time")))
        if spec is not None and spec.seam is not None and s.role == "seam":
            raise InputError(f"schedule.seam {spec.seam:g} s is too narrow: {why}", scn.location(("schedule", "seam")))
        if spec is not None and s.role == "window":
            raise InputError(f"schedule.max_window {spec.max_window:g} s splits the scene too finely: {why}",
                             scn.location(("schedule", "max_window")))
        timed = [(abs(getattr(g, "time", 1e300) - w0), j) for j, g in enumerate(scn.goals) if hasattr(g, "time")]
        path = ("goals", min(timed)[1], "time") if timed else ("duration",)
        raise InputError(f"a goal time leaves too little time to optimise: {why}", scn.location(path))


def _check_hard_couplings(scn: Scenario, steps: list[Step]) -> None:
    """A hard coupling is solved jointly (scenegraph/problem/joint.py): a hand-hold between two
    characters.  A hard carry (the holders' hands do not meet) and a joint step of more than
    two characters have no joint solve: InputError at the coupling or at ``schedule.kind``."""
    index = {name: i for i, (name, _) in enumerate(scn.named_couplings())}
    for s in steps:
        hard = [n.split(":", 1)[1] for n, w in s.terms if n.startswith("coupling:") and w == HARD]
        for cname in hard:
            i = index[cname]
            c = scn.couplings[i]
            if not isinstance(c, HandHold):
                raise InputError(f"couplings[{i}] ({cname}): a {c.type} cannot be solved as a hard coupling "
                                 f"(schedule.kind {scn.schedule.kind!r} solves couplings jointly, and only a "
                                 "hand_hold between two characters has a joint solve); use schedule.kind auto "
                                 "or coupled (rubber band)", scn.location(("couplings", i, "type")))
        if hard and len(s.characters) != 2:
            raise InputError(f"schedule.kind {scn.schedule.kind!r} would solve {len(s.characters)} characters "
                             f"({', '.join(s.characters)}) jointly with hard couplings; a joint solve holds two "
                             "characters; use schedule.kind auto or coupled", scn.location(("schedule", "kind")))


def compile_schedule(scn: Scenario) -> Schedule:
    """The Schedule of a scenario: independent branches of timewarp-scheduled subproblems."""
    if scn.is_edit:  # scenarios/edit_block.py: `compose run` edits the clip, nothing is scheduled
        raise InputError("an edit scenario has no schedule: it edits its clip (compose run executes the edit)",
                         scn.location(("edit",)))
    st = _structure(scn)
    kind = st.spec.kind
    notes: list[str] = []
    if kind in (COUPLED, DECREASING_HORIZON):
        components = [sorted(st.names)]
        notes.append(f"explicit schedule {kind!r}: all characters in one branch")
    else:
        components = sorted((sorted(c) for c in nx.connected_components(st.graph)), key=lambda c: c[0])
        if kind != "auto":
            notes.append(f"explicit schedule {kind!r}")

    all_steps: list[Step] = []
    all_edges: list[tuple[str, str]] = []
    groups: list[Group] = []
    programs: list[list[_Block]] = []
    for members in components:
        sub = st.graph.subgraph(members)
        adversarial = any(d["adversarial"] for _, _, d in sub.edges(data=True))
        coupled = any(d["couplings"] for _, _, d in sub.edges(data=True))
        if kind == "auto":
            mode = "adversarial" if adversarial else "coupled" if coupled else "single"
        elif kind == TIMEWARP:
            mode = "joint" if len(members) > 1 else "single_plain"
        elif kind == TIME_LAYERED:
            mode = "joint_layered"
        elif kind == COUPLED:
            mode = "coupled"
        else:
            mode = "adversarial"
        if mode == "single_plain":
            mode = "joint"
        blocks, group = _program(st, members, mode)
        # seams of this branch, for the style blends
        seam_map = {b.seam: b.window for b in blocks if b.seam is not None}
        styles = {m: _style_timeline(st, m, seam_map) for m in members}
        name = group.name
        for b in blocks:
            b.steps = _steps_of(st, b, name, styles)
            all_steps += b.steps
        _check_size(scn, all_steps)
        programs.append(blocks)
        groups.append(group)

    _check_windows(scn, all_steps)
    for blocks in programs:  # quadratic in the blocks of a branch: after the size check
        all_edges += _edges(blocks)
    g = nx.DiGraph()
    for s in all_steps:
        g.add_node(s.id)
    g.add_edges_from(all_edges)
    _check_hard_couplings(scn, all_steps)
    reduced = nx.transitive_reduction(g)
    return Schedule.from_steps(all_steps, sorted(reduced.edges()), scenario=scn.name, groups=tuple(groups),
                               notes=tuple(notes))
