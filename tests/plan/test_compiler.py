"""The schedule compiler: kinds chosen per bundled scenario and partial-order properties of the graph."""
from __future__ import annotations

import itertools
from pathlib import Path

import networkx as nx
import pytest

from scenarios import bundled_scenarios, load_scenario, parse_scenario
from scenarios.bundled import bundled_syntheses
from schedules import (COUPLED, DECREASING_HORIZON, JOINT, TIME_LAYERED, TIMEWARP, Schedule, Step,
                       compile_schedule)
from schedules.cli.main import main
from schedules.plan.compiler import layer_windows, timing_steps
from scenarios.weights import AVOID_WEIGHT, START_WEIGHT, TARGET_WEIGHT

FULL = Path(__file__).resolve().parents[1] / "scenarios" / "full.yaml"


def _compile(name_or_text: str, extra: str = "") -> Schedule:
    if extra or "\n" in name_or_text:
        text = name_or_text if "\n" in name_or_text else bundled_scenarios()[name_or_text].read_text()
        return compile_schedule(parse_scenario(text + extra, "t.yaml"))
    return compile_schedule(load_scenario(name_or_text))


def _blocks(s: Schedule) -> dict[str, list[Step]]:
    """Steps grouped by their subproblem (id without the /timing|/full suffix)."""
    out: dict[str, list[Step]] = {}
    for st in s.order():
        out.setdefault(st.id.rsplit("/", 1)[0], []).append(st)
    return out


# --- kinds chosen per bundled scenario ------------------------------------------------------------

KINDS = [
    # scenario, kinds of the schedule, number of independent branches
    # no bundled scene has timing: free, so none has a timing step (the timewarp schedule)
    ("walk", set(), 1),
    ("walk_to", set(), 1),
    ("two_walkers", set(), 2),
    ("walk_to_run", {TIME_LAYERED}, 1),
    ("handhold", {COUPLED}, 1),
    ("handhold_child_adapts", {COUPLED}, 1),
    ("crowd", {COUPLED}, 6),
    ("tackle", {DECREASING_HORIZON}, 1),
    ("tackle_dodge", {DECREASING_HORIZON}, 1),
    ("two_tacklers", {DECREASING_HORIZON}, 1),
    # edits of one style (paper §7): the walk's shape, one subproblem each
    ("suitcase", set(), 1),
    ("limp", set(), 1),
    ("uphill", set(), 1),
    ("downhill", set(), 1),
    ("turn180", set(), 1),
    ("springy_run", set(), 1),
    # jumps: take-off and landing times given, no timing step (schedule.timewarp: false)
    ("broad_jump", set(), 1),
    ("twist_jump", set(), 1),
    ("run_and_leap", set(), 1),  # a run-up, a leap, a run on: one whole-scene step
    ("hopscotch", {TIME_LAYERED}, 1),  # three leaps in 1 s windows and a seam (schedule.kind)
]


def test_every_bundled_scenario_has_a_row():
    assert {row[0] for row in KINDS} == set(bundled_syntheses())
    assert set(bundled_scenarios()) - set(bundled_syntheses()) == {"edit_broad_jump"}  # edits have no schedule


def test_an_edit_scenario_has_no_schedule():
    with pytest.raises(Exception) as e:
        compile_schedule(load_scenario("edit_broad_jump"))
    assert "edit_broad_jump.yaml:" in str(e.value) and "has no schedule" in str(e.value)


@pytest.mark.parametrize("name,kinds,branches", KINDS)
def test_kinds_chosen(name, kinds, branches):
    s = _compile(name)
    assert s.kinds == kinds
    assert len(s.groups) == branches
    assert nx.number_weakly_connected_components(s.graph) == branches


