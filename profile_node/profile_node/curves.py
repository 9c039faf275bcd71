"""Plot the target curve of scenarios: ``python -m profile_node.curves [SCENARIO ...] [-o DIR]``
(``make curves``). One PNG per scenario: speed against distance with the static limits, the
MRSP, the supervision's EBD, EBI, SBD, permitted and indication curves and the ATO target; speed
against time with the permitted speed at the target's position; and position against time with
the journey's time windows. The target is drawn twice: the ``fastest`` curve and the
``timetable`` one (least energy on time: the journey's times, or the scenario's running-time
supplement), whichever the scenario drives. Without names: every built-in scenario."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from ato_common import units
from ato_common.scenario import builtin_scenarios, load_scenario
from ato_common.validation import ConfigError
from profile_node.planner import Plan, PlanningError, plan_reference

SUPERVISION_STYLES = (('ebd', 'EBD', 'tab:red', ':'), ('ebi', 'EBI', 'tab:red', '-'),
                      ('sbd', 'SBD', 'tab:orange', ':'), ('permitted', 'permitted', 'tab:orange',
                                                          '-'),
                      ('indication', 'indication', 'tab:olive', '--'))
POINTS_PER_LEG = 3000


def curve_data(scenario, plan: Plan, step_s: float = 1.0) -> dict[str, np.ndarray]:
    """The arrays plotted, in SI: the target against time, and each supervision curve against
    position over its leg (NaN separates legs)."""
    times = np.arange(0.0, plan.trajectory.end_time + step_s, step_s)
    points = [plan.trajectory.at(t) for t in times]
    data = {'time_s': times, 'position_m': np.array([p.position for p in points]),
            'speed_mps': np.array([p.speed for p in points]),
            'permitted_at_target_mps': np.array([plan.permitted_speed(p.position, t)
                                                 for t, p in zip(times, points)])}
    positions: list[float] = []
    columns: dict[str, list[float]] = {name: [] for name, *_ in SUPERVISION_STYLES}
    columns['mrsp'], columns['static'] = [], []
    for leg, (origin, stop) in enumerate(zip(plan.supervision.stations_m,
                                             plan.supervision.stations_m[1:])):
        supervision = plan.supervision.legs[leg]
        xs = np.linspace(origin, stop, POINTS_PER_LEG)
        positions.extend(xs)
        for name in columns:
            if name == 'mrsp':
                columns[name].extend(supervision.mrsp(x) for x in xs)
            elif name == 'static':
                columns[name].extend(scenario.line.speed_limit_mps(x) for x in xs)
            else:
                columns[name].extend(supervision.curve(name, x) for x in xs)
        positions.append(np.nan)
        for values in columns.values():
            values.append(np.nan)
    data['curve_position_m'] = np.array(positions)
    for name, values in columns.items():
        array = np.array(values, dtype=float)
        array[np.isinf(array)] = np.nan
        data[f'{name}_mps'] = array
    return data


def strategy_plans(scenario) -> dict[str, Plan]:
    """The curve of each strategy ('fastest', 'timetable'); a timetable the journey's windows
    refuse is left out (the scenario's own strategy raises the error)."""
    plans = {}
    for strategy in ('fastest', 'timetable'):
        variant = replace(scenario, timetable=replace(scenario.timetable, strategy=strategy))
        try:
            plans[strategy] = plan_reference(variant)
        except PlanningError:
            if strategy == scenario.timetable.strategy:
                raise
    return plans


STRATEGY_STYLES = {'fastest': ('tab:blue', 'ATO target, fastest'),
                   'timetable': ('tab:green', 'ATO target, timetable (least energy)')}


def plot(scenario, plan: Plan, path: Path, others: dict[str, Plan] | None = None) -> None:
    """``plan``: the scenario's own curve (``plan_reference``), with its supervision;
    ``others``: every strategy's curve (``strategy_plans``), drawn beside it."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    data = curve_data(scenario, plan)
    kmh = units.KMH_PER_MPS
    km = data['curve_position_m'] / 1000.0
    figure, (by_distance, by_time, position) = plt.subplots(3, 1, figsize=(12, 12))
    by_distance.plot(km, data['static_mps'] * kmh, color='0.6', lw=1.0, label='static limit')
    by_distance.plot(km, data['mrsp_mps'] * kmh, color='k', lw=1.0, label='MRSP (train length)')
    for name, label, color, style in SUPERVISION_STYLES:
        by_distance.plot(km, data[f'{name}_mps'] * kmh, color=color, ls=style, lw=1.0,
                         label=label)
    curves = others or {plan.strategy: plan}
    for strategy, drawn in curves.items():
        color, label = STRATEGY_STYLES[strategy]
        # plan_reference (the plans drawn: the docstring's) forecasts every plan it returns
        assert drawn.forecast is not None
        energy = drawn.forecast.kwh()
        label = (f'{label}: {drawn.stops[-1].arrival_s:.0f} s, '
                 f'{energy["traction_energy_kwh"]:.0f} kWh gross, '
                 f'{energy["net_energy_kwh"]:.0f} kWh net')
        times = np.arange(0.0, drawn.trajectory.end_time + 1.0, 1.0)
        points = [drawn.trajectory.at(t) for t in times]
        xs = np.array([p.position for p in points])
        vs = np.array([p.speed for p in points])
        by_distance.plot(xs / 1000.0, vs * kmh, color=color, lw=1.6, label=label)
        by_time.plot(times, vs * kmh, color=color, lw=1.6, label=label)
        position.plot(times, xs / 1000.0, color=color, lw=1.4, label=label)
    for stop in plan.stops:
        by_distance.axvline(stop.station.position_m / 1000.0, color='0.8', lw=0.8)
    top = np.nanmax(data['mrsp_mps']) * kmh
    by_distance.set_ylim(0.0, top * 1.15)
    by_distance.set_xlabel('position [km]')
    by_distance.set_ylabel('speed [km/h]')
    by_distance.legend(loc='lower center', ncol=4, fontsize=8)
    by_distance.grid(alpha=0.3)
    by_time.plot(data['time_s'], data['permitted_at_target_mps'] * kmh, color='tab:orange',
                 lw=1.0, label=f'permitted speed at the {plan.strategy} target position')
    by_time.set_ylim(0.0, top * 1.15)
    by_time.set_xlabel('time [s]')
    by_time.set_ylabel('speed [km/h]')
    by_time.legend(loc='lower center', fontsize=8)
    by_time.grid(alpha=0.3)
    windows = scenario.journey.timing_points if scenario.journey is not None else ()
    end = max(p.trajectory.end_time for p in curves.values())
    for i, point in enumerate(windows):
        if point.earliest_s is None and point.latest_s is None:
            continue
        low = point.earliest_s if point.earliest_s is not None else 0.0
        high = point.latest_s if point.latest_s is not None else end
        position.plot([low, high], [point.position_m / 1000.0] * 2, color='tab:red', lw=3.0,
                      solid_capstyle='butt', label='time window' if i == 0 else None)
    for leg in plan.legs:
        stop = next(s for s in plan.stops if s.station.name == leg.destination)
        position.plot([leg.target_arrival_s], [stop.station.position_m / 1000.0], 'kx',
                      label='target arrival' if leg is plan.legs[0] else None)
    position.set_xlabel('time [s]')
    position.set_ylabel('position [km]')
    position.legend(loc='upper left', fontsize=8)
    position.grid(alpha=0.3)
    distance_km = (plan.trajectory.end_position - plan.trajectory.at(0.0).position) / 1000.0
    figure.suptitle(f'{scenario.name}: {scenario.train.name}, {distance_km:.1f} km, '
                    f'{plan.strategy} in {plan.trajectory.end_time:.0f} s, top '
                    f'{np.max(data["speed_mps"]) * kmh:.0f} km/h\n{scenario.source}', fontsize=10)
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    plt.close(figure)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('scenarios', nargs='*', help='built-in names or scenario files '
                        '(default: every built-in scenario)')
    parser.add_argument('-o', '--output', default='runs/curves', help='folder of the PNGs')
    args = parser.parse_args(argv)
    for name in args.scenarios or builtin_scenarios():
        try:
            scenario = load_scenario(name)
            plan = plan_reference(scenario)
            others = strategy_plans(scenario)
        except ConfigError as error:
            print(f'error: {error}', file=sys.stderr)
            return 2
        path = Path(args.output) / f'{scenario.name}.png'
        plot(scenario, plan, path, others)
        print(path)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
