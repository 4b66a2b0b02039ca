"""Steps and the Schedule graph.

A :class:`Step` is one spacetime subproblem, described as plain immutable data: which
characters are free, over which time window, which variable blocks are free, and which
terms are active with which weights.  Everything a Step does not free is read from the
current Scene.  A :class:`Schedule` is a ``networkx.DiGraph`` whose nodes are Step ids
(the Step is the node attribute ``step``) and whose edges mean "must run after".

Times in a Step (``window``, style keys, ``seam``) are *canonical* times s in seconds: the
world times of the initial motion.  Constraint times are fixed in canonical time, so they
travel with the motion when the timewarp changes.

Semantics the executor should keep so that results do not depend on ``--jobs``: a Step
reads the Scene as left by its ancestors in the graph; two Steps without a path between
them write disjoint data (different characters, or windows that do not overlap — windows
that merely touch share only the coefficients that neither frees).
"""
from __future__ import annotations

import json
import shutil
import subprocess
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Iterable, Iterator

import networkx as nx

from scenarios.atomic import atomic_path, atomic_write
from scenarios.errors import ComposeError, InputError

__all__ = ["Step", "StyleTimeline", "Group", "Schedule", "Weight",
           "TIMEWARP", "TIME_LAYERED", "COUPLED", "DECREASING_HORIZON", "JOINT", "KINDS",
           "TIMING", "FULL", "HARD", "RELAXED", "FREE", "STEP_KINDS", "FREE_BLOCKS", "TERMS", "TERM_PREFIXES",
           "ROLES", "vocabulary", "declared_vocabulary"]

# schedule kinds (thesis §6.4); JOINT: the characters of a group are solved together in one Step
TIMEWARP = "timewarp"
TIME_LAYERED = "time_layered"
COUPLED = "coupled"
DECREASING_HORIZON = "decreasing_horizon"
JOINT = "joint"
KINDS = (TIMEWARP, TIME_LAYERED, COUPLED, DECREASING_HORIZON, JOINT)

# step kinds (the two halves of the timewarp schedule)
TIMING = "timing"  # timing and constraint placement with the dynamics relaxed
FULL = "full"      # the full problem with hard dynamics

HARD = "hard"
RELAXED = "relaxed"
FREE = "free"  # boundary:end of a receding window: the end state is free (the next window moves on from it)

Weight = float | str  # a number (a penalty weight or a spring stiffness) or HARD / RELAXED / FREE

# --- the vocabulary of a Step: everything the compiler may write and the executor must honour ---
# (schedules/execution/lower.py lists what it handles; tests/execution/test_contract.py checks that what the compiler
# emits is a subset of this vocabulary and that the lowering handles every item of it)
STEP_KINDS = (TIMING, FULL)
FREE_BLOCKS = ("q", "timewarp", "duration", "footprints", "lambda", "coupling_forces")
NUMBER = "number"  # a term whose value is a float
TERMS: dict[str, tuple[str, ...]] = {  # exact term names -> the values they may take
    "energy": (NUMBER,),
    "dynamics": (HARD, RELAXED),
    "environment": (HARD,),
    "start": (NUMBER,),
    "boundary:start": (HARD,),
    "boundary:end": (HARD, FREE),
}
TERM_PREFIXES: dict[str, tuple[str, ...]] = {  # "goal:<name>", "coupling:<name>" -> values
    "goal": (NUMBER, HARD),
    "coupling": (NUMBER, HARD),
    "flight": (HARD,),  # a jump's or hop's flight stage: zero root residual (scenegraph/model/leaps.py)
}
ROLES = ("whole", "window", "seam", "horizon", "receding")


def vocabulary(step: "Step") -> set[tuple[str, str]]:
    """The Step's vocabulary items: ("kind", k), ("free", block), ("role", r), and
    ("term", "<name or prefix>=<value class>") with value class ``number`` for floats."""
    out = {("kind", step.kind), ("role", step.role)}
    out |= {("free", b) for b in step.free}
    for name, w in step.terms:
        key = name.split(":", 1)[0] if name.split(":", 1)[0] in TERM_PREFIXES else name
        out.add(("term", f"{key}={NUMBER if isinstance(w, (int, float)) else w}"))
    return out