@pytest.mark.parametrize("name", list(bundled_syntheses()) + [str(FULL)])  # an edit has no schedule
def test_general_properties(name):
    s = _compile(name)
    g = s.graph
    assert nx.is_directed_acyclic_graph(g)
    order = s.order()
    pos = {st.id: i for i, st in enumerate(order)}
    assert len(pos) == len(s) == g.number_of_nodes()
    assert all(pos[a] < pos[b] for a, b in g.edges()), "order() must be a topological order"
    # with timing steps (timing: free, or schedule.timewarp: true): timing (relaxed dynamics) then
    # full (hard dynamics); a time-layered branch solves its timing once over the whole duration,
    # its windows full only.  Without: one full step, the timewarp held unless schedule.timewarp: false
    layered = {gr.name for gr in s.groups if TIME_LAYERED in gr.kinds
               if any(st.role == "whole" and st.group == gr.name for st in order)}
    for block, steps in _blocks(s).items():
        if steps[0].group in layered:
            kinds = [st.kind for st in steps]
            timed = any(st.kind == "timing" for st in order)  # off with schedule.timewarp: false (hopscotch)
            assert kinds == (["timing", "full"] if steps[0].role == "whole" and timed else ["full"]), block
            if steps[0].role == "whole" and timed:
                timing, full = steps
                assert timing.window == full.window == (0.0, load_scenario(name).duration)
                # the timewarp is free unless the character changes gait (its footstep plan times it)
                gait_change = any(getattr(g, "gait", None) for g in load_scenario(name).goals
                                  if getattr(g, "character", None) in timing.characters)
                assert ("timewarp" in timing.free) != gait_change
                later = [st for st in order if set(st.characters) & set(timing.characters) and st not in steps]
                assert all(s.has_path(full.id, st.id) for st in later)
            continue
        coupled_later = {COUPLED, DECREASING_HORIZON} & set(next(gr.kinds for gr in s.groups
                                                                 if gr.name == steps[0].group)) \
            and steps[0].cycle > 1
        if coupled_later:  # coupled and decreasing-horizon schedules settle the timing in their first cycle
            assert [st.kind for st in steps] == ["full"], block
            continue
        if steps[0].role in ("window", "seam"):  # windows hold the (global) timewarp: full steps only
            assert [st.kind for st in steps] == ["full"], block
            assert all("timewarp" not in st.free for st in steps), block
            continue
        spec = load_scenario(name).schedule
        if not timing_steps(load_scenario(name)) and (spec is None or spec.timewarp is None):
            # the default without timing: free: one full step, the timewarp held (the footstep plan times it)
            assert [st.kind for st in steps] == ["full"] and "timewarp" not in steps[0].free, block
            continue
        if spec is not None and spec.timewarp is False:  # schedule.timewarp: false (the jumps): no timing step
            # the full step times it, unless leaps with given times hold the warp (their take-off and landing)
            timed = any(getattr(g, "type", "") in ("jump", "hop") and (g.takeoff.time is not None
                        or g.landing.time is not None) for g in load_scenario(name).goals)
            assert [st.kind for st in steps] == ["full"] and ("timewarp" in steps[0].free) != timed, block
            continue
        assert [st.kind for st in steps] == ["timing", "full"], block
        timing, full = steps
        assert g.has_edge(timing.id, full.id)
        assert timing.term("dynamics") == "relaxed" and full.term("dynamics") == "hard"
        assert "timewarp" in timing.free and "lambda" in full.free
        assert TIMEWARP in timing.schedules
    for st in order:
        assert 0.0 <= st.window[0] < st.window[1] <= load_scenario(name).duration + 1e-9
        assert st.term("energy") == 1.0
        assert {t.character for t in st.styles} == set(st.characters)
        assert st.group in {gr.name for gr in s.groups}
    # no edges between branches
    for a, b in g.edges():
        assert s.step(a).group == s.step(b).group
    # the same scenario always gives the same graph and order
    again = _compile(name)
    assert again.to_data() == s.to_data()
    assert [st.id for st in again.order()] == [st.id for st in order]


# --- partial-order properties ---------------------------------------------------------------------

def test_walk_is_one_full_step_on_explicit_footprints():
    s = _compile("walk")
    assert [st.id for st in s.order()] == ["walker/c1/whole/full"]
    full = s.order()[-1]
    assert "timewarp" not in full.free  # the footprints' times are the motion's
    assert "footprints" not in full.free  # explicit footprints are fixed
    assert full.goals == ("footprints_0",) and full.term("goal:footprints_0") == "hard"
    assert full.term("start") == START_WEIGHT  # the start is a soft spring (executor), not a constraint


def test_walk_to_frees_the_footprints():
    s = _compile("walk_to")
    assert all("footprints" in st.free for st in s.order())
    assert all(st.goals == ("walk_to_0",) for st in s.order())


def test_independent_characters_have_no_path_between_their_steps():
    s = _compile("two_walkers")
    alice = [st.id for st in s.steps_of("alice")]
    bob = [st.id for st in s.steps_of("bob")]
    assert alice and bob
    for a, b in itertools.product(alice, bob):
        assert not s.has_path(a, b) and not s.has_path(b, a)
    assert all(not st.observes for st in s.order())
    # they may run in parallel: the first generation holds both characters
    assert {st.characters for st in s.generations()[0]} == {("alice",), ("bob",)}


