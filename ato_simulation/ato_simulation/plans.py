"""The plan of a run, once per scenario: the target curve (``profile_node.planner``) cached under
a digest of the scenario's content, its references sampled at the control instants, the stops
the run is judged at and the run's end. The offline loop (``ato_simulation.loop``) and the
graph's runner (``ato_bringup.runner``) both take their plans here.
"""

from __future__ import annotations

from collections import OrderedDict

from ato_common.identity import Undescribable, scenario_hash
from ato_common.metrics import StopSample
from ato_common.scenario import Scenario
from ato_common.types import NS_PER_S
from profile_node.planner import Plan, plan_reference


def stop_samples(plan: Plan, replans: tuple[Plan, ...] = ()) -> list[StopSample]:
    """Each stop sampled at its departure in the last plan that has it (a replan's)."""
    stops = {s.station.name: s for s in plan.stops}
    for later in replans:
        stops.update((s.station.name, s) for s in later.stops)
    return [StopSample(s.station.name, s.station.position_m, s.departure_s)
            for s in sorted(stops.values(), key=lambda s: s.station.position_m)]


def run_end_time_s(scenario: Scenario, plan: Plan) -> float:
    if scenario.run.end_time_s > 0.0:
        return scenario.run.end_time_s
    return plan.trajectory.end_time + scenario.run.settle_time_s


# --- the plan, once per scenario --------------------------------------------------------------
#
# A campaign runs the same nominal scenario thousands of times (every law, every draw: the draw
# perturbs only the plant's truth), and the target curve is a function of the scenario alone
# (``plan_reference(scenario)``). The plan is therefore cached here, at the call site, under a
# digest of the scenario's whole content: two scenarios loaded separately share it, two that
# differ anywhere (even under the same name) do not. The references the loop samples at its
# control instants are a function of the plan and the instants: cached beside it.

#: plans kept per process (each a few hundred kB), least recently used dropped first
PLAN_CACHE_SIZE = 16
#: sampled references kept per process, and the longest run whose samples are kept (a longer
#: one, e.g. 200 Hz over a whole line, samples them as it goes)
REFERENCE_CACHE_SIZE = 8
REFERENCE_CACHE_MAX_STEPS = 50_000

_plans: OrderedDict[str, Plan] = OrderedDict()
_references: OrderedDict[tuple, list] = OrderedDict()


def scenario_key(scenario: Scenario) -> str | None:
    """The digest of a scenario's whole content (``ato_common.identity.scenario_hash``, the
    plant's identity), or None if some part of it cannot be described: such a scenario is
    planned on every run."""
    try:
        return scenario_hash(scenario)
    except Undescribable:
        return None


def clear_plan_cache() -> None:
    """Forget every cached plan and sampled reference of this process (for a benchmark of
    the planning, or after changing what the planner reads from outside the scenario)."""
    _plans.clear()
    _references.clear()


def _remember(cache: OrderedDict, key, value, size: int):
    cache[key] = value
    cache.move_to_end(key)
    while len(cache) > size:
        cache.popitem(last=False)
    return value


def cached_plan(scenario: Scenario, key: str | None = None) -> Plan:
    """``plan_reference(scenario)``, planned once per scenario content in this process."""
    key = key or scenario_key(scenario)
    if key is None:
        return plan_reference(scenario)
    plan = _plans.get(key)
    if plan is None:
        return _remember(_plans, key, plan_reference(scenario), PLAN_CACHE_SIZE)
    _plans.move_to_end(key)
    return plan


def sampled_references(plan: Plan, key: str | None, period_ns: int, steps: int) -> list | None:
    """``plan.trajectory.at`` at the run's control instants k * period (k = 0..steps), as the
    simulation's clock gives them (integer nanoseconds over 1e9); None for a run too long to
    keep them (it samples them step by step)."""
    if steps + 1 > REFERENCE_CACHE_MAX_STEPS:
        return None
    at = plan.trajectory.at
    if key is None:
        return [at(k * period_ns / NS_PER_S) for k in range(steps + 1)]
    entry = (key, period_ns, steps)
    references = _references.get(entry)
    if references is None:
        references = _remember(_references, entry,
                               [at(k * period_ns / NS_PER_S) for k in range(steps + 1)],
                               REFERENCE_CACHE_SIZE)
    return references