def declared_vocabulary() -> set[tuple[str, str]]:
    """Every item a Step may hold (see :func:`vocabulary`)."""
    out = {("kind", k) for k in STEP_KINDS} | {("role", r) for r in ROLES} | {("free", b) for b in FREE_BLOCKS}
    for table in (TERMS, TERM_PREFIXES):
        out |= {("term", f"{n}={v}") for n, vs in table.items() for v in vs}
    return out


@dataclass(frozen=True)
class StyleTimeline:
    """A character's style θ over the whole scenario.

    ``keys`` are (canonical time s, style reference) pairs with non-decreasing times; θ is
    constant before the first and after the last key and interpolated linearly (per
    parameter) between consecutive keys.  Style references are as written in the scenario
    (a bundled name or a path); resolve them with ``Scenario.style_file``.
    """

    character: str
    keys: tuple[tuple[float, str], ...]

    def at(self, t: float) -> tuple[str, str, float]:
        """(style before, style after, weight of 'after' in [0, 1]) at time t."""
        keys = self.keys
        if t <= keys[0][0]:
            return keys[0][1], keys[0][1], 0.0
        for (t0, s0), (t1, s1) in zip(keys, keys[1:]):
            if t <= t1:
                if s0 == s1:
                    return s0, s1, 0.0
                w = 1.0 if t1 == t0 else (t - t0) / (t1 - t0)
                return s0, s1, w
        return keys[-1][1], keys[-1][1], 0.0

    @property
    def changes(self) -> bool:
        """True if the timeline has a style change (even to the same style: a blend window)."""
        return len(self.keys) > 1


@dataclass(frozen=True)
class Step:
    """One spacetime subproblem (see the module docstring).

    id          unique, readable: ``<characters>/c<cycle>/<block>/<kind>``
    kind        ``timing`` (timewarp + placements, dynamics relaxed) or ``full`` (dynamics hard)
    characters  whose variables are free (one, or a whole group when solved jointly)
    window      (t0, t1) canonical seconds: only coefficients whose support lies inside are free
    free        free variable blocks (FREE_BLOCKS): ``q`` (DOF spline coefficients), ``timewarp``
                (only in steps over the whole scene, and never for a character with a gait
                change, whose footstep plan times the walk and the run), ``footprints`` (free
                constraint locations), ``lambda`` (contact force coefficients; every step),
                ``coupling_forces`` (the hand forces of hard couplings: the characters are
                solved jointly, scenegraph/problem/joint.py), ``duration`` (with ``timing: free``: the
                end of the timewarp moves within ``duration_bounds``; only with ``timewarp``)
    terms       (name, weight) pairs; names: ``energy`` (weight), ``dynamics`` (hard|relaxed),
                ``environment`` (ground, friction cone, no penetration, feet not crossing),
                ``start`` (a soft spring of this weight holding the start position),
                ``boundary:start`` / ``boundary:end`` (``hard``: pose and velocity at the window's
                end held at the current Scene; ``boundary:end=free``: a receding window's end
                state is free, its dynamics count up to the window's end), ``goal:<name>``
                (``hard`` for footprints, else the weight of its soft springs: walk_to, reach,
                tackle, avoid; the executor uses exactly this weight), ``coupling:<name>`` (a
                stiffness in N/m = rubber-band continuation, or ``hard``: a joint solve, full
                steps only)
    cycle       1-based schedule cycle
    schedules   the schedule kinds that produced it, outermost first, e.g. (coupled, timewarp)
    role        ``whole`` | ``window`` | ``seam`` | ``horizon`` | ``receding``
    group       the independent branch it belongs to (a connected component of characters)
    observes    other characters whose current motion enters (partners, opponents), read-only
    styles      full-scenario style timelines of the free characters
    seam        for seam steps: the canonical time of the seam the window straddles
    stiffness   for steps with rubber-band couplings: their stiffness this cycle (N/m)
    repeat      1-based repetition index inside a cycle (``solves_per_cycle``)
    """

    id: str
    kind: str
    characters: tuple[str, ...]
    window: tuple[float, float]
    free: tuple[str, ...]
    terms: tuple[tuple[str, Weight], ...]
    cycle: int = 1
    schedules: tuple[str, ...] = ()
    role: str = "whole"
    group: str = ""
    observes: tuple[str, ...] = ()
    styles: tuple[StyleTimeline, ...] = ()
    seam: float | None = None
    stiffness: float | None = None
    repeat: int = 1

    @property
    def weights(self) -> dict[str, Weight]:
        """``terms`` as a (fresh) dict."""
        return dict(self.terms)

    def term(self, name: str, default: Weight | None = None) -> Weight | None:
        for n, w in self.terms:
            if n == name:
                return w
        return default

    @property
    def goals(self) -> tuple[str, ...]:
        return tuple(n.split(":", 1)[1] for n, _ in self.terms if n.startswith("goal:"))

    @property
    def couplings(self) -> tuple[str, ...]:
        return tuple(n.split(":", 1)[1] for n, _ in self.terms if n.startswith("coupling:"))

    @property
    def duration(self) -> float:
        return self.window[1] - self.window[0]

    def sort_key(self) -> tuple:
        return (self.cycle, self.window[0], self.id)

    def summary(self) -> str:
        def w(x: Weight) -> str:
            return x if isinstance(x, str) else f"{x:g}"
        terms = " ".join(f"{n}={w(v)}" for n, v in self.terms if n not in ("energy", "environment"))
        obs = f" sees {','.join(self.observes)}" if self.observes else ""
        return (f"[{self.window[0]:.3f}, {self.window[1]:.3f}] s  free {','.join(self.free)}  "
                f"{terms}{obs}")

    def to_data(self) -> dict:
        d = asdict(self)
        d["terms"] = [[n, v] for n, v in self.terms]
        d["styles"] = [{"character": s.character, "keys": [list(k) for k in s.keys]} for s in self.styles]
        return d