def test_time_layered_seam_runs_after_both_windows():
    s = _compile("walk_to_run")
    steps = s.order()
    whole = s.step("runner/c1/whole/full")
    assert steps[0] is whole and whole.window == (0.0, 2.0)
    assert max(st.cycle for st in steps) == 1  # solved whole first: one layered cycle by default
    for cycle in (1,):
        w0 = s.step(f"runner/c{cycle}/w0/full")
        w1 = s.step(f"runner/c{cycle}/w1/full")
        seam = s.step(f"runner/c{cycle}/seam0/full")
        assert s.has_path(whole.id, w0.id) and s.has_path(whole.id, w1.id)
        assert w0.window[1] == w1.window[0] == 1.0  # windows abut at the style change
        assert seam.window[0] < 1.0 < seam.window[1] and seam.seam == 1.0 and seam.role == "seam"
        assert s.has_path(w0.id, seam.id) and s.has_path(w1.id, seam.id)
        # A and B of one cycle are independent
        assert not s.has_path(w0.id, w1.id) and not s.has_path(w1.id, w0.id)
        # endpoint conditions from the neighbours
        assert w0.term("boundary:end") == "hard" and w0.term("start") == START_WEIGHT
        assert w1.term("boundary:start") == "hard" and w1.term("boundary:end") is None
        assert seam.term("boundary:start") == seam.term("boundary:end") == "hard"
        assert all(st.kind == "full" for st in (w0, w1, seam))
    # with more cycles, the next cycle's windows run after the previous seam
    s2 = _compile("walk_to_run", "schedule: {cycles: 2}\n")
    assert s2.has_path("runner/c1/seam0/full", "runner/c2/w0/full")
    assert s2.has_path("runner/c1/seam0/full", "runner/c2/w1/full")
    # θ interpolated across the seam window
    seam = s.step("runner/c1/seam0/full")
    (timeline,) = seam.styles
    assert [t for t, _ in timeline.keys] == [0.0, seam.window[0], seam.window[1]]
    assert steps[-1].role == "seam"


def test_style_blend_is_linear_across_the_seam():
    s = _compile("walk_to_run")
    (tl,) = s.step("runner/c1/seam0/full").styles
    assert [t for t, _ in tl.keys] == [0.0, 0.5, 1.5]  # the blend spans the seam window
    s = _compile(str(FULL))
    (tl,) = next(st for st in s.order() if st.characters == ("mother",)).styles
    assert tl.at(1.0) == ("custom.style.yaml", "custom.style.yaml", 0.0)
    assert tl.at(1.4) == ("custom.style.yaml", "default", pytest.approx(0.25))
    assert tl.at(2.5) == ("default", "default", 0.0)


def test_coupled_characters_alternate_with_rising_stiffness():
    s = _compile("handhold")
    fulls = [st for st in s.order() if st.kind == "full"]
    assert [st.characters[0] for st in fulls] == ["adult", "child"] * 4
    stiff = [st.stiffness for st in fulls]
    assert all(k is not None for k in stiff)
    assert all(b >= a for a, b in zip(stiff, stiff[1:])), stiff
    per_cycle = {st.cycle: st.stiffness for st in fulls}
    assert all(per_cycle[c + 1] > per_cycle[c] for c in range(1, 4))
    for st in s.order():
        assert st.term("coupling:hold") == st.stiffness
        assert st.observes == (("child",) if st.characters == ("adult",) else ("adult",))
    # strictly alternating: a single chain
    assert all(len(gen) == 1 for gen in s.generations())


def test_solves_per_cycle_decides_who_adapts_more():
    s = _compile("handhold", "schedule:\n  solves_per_cycle: {adult: 3}\n  cycles: 2\n")
    fulls = [st for st in s.order() if st.kind == "full"]
    assert [st.characters[0] for st in fulls] == ["adult", "child", "adult", "adult"] * 2
    assert {st.repeat for st in fulls if st.characters == ("adult",)} == {1, 2, 3}
    # the one solved more often also goes first (it makes the first move toward the partner)
    s = _compile("handhold_child_adapts")
    fulls = [st for st in s.order() if st.kind == "full"]
    assert [st.characters[0] for st in fulls] == ["child", "adult", "child"] * 4
    assert s.order()[0].characters == ("child",)
    # coupled schedules settle the timing in their first cycle (with timing steps asked for)
    text = bundled_scenarios()["handhold_child_adapts"].read_text().replace("schedule:\n", "schedule:\n  timewarp: true\n")
    s = _compile(text)
    assert s.order()[0].kind == "timing"
    assert {st.cycle for st in s.order() if st.kind == "timing"} == {1}


