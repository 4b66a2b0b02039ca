"""The import rules of docs/architecture.md, checked by walking the import statements (AST).

Every ``import``/``from … import`` of the three packages is read, at module level and inside
functions (a lazy import still couples two modules), and resolved to a project module. The
rules:

1. no import cycles between modules;
2. ``scenarios`` (the language) imports neither ``scenegraph`` nor ``schedules``;
3. ``scenegraph`` (the model, the world and the solver) never imports ``schedules``;
4. the physics audit and the residual kernels never see the transcription:
   ``scenegraph/model/audit.py`` and ``scenegraph/model/residual.py`` never import ``scenegraph.problem``;
5. the plan is data: ``schedules/plan/compiler.py`` and ``schedules/plan/step.py`` import no CasADi,
   directly or through anything they import at module level (package ``__init__`` files
   included, as Python runs them); and ``compose schedule`` really does not load it;
6. learning (``scenegraph/nio/``) sits on top of the model: no other ``scenegraph`` module
   imports it, and inside it each module imports only those before it in ``NIO_ORDER``;
7. the file and version helpers ``scenarios/atomic.py`` and ``scenarios/versions.py`` import
   nothing of the project but ``scenarios.errors``, so every layer can use them;
8. goal and coupling records (``scenegraph/world/goals``) and the measures they use
   (``scenegraph/world/measure.py``) never import the Scene (``scenegraph.world.scene`` builds them);
9. the stage auditor (``scenegraph/stage_audit/``) reads the stage only: it imports no
   other ``scenegraph`` module (not the transcription, the residual kernels, the dynamics
   or the body model) and no CasADi — it is the independent check of them;
10. the layers are sub-packages in the order of ``LAYERS``, and a module imports only from
    its own layer or layers before it (no upward imports); every module belongs to a layer.
"""
from __future__ import annotations

import ast
import os
import subprocess
import sys
from functools import lru_cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("scenarios", "scenegraph", "schedules")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


@lru_cache(maxsize=None)
def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for p in sorted((ROOT / pkg).rglob("*.py")):
            out[_module_name(p)] = p
    return out


def _is_package(mod: str) -> bool:
    return _modules()[mod].name == "__init__.py"


def _resolve(mod: str, node: ast.ImportFrom) -> str:
    """The absolute module named by a (possibly relative) ``from X import …``."""
    if not node.level:
        return node.module or ""
    base = mod.split(".") if _is_package(mod) else mod.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _targets(mod: str, node: ast.AST) -> list[str]:
    """Modules an import statement names: project modules by full name, others by top-level name."""
    mods = _modules()
    names: list[str] = []
    if isinstance(node, ast.Import):
        names = [a.name for a in node.names]
    elif isinstance(node, ast.ImportFrom):
        src = _resolve(mod, node)
        for a in node.names:  # ``from pkg import sub`` names the submodule ``pkg.sub``
            names.append(f"{src}.{a.name}" if f"{src}.{a.name}" in mods else src)
    out = []
    for n in names:
        if n.split(".")[0] in PACKAGES:
            while n not in mods and "." in n:  # ``import a.b.attr`` → the module a.b
                n = n.rsplit(".", 1)[0]
            out.append(n)
        else:
            out.append(n.split(".")[0])
    return out


@lru_cache(maxsize=None)
def _imports(mod: str) -> tuple[frozenset, frozenset]:
    """(every import, module-level imports only) of one project module."""
    tree = ast.parse(_modules()[mod].read_text(encoding="utf-8"))
    every, top = set(), set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            every.update(_targets(mod, node))
    for node in tree.body:  # module level: also inside top-level if/try blocks, not in defs/classes
        for sub in ast.walk(node) if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) \
                else ():
            if isinstance(sub, (ast.Import, ast.ImportFrom)):
                top.update(_targets(mod, sub))
    every.discard(mod)
    top.discard(mod)
    return frozenset(every), frozenset(top)


def _graph(module_level_only: bool = False) -> dict[str, set[str]]:
    mods = _modules()
    return {m: {t for t in _imports(m)[1 if module_level_only else 0] if t in mods} for m in mods}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def _violations(sources: str, forbidden: str) -> list[str]:
    """``module -> target`` for every import from a module under ``sources`` of one under ``forbidden``."""
    under = lambda m, p: m == p or m.startswith(p + ".")  # noqa: E731
    return [f"{m} -> {t}" for m, ts in sorted(_graph().items()) if under(m, sources)
            for t in sorted(ts) if under(t, forbidden)]


def _module_level_closure(start: str) -> set[str]:
    """Everything importing ``start`` loads: module-level imports, transitively, plus parent packages."""
    mods = _modules()
    seen, todo, external = set(), [start], set()
    while todo:
        m = todo.pop()
        if m in seen:
            continue
        seen.add(m)
        parts = m.split(".")
        todo.extend(".".join(parts[:i]) for i in range(1, len(parts)))  # parent packages' __init__
        for t in _imports(m)[1]:
            (todo.append(t) if t in mods else external.add(t))
    return seen | external


def test_the_walk_sees_every_package_and_their_imports():
    mods = _modules()
    assert {"scenarios.schema", "scenegraph.model.body", "schedules.plan.compiler", "scenegraph.problem"} <= set(mods)
    assert "scenarios.schema" in _graph()["scenarios.loader"]
    assert "casadi" in _imports("scenegraph.problem.transcription")[1]