@dataclass(frozen=True)
class Group:
    """An independent branch: characters that interact, the kinds chosen and why."""

    name: str
    characters: tuple[str, ...]
    kinds: tuple[str, ...]
    reasons: tuple[str, ...] = ()
    order: tuple[str, ...] = ()  # the order characters are solved in within a cycle


@dataclass
class Schedule:
    """A DAG of Steps; edges point from a Step to the Steps that must run after it."""

    graph: nx.DiGraph
    scenario: str = ""
    groups: tuple[Group, ...] = ()
    notes: tuple[str, ...] = field(default_factory=tuple)

    def __post_init__(self):
        if not nx.is_directed_acyclic_graph(self.graph):
            cycle = nx.find_cycle(self.graph)
            raise ComposeError(f"schedule has a cycle: {cycle}")

    # -- access ------------------------------------------------------------------------
    @classmethod
    def from_steps(cls, steps: Iterable[Step], edges: Iterable[tuple[str, str]], **kw) -> "Schedule":
        g = nx.DiGraph()
        for s in steps:
            if s.id in g:
                raise ComposeError(f"duplicate step id {s.id!r}")
            g.add_node(s.id, step=s)
        for a, b in edges:
            if a not in g or b not in g:
                raise ComposeError(f"edge {a!r} -> {b!r} names an unknown step")
            g.add_edge(a, b)
        return cls(g, **kw)

    def __len__(self) -> int:
        return self.graph.number_of_nodes()

    def __iter__(self) -> Iterator[Step]:
        return iter(self.order())

    def __contains__(self, step_id: str) -> bool:
        return step_id in self.graph

    def step(self, step_id: str) -> Step:
        return self.graph.nodes[step_id]["step"]

    @property
    def steps(self) -> list[Step]:
        return self.order()

    def order(self) -> list[Step]:
        """A deterministic topological order (ties: cycle, window start, id)."""
        key = lambda n: self.step(n).sort_key()  # noqa: E731
        return [self.step(n) for n in nx.lexicographical_topological_sort(self.graph, key=key)]

    def generations(self) -> list[list[Step]]:
        """Batches of Steps whose predecessors all lie in earlier batches (may run in parallel)."""
        return [sorted((self.step(n) for n in gen), key=Step.sort_key)
                for gen in nx.topological_generations(self.graph)]

    def predecessors(self, step_id: str) -> list[str]:
        return sorted(self.graph.predecessors(step_id))

    def successors(self, step_id: str) -> list[str]:
        return sorted(self.graph.successors(step_id))

    def has_path(self, a: str, b: str) -> bool:
        return nx.has_path(self.graph, a, b)

    @property
    def kinds(self) -> set[str]:
        return {k for g in self.groups for k in g.kinds}

    def steps_of(self, character: str) -> list[Step]:
        return [s for s in self.order() if character in s.characters]

    # -- rendering ---------------------------------------------------------------------
    def to_text(self) -> str:
        order = self.order()
        index = {s.id: i + 1 for i, s in enumerate(order)}
        lines = [f"schedule for scenario {self.scenario!r}: {len(order)} steps in "
                 f"{len(self.groups)} independent branch(es); kinds: {', '.join(sorted(self.kinds)) or 'one full step per subproblem'}"]
        for n in self.notes:
            lines.append(f"  note: {n}")
        for g in self.groups:
            lines.append(f"branch {g.name}: {', '.join(g.kinds)}"
                         + (f"  (solve order: {', '.join(g.order)})" if len(g.order) > 1 else ""))
            for r in g.reasons:
                lines.append(f"  - {r}")
        lines.append("steps in run order (#, id, window, free blocks, terms; after: predecessors):")
        width = max((len(s.id) for s in order), default=0)
        for s in order:
            after = ",".join(str(index[p]) for p in sorted(self.graph.predecessors(s.id), key=index.get)) or "-"
            lines.append(f"{index[s.id]:4d}  {s.id:<{width}}  {s.summary()}  after: {after}")
        return "\n".join(lines) + "\n"

    def to_dot(self) -> str:
        def q(s: str) -> str:
            return '"' + s.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
        lines = [f"digraph {q('schedule ' + self.scenario)} {{", "  rankdir=LR;",
                 '  node [shape=box, fontname="Helvetica", fontsize=10];']
        for i, g in enumerate(self.groups):
            lines.append(f"  subgraph cluster_{i} {{")
            lines.append(f"    label={q(g.name + ': ' + ', '.join(g.kinds))};")
            for s in self.order():
                if s.group != g.name:
                    continue
                label = f"{s.id}\n[{s.window[0]:.2f}, {s.window[1]:.2f}] s"
                if s.stiffness is not None:
                    label += f"\nk={s.stiffness:g} N/m"
                style = ", style=dashed" if s.kind == TIMING else ""
                lines.append(f"    {q(s.id)} [label={q(label)}{style}];")
            lines.append("  }")
        for a, b in sorted(self.graph.edges()):
            lines.append(f"  {q(a)} -> {q(b)};")
        lines.append("}")
        return "\n".join(lines) + "\n"

    def write_dot(self, path: str | Path) -> None:
        atomic_write(path, self.to_dot())

    def write_png(self, path: str | Path) -> None:
        """Render with graphviz ``dot``; InputError if graphviz is not installed."""
        exe = shutil.which("dot")
        if exe is None:
            raise InputError("graphviz `dot` is not installed: cannot write PNG (use --dot and render it elsewhere)")
        with atomic_path(path, suffix=".png") as tmp:
            res = subprocess.run([exe, "-Tpng", "-o", str(tmp)], input=self.to_dot(), text=True,
                                 capture_output=True, timeout=120)
            if res.returncode != 0:
                raise ComposeError(f"graphviz dot failed: {res.stderr.strip()}")

    def to_data(self) -> dict:
        return {
            "scenario": self.scenario,
            "groups": [asdict(g) for g in self.groups],
            "notes": list(self.notes),
            "steps": [s.to_data() for s in self.order()],
            "edges": sorted([a, b] for a, b in self.graph.edges()),
        }

    def to_json(self) -> str:
        return json.dumps(self.to_data(), indent=1, sort_keys=False)