def test_stiffness_schedule_parameters():
    s = _compile("handhold", "schedule:\n  stiffness_start: 10\n  stiffness_increase: 0\n"
                             "  stiffness_factor: 10\n  cycles: 3\n")
    assert sorted({st.stiffness for st in s.order()}) == [10.0, 100.0, 1000.0]


def test_decreasing_horizon_shrinks_and_planner_last_is_last():
    s = _compile("tackle")
    fulls = [st for st in s.order() if st.kind == "full"]
    assert [st.characters[0] for st in fulls] == ["dodger", "tackler"] * 3
    assert s.order()[-1].characters == ("tackler",)  # plans_last: tackler
    by_cycle: dict[int, set] = {}
    for st in fulls:
        by_cycle.setdefault(st.cycle, set()).add(st.window)
    windows = [by_cycle[c].pop() for c in sorted(by_cycle)]
    assert all(len(by_cycle[c]) == 0 for c in by_cycle)  # one window per cycle
    lengths = [b - a for a, b in windows]
    assert all(b < a for a, b in zip(lengths, lengths[1:])), lengths
    t_hit = 1.0
    before = [t_hit - a for a, _ in windows]  # time left to react before the impact halves
    assert before == pytest.approx([1.0, 0.5, 0.25])
    assert all(b == pytest.approx(1.1) for _, b in windows)  # to the end of the scenario (0.1 s past the impact)
    for st in fulls:
        assert st.role == "horizon"
        if st.characters == ("tackler",):
            assert "hit" in st.goals and st.term("goal:hit") == TARGET_WEIGHT  # soft springs (scene.goal_targets)
        else:
            assert "dodge" in st.goals and st.term("goal:dodge") == AVOID_WEIGHT
            assert not any(n.startswith("impact:") for n, _ in st.terms)  # the impact force is not modelled
        assert (st.term("start") == START_WEIGHT) == (st.window[0] == 0.0)
        assert (st.term("boundary:start") == "hard") == (st.window[0] > 0.0)


def test_plans_last_decides_the_order():
    text = bundled_scenarios()["tackle"].read_text().replace("plans_last: tackler", "plans_last: dodger")
    s = compile_schedule(parse_scenario(text, "t.yaml"))
    assert s.order()[-1].characters == ("dodger",)
    fulls = [st for st in s.order() if st.kind == "full"]
    assert [st.characters[0] for st in fulls] == ["tackler", "dodger"] * 3
    # the bundled variant that differs only in who plans last compiles to the same order
    d = _compile("tackle_dodge")
    assert [st.id for st in d.order()] == [st.id for st in s.order()]
    assert [st.window for st in d.order()] == [st.window for st in s.order()]


def test_two_tacklers_one_horizon_branch_target_last():
    s = _compile("two_tacklers")
    assert len(s.groups) == 1
    fulls = [st for st in s.order() if st.kind == "full"]
    per_cycle = {}
    for st in fulls:
        per_cycle.setdefault(st.cycle, []).append(st)
    assert sorted(per_cycle) == [1, 2, 3]
    for cycle, sts in per_cycle.items():
        assert {st.characters[0] for st in sts} == {"dodger", "left_tackler", "right_tackler"}
        assert len({st.window for st in sts}) == 1
        assert sts[-1].characters == ("dodger",)  # plans last in every cycle
        # the two tacklers do not depend on each other within a cycle
        a, b = [st for st in sts if st.characters[0] != "dodger"]
        assert not s.has_path(a.id, b.id) and not s.has_path(b.id, a.id)
    assert [per_cycle[c][0].window[0] for c in (1, 2, 3)] == pytest.approx([0.0, 0.5, 0.75])