def test_no_import_cycles():
    assert _cycles(_graph()) == []


def test_language_imports_neither_the_model_nor_the_plan():
    assert _violations("scenarios", "scenegraph") + _violations("scenarios", "schedules") == []


def test_model_never_imports_the_plan():
    assert _violations("scenegraph", "schedules") == []


def test_audit_and_residual_never_see_the_transcription():
    bad = [f"{m} -> {t}" for m in ("scenegraph.model.audit", "scenegraph.model.residual")
           for t in sorted(_imports(m)[0]) if t == "scenegraph.problem" or t.startswith("scenegraph.problem.")]
    assert bad == []


def test_goal_records_never_import_the_scene():
    bad = [f"{m} -> {t}" for m in _modules() if m == "scenegraph.world.measure" or m.startswith("scenegraph.world.goals")
           for t in sorted(_imports(m)[0]) if t == "scenegraph.world.scene"]
    assert bad == []


def test_stage_auditor_reads_the_stage_only():
    mods = [m for m in _modules() if m == "scenegraph.stage_audit" or m.startswith("scenegraph.stage_audit.")]
    assert "scenegraph.stage_audit.reader" in mods
    bad = [f"{m} -> {t}" for m in mods for t in sorted(_imports(m)[0])
           if (t.startswith("scenegraph") and not t.startswith("scenegraph.stage_audit")) or t == "casadi"
           or t.startswith("schedules")]
    assert bad == []


def test_compiler_and_step_are_free_of_casadi():
    for m in ("schedules.plan.compiler", "schedules.plan.step"):
        loaded = _module_level_closure(m)
        assert "casadi" not in loaded, (m, sorted(x for x in loaded if x.split(".")[0] == "scenegraph"))


def test_compose_schedule_does_not_import_casadi():
    code = ("import sys\nfrom schedules.cli.main import main\nrc = main(['schedule', 'walk_to_run'])\n"
            "print('CASADI' if 'casadi' in sys.modules else 'NO-CASADI', rc)\n")
    env = dict(os.environ, OMP_NUM_THREADS="1")
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().splitlines()[-1] == "NO-CASADI 0", p.stdout[-2000:]


# the order of the computation in scenegraph/nio/ (its __init__ docstring): each module may
# import only the modules before it
NIO_ORDER = ("plausibility", "slide", "theta", "prior", "energy", "counterexamples", "records", "multi", "initial", "bundle", "gradient", "problem",
             "target", "resynthesis", "learn", "heldout", "sensitivity", "ranking")


def test_learning_is_on_top_of_the_model_and_ordered_inside():
    nio = {m for m in _modules() if m.startswith("scenegraph.nio.")}
    assert nio == {f"scenegraph.nio.{n}" for n in NIO_ORDER}, sorted(nio)
    outside = [v for v in _violations("scenegraph", "scenegraph.nio") if not v.startswith("scenegraph.nio")]
    assert outside == []
    backward = [f"{n} -> {t}" for i, n in enumerate(NIO_ORDER) for t in sorted(_graph()[f"scenegraph.nio.{n}"])
                if t.startswith("scenegraph.nio.") and NIO_ORDER.index(t.rsplit(".", 1)[1]) >= i]
    assert backward == []


def test_file_and_version_helpers_are_leaves():
    for m in ("scenarios.atomic", "scenarios.versions"):
        assert _graph()[m] <= {"scenarios.errors"}, (m, sorted(_graph()[m]))


# the pipeline's layers, in order (docs/architecture.md): a module may import its own layer
# and the layers before it.  ``scenegraph.stage_audit`` reads stages only (rule 9): it comes
# before the output that measures its own stages (``export.clip_edit``); the plan needs only
# the language, so it could come earlier, but placing it after scenegraph keeps one line.
LAYERS = ("scenarios", "scenegraph.model", "scenegraph.problem", "scenegraph.world", "scenegraph.mocap",
          "scenegraph.nio", "scenegraph.stage_audit", "scenegraph.export", "schedules.plan",
          "schedules.execution", "schedules.cli")
# package __init__ files above the layers: what they may re-export
ROOT_PACKAGES = {"scenegraph": "scenegraph.model", "schedules": "schedules.plan"}


def _layer(mod: str) -> int:
    best = -1
    for i, name in enumerate(LAYERS):
        if mod == name or mod.startswith(name + "."):
            best = i if best < 0 or len(name) > len(LAYERS[best]) else best
    return best


def test_every_module_belongs_to_a_layer():
    loose = [m for m in _modules() if _layer(m) < 0 and m not in ROOT_PACKAGES]
    assert loose == []


def test_no_upward_imports_between_layers():
    bad = []
    for m, ts in sorted(_graph().items()):
        own = _layer(ROOT_PACKAGES[m]) if m in ROOT_PACKAGES else _layer(m)
        for t in sorted(ts):
            if t in ROOT_PACKAGES:  # ``import scenegraph`` (for its path) loads only its __init__
                t = ROOT_PACKAGES[t]
            if _layer(t) > own:
                bad.append(f"{m} ({LAYERS[own]}) -> {t} ({LAYERS[_layer(t)]})")
    assert bad == []
