"""The plan of a run, once per scenario: the target curve (``profile_node.planner``) cached under
a digest of the scenario's content, its references sampled at the control instants, the stops
the run is judged at and the run's end. The offline loop (``ato_simulation.loop``) and the
graph's runner (``ato_bringup.runner``) both take their plans here.

The run's end follows the journey, not the clock alone (:class:`JourneyEnd`): a run whose
scenario states no end (``run.end_time_s`` 0) is planned to end ``settle_time_s`` after its
timetable's end (:func:`run_end_time_s`); if its train does not stand at its last stop then, it
goes on until the train has stood there for ``settle_time_s`` (a late arrival), at the latest
until a stated limit past the timetable (:func:`run_limit_time_s`: the timetable's end plus
``LATE_LIMIT_SHARE`` of its journey time, at least ``LATE_LIMIT_MIN_S``). A train that has not
arrived by then did not finish.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from ato_common.identity import Undescribable, scenario_hash
from ato_common.metrics import StopSample
from ato_common.run_events import STANDSTILL_MPS
from ato_common.scenario import Scenario
from ato_common.types import NS_PER_S
from profile_node.planner import Plan, plan_reference

#: how long a run may go on past its timetable's end for a late train to arrive: this share of
#: the timetable's journey time, at least LATE_LIMIT_MIN_S (a suite setting: room for a train
#: that has lost part of its traction to arrive; one that has not arrived by then is stranded,
#: not late)
LATE_LIMIT_SHARE = 0.5
LATE_LIMIT_MIN_S = 60.0


def stop_samples(plan: Plan, replans: tuple[Plan, ...] = (),
                 late: tuple[tuple[str, float], ...] = ()) -> list[StopSample]:
    """Each stop sampled at its departure in the last plan that has it (a replan's); the stops
    that ``late`` pairs with a time (:func:`late_readings`: the train was not at the stop at
    its planned time in a run that went on past its planned end) at that time."""
    stops = {s.station.name: s for s in plan.stops}
    for later in replans:
        stops.update((s.station.name, s) for s in later.stops)
    readings = dict(late)
    return [StopSample(s.station.name, s.station.position_m,
                       readings.get(s.station.name, s.departure_s))
            for s in sorted(stops.values(), key=lambda s: s.station.position_m)]


def follows_journey(scenario: Scenario) -> bool:
    """Whether the run's end follows the journey (the scenario states no end of its own)."""
    return not scenario.run.end_time_s > 0.0


def run_end_time_s(scenario: Scenario, plan: Plan) -> float:
    """The run's planned end: the scenario's stated end, else ``settle_time_s`` after the end
    of ``plan`` (the timetable). A run whose train stands at its last stop then ends there (the
    graph's runs always do: a plant's end is fixed when it starts); the offline loop lets a
    late train arrive, up to :func:`run_limit_time_s`."""
    if not follows_journey(scenario):
        return scenario.run.end_time_s
    return plan.trajectory.end_time + scenario.run.settle_time_s


def run_limit_time_s(scenario: Scenario, plan: Plan) -> float:
    """The latest end of a run: the scenario's stated end, else the planned end
    (:func:`run_end_time_s`) plus LATE_LIMIT_SHARE of the timetable's journey time, at least
    LATE_LIMIT_MIN_S."""
    if not follows_journey(scenario):
        return scenario.run.end_time_s
    journey = plan.trajectory.end_time - plan.trajectory.start_time
    return run_end_time_s(scenario, plan) + max(LATE_LIMIT_MIN_S, LATE_LIMIT_SHARE * journey)


@dataclass(frozen=True)
class JourneyEnd:
    """When a run that follows its journey ends: at ``planned_s`` (the later of the
    timetable's and the plan in force's planned ends; a replan aimed past the limit is cut
    there) if the train then stands within its length (``reach_m``) of the last stop at
    ``stop_m``, else once it has stood there for ``settle_s``, at the latest at ``limit_s``."""

    stop_m: float
    reach_m: float
    settle_s: float
    planned_s: float
    limit_s: float

    @classmethod
    def of(cls, scenario: Scenario, timetable: Plan, in_force: Plan | None = None
           ) -> 'JourneyEnd | None':
        """The end rule of a run of ``scenario`` whose timetable is ``timetable`` and whose
        plan in force is ``in_force`` (a replan's; default the timetable); None for a run with
        a stated end or a plan without stops."""
        plan = in_force or timetable
        if not follows_journey(scenario) or not plan.stops:
            return None
        limit = run_limit_time_s(scenario, timetable)
        planned = max(run_end_time_s(scenario, plan), run_end_time_s(scenario, timetable))
        return cls(plan.stops[-1].station.position_m, scenario.train.length_m,
                   scenario.run.settle_time_s, min(planned, limit), limit)

    def at_stop(self, position_m: float, speed_mps: float) -> bool:
        return abs(speed_mps) <= STANDSTILL_MPS and abs(position_m - self.stop_m) <= self.reach_m

    def remaining_s(self, times_s, positions, speeds) -> float:
        """Simulated time the run must still go on after its last sample (0: it ends there),
        from the lead car's true ``positions`` and ``speeds`` so far (newest last; read from
        the end, as far back as the train has stood at the stop). Asked first at the last
        sample of the planned end, then at each sample the answer before leads to."""
        now = times_s[-1]
        if now >= self.limit_s - 1e-9:
            return 0.0
        k = len(times_s) - 1
        while k >= 0 and self.at_stop(positions[k], speeds[k]):
            k -= 1
        if k == len(times_s) - 1:  # not standing at the stop: look again a settle time on
            return min(self.settle_s, self.limit_s - now)
        if now <= self.planned_s + 1e-9:  # standing there at the planned end
            return 0.0
        stood = now - times_s[k + 1]
        return max(0.0, min(self.settle_s - stood, self.limit_s - now))


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


def late_readings(stops: list[StopSample], times_s, positions, speeds, reach_m: float
                  ) -> tuple[tuple[str, float], ...]:
    """For a run that went on past its planned end (a late train), where each stop's error is
    read instead: a stop at whose planned reading time the train did not stand within
    ``reach_m`` of it is read at the end of its last standstill there (a stop it never stood
    at keeps its planned time: the error there says how far off it was)."""
    t, x, v = (np.asarray(a, dtype=float) for a in (times_s, positions, speeds))
    standing = np.abs(v) <= STANDSTILL_MPS
    readings = []
    for stop in stops:
        near = standing & (np.abs(x - stop.station_position_m) <= reach_m)
        planned = min(int(np.searchsorted(t, stop.time_s, side='right')) - 1, t.size - 1)
        if planned >= 0 and near[planned]:
            continue
        stood = np.flatnonzero(near)
        if stood.size and stood[-1] > planned:
            readings.append((stop.station, float(t[stood[-1]])))
    return tuple(readings)