def test_long_duration_is_time_layered_within_max_window():
    text = bundled_scenarios()["walk_to"].read_text().replace("duration: 1.4", "duration: 6.0") \
        .replace("time: 1.4", "time: 6.0")
    s = compile_schedule(parse_scenario(text, "t.yaml"))
    assert TIME_LAYERED in s.kinds
    order = s.order()
    assert all(st.duration <= 2.5 + 1e-9 for st in order)
    # one character, one style: receding windows, each after the one before, overlapping by
    # half, every one a full step; only the last one holds no free end
    assert [st.role for st in order] == ["receding"] * len(order) and all(st.kind == "full" for st in order)
    assert order[0].window[0] == 0.0 and order[-1].window[1] == 6.0
    for a, b in zip(order, order[1:]):
        assert s.has_path(a.id, b.id)
        assert a.window[0] < b.window[0] < a.window[1]
    assert [st.term("boundary:end") for st in order] == ["free"] * (len(order) - 1) + [None]
    # cost linear in the duration: twice as long, about twice the windows
    s2 = compile_schedule(parse_scenario(text.replace("6.0", "12.0"), "t.yaml"))
    assert len(s2) <= 2 * len(s) + 1


def test_long_duration_with_a_style_change_keeps_windows_and_seams():
    text = bundled_scenarios()["walk_to_run"].read_text()
    s = compile_schedule(parse_scenario(text, "t.yaml"))
    roles = {st.role for st in s.order()}
    assert "seam" in roles and "receding" not in roles


def test_full_scenario_branches():
    s = _compile(str(FULL))
    groups = {g.name: g for g in s.groups}
    assert set(groups) == {"child+mother", "dodger+tackler", "porter_a+porter_b", "jumper", "hopper"}
    assert set(groups["child+mother"].kinds) == {COUPLED, TIME_LAYERED, TIMEWARP}
    assert set(groups["dodger+tackler"].kinds) == {DECREASING_HORIZON, TIMEWARP}
    assert set(groups["porter_a+porter_b"].kinds) == {COUPLED, TIME_LAYERED, TIMEWARP}
    # the dodger plans last in its branch
    horizon = [st for st in s.order() if st.group == "dodger+tackler"]
    assert horizon[-1].characters == ("dodger",)
    # solves_per_cycle {child: 2}: the child is solved twice per window and cycle
    child = [st for st in s.order() if st.characters == ("child",) and st.kind == "full" and st.cycle == 1]
    mother = [st for st in s.order() if st.characters == ("mother",) and st.kind == "full" and st.cycle == 1]
    assert len(child) == 2 * len(mother)
    # the mother's style blends over the change's own `blend` (0.4 s around 1.5 s)
    mom = next(st for st in s.order() if st.characters == ("mother",))
    assert mom.styles[0].keys == ((0.0, "custom.style.yaml"), (1.3, "custom.style.yaml"), (1.7, "default"))
    # free timing: the duration is free in timing steps that reach the end
    assert any("duration" in st.free for st in s.order() if st.kind == "timing")


@pytest.mark.parametrize("kind,expect", [
    ("timewarp", {JOINT}),  # no timing step without timing: free (the kind still solves jointly)
    ("time_layered", {JOINT, TIME_LAYERED}),
    ("coupled", {COUPLED}),
    ("decreasing_horizon", {DECREASING_HORIZON}),
])
def test_explicit_schedule_overrides_the_compiler(kind, expect):
    s = _compile("handhold", f"schedule:\n  kind: {kind}\n  cycles: 2\n")
    assert s.kinds == expect
    if kind in ("timewarp", "time_layered"):
        assert all(st.characters == ("adult", "child") for st in s.order())
        assert all(st.term("coupling:hold") == "hard" and "coupling_forces" in st.free
                   for st in s.order() if st.kind == "full")


def test_explicit_schedule_can_drop_the_timing_step():
    s = _compile("walk", "schedule:\n  timewarp: false\n")
    assert [st.kind for st in s.order()] == ["full"]
    assert "timewarp" in s.order()[0].free and TIMEWARP not in s.kinds


def test_timing_steps_only_where_the_duration_is_free():
    """By default a whole-scene subproblem gets a timing step only with ``timing: free`` (its free
    duration rides on the timewarp, which only a timing step frees); with the duration fixed the
    full step holds the warp — every such timing step ended at its cap and was discarded
    (docs/results.md, round 14).  ``schedule.timewarp`` overrides both ways."""
    free = _compile("walk_to", "timing: free\nduration_bounds: [1.0, 2.0]\n")
    timing, full = free.order()
    assert (timing.kind, full.kind) == ("timing", "full") and free.has_path(timing.id, full.id)
    assert {"timewarp", "duration"} <= set(timing.free) and "timewarp" not in full.free
    assert TIMEWARP in free.kinds
    fixed = _compile("walk_to")
    assert [(st.kind, "timewarp" in st.free) for st in fixed.order()] == [("full", False)]
    assert any("no timing step" in r for r in fixed.groups[0].reasons)  # `compose schedule` says why
    forced = _compile("walk_to", "schedule:\n  timewarp: true\n")
    assert [st.kind for st in forced.order()] == ["timing", "full"] and "timewarp" in forced.order()[0].free
    off = _compile("walk_to", "timing: free\nduration_bounds: [1.0, 2.0]\nschedule:\n  timewarp: false\n")
    assert [st.kind for st in off.order()] == ["full"] and {"timewarp", "duration"} <= set(off.order()[0].free)


def test_schedule_timewarp_must_be_a_boolean_or_null():
    assert _compile("walk", "schedule:\n  timewarp: null\n").order()[0].kind == "full"
    with pytest.raises(Exception) as e:
        _compile("walk", "schedule:\n  timewarp: 1\n")
    assert "timewarp" in str(e.value)


def test_explicit_coupled_puts_everyone_in_one_branch():
    s = _compile("two_walkers", "schedule:\n  kind: coupled\n")
    assert len(s.groups) == 1 and s.kinds == {COUPLED}


# --- windows -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("T,cuts,maxw,seam,windows,seams", [
    (2.0, [1.0], 2.5, None, [(0, 1), (1, 2)], [(0.5, 1.5, 1.0)]),
    (2.0, [], 2.5, None, [(0, 2)], []),
    (5.0, [], 2.0, None, [(0, 5 / 3), (5 / 3, 10 / 3), (10 / 3, 5)],
     [(5 / 6, 2.5, 5 / 3), (2.5, 25 / 6, 10 / 3)]),
    (3.0, [0.5], 2.5, 0.4, [(0, 0.5), (0.5, 3.0)], [(0.3, 0.7, 0.5)]),
    (3.0, [0.5], 2.5, 5.0, [(0, 0.5), (0.5, 3.0)], [(0.0, 1.0, 0.5)]),
])
def test_layer_windows(T, cuts, maxw, seam, windows, seams):
    w, s = layer_windows(T, cuts, maxw, seam)
    flat = lambda pairs: [x for pair in pairs for x in pair]  # noqa: E731 (approx takes flat lists only)
    assert len(w) == len(windows) and flat(w) == pytest.approx(flat(windows))
    assert len(s) == len(seams) and flat(s) == pytest.approx(flat(seams))
    assert all(b - a <= maxw + 1e-9 for a, b in w)


# --- rendering and the CLI ------------------------------------------------------------------------------

def test_text_and_dot_rendering(tmp_path):
    s = _compile("handhold")
    text = s.to_text()
    assert all(st.id in text for st in s.order())
    assert "coupled" in text.splitlines()[0]
    dot = s.to_dot()
    assert dot.startswith("digraph") and dot.rstrip().endswith("}")
    for a, b in s.graph.edges():
        assert f'"{a}" -> "{b}";' in dot
    path = tmp_path / "s.dot"
    s.write_dot(path)
    assert path.read_text() == dot


def test_schedule_command_by_bundled_name(tmp_path, capsys):
    out = tmp_path / "tackle.dot"
    assert main(["schedule", "tackle", "--dot", str(out)]) == 0
    text = capsys.readouterr().out
    assert "decreasing_horizon" in text and "tackler/c3/horizon/full" in text
    assert out.read_text().startswith("digraph")


def test_schedule_png_needs_graphviz(tmp_path, capsys, monkeypatch):
    import shutil as _shutil
    monkeypatch.setattr(_shutil, "which", lambda name: None)
    assert main(["schedule", "walk", "--png", str(tmp_path / "x.png")]) == 2
    assert "graphviz" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_schedule_json_round_trips(capsys):
    import json
    assert main(["schedule", "walk_to_run", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert [s["id"] for s in data["steps"]] == [s.id for s in _compile("walk_to_run").order()]


def test_a_schedule_without_schedule_kinds_says_what_it_runs():
    """A plain walk has no timing step since round 14 (and so no schedule kind): `compose schedule`
    says it runs one full step per subproblem instead of printing an empty list."""
    head = compile_schedule(load_scenario("walk")).to_text().splitlines()[0]
    assert head.endswith("kinds: one full step per subproblem"), head
    assert "kinds: one full step" not in compile_schedule(load_scenario("handhold")).to_text().splitlines()[0]
