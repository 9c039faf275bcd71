"""``TrainSimulation.run_commands``: many periods in one call, compiled where it can be, equal
to the period-by-period interface to the last bit."""

import math
from unittest import mock

import numpy as np
import pytest

from ato_common.braking_curves import RunSupervision
from ato_common.scenario import load_scenario, parse_scenario
from train_plant_node import batch
from train_plant_node.periods import exact_sum, limit_at
from train_plant_node.simulation import CommandRejected, TrainSimulation

PERIOD_NS = 100_000_000


def scenario(preset='mao_2017_500t', plant=None, **line_features):
    line = {'name': 'l', 'length_m': 60e3,
            'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 25e3},
                         {'name': 'C', 'position_m': 55e3}],
            'speed_limits': [{'start_m': 0, 'speed_kmh': 200}, {'start_m': 8e3, 'speed_kmh': 120},
                             {'start_m': 12e3, 'speed_kmh': 200}],
            **line_features}
    return parse_scenario({
        'name': 's', 'train': {'preset': preset}, 'line': line,
        'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.5}, 'plant': plant})


LINE = {'gradients': [{'start_m': 0, 'per_mille': 0}, {'start_m': 3e3, 'per_mille': 8},
                      {'start_m': 9e3, 'per_mille': -6}, {'start_m': 20e3, 'per_mille': 2}],
        'curves': [{'start_m': 4.8e3, 'length_m': 200, 'radius_m': 1e5, 'end_radius_m': 4000},
                   {'start_m': 5e3, 'length_m': 1500, 'radius_m': 4000}],
        'tunnels': [{'start_m': 14e3, 'length_m': 2e3}]}

VARIATION_AND_DISTURBANCE = {
    'resistance_variation': {'a': {'amplitude': 0.3, 'omega_rad_per_s': 0.1},
                             'c': {'amplitude': 0.1, 'omega_rad_per_s': 0.05},
                             'line': {'amplitude': 0.05, 'omega_rad_per_s': 0.02}},
    'disturbance': {'kind': 'fast', 'amplitude_n': 8900, 'omega_rad_per_s': 1.0}}

FAILURES_AND_SENSORS = {
    'failures': [{'actuator': 'motor_2', 'kind': 'loss', 'start_s': 100.05, 'end_s': 160},
                 {'actuator': 'motor_3', 'kind': 'stuck_signal', 'start_s': 300, 'end_s': 330,
                  'force_n': 1e5, 'amplitude_n': 1e5, 'omega_rad_per_s': 0.05}],
    'sensors': {'speed': {'failed_from_s': 200, 'failed_until_s': 250}}}


def commands(periods, actuators, seed=1, hold=40, total_n=500e3):
    """Held random commands from full service braking to beyond the traction limit."""
    rng = np.random.default_rng(seed)
    levels = rng.uniform(-0.4, 1.2, (periods // hold + 1, 1)) * total_n / actuators
    return np.repeat(levels, hold, axis=0)[:periods] * np.ones((1, actuators))


def period_by_period(sim, rows):
    out = []
    for row in rows:
        sim.apply_command(tuple(row.tolist()))
        sim.advance(PERIOD_NS)
        out.append((sim.truth(), sim.atp_intervention))
    return out


def assert_same_run(scenario_, model='point_mass', periods=4000, seed=1, compiled=None):
    """run_commands against the period-by-period interface; ``compiled``: whether the
    compiled path must have run (True), must not have (False)."""
    fast, slow = TrainSimulation(scenario_, model), TrainSimulation(scenario_, model)
    rows = commands(periods, len(fast.actuator_names), seed)
    calls = []  # periods each compiled call ran

    def spy(*args, original=batch.run_compiled):
        calls.append(original(*args))
        return calls[-1]
    with mock.patch.object(batch, 'run_compiled', spy):
        trajectory = fast.run_commands(rows, PERIOD_NS)
    expected = period_by_period(slow, rows)
    assert len(trajectory) == periods
    for k, (truth, intervention) in enumerate(expected):
        assert trajectory.state(k) == truth, k
        assert trajectory.atp_intervention[k] == intervention, k
    # The simulation carries on from the same state either way.
    assert fast.stamp_ns == slow.stamp_ns and np.array_equal(fast.state, slow.state)
    assert (fast.applied, fast.commanded) == (slow.applied, slow.commanded)
    assert fast.atp_interventions == slow.atp_interventions
    if hasattr(fast.model, 'work'):
        assert np.array_equal(fast.model.work, slow.model.work)
    if compiled is not None:
        assert bool(calls) == compiled, calls
    return fast, calls


def test_compiled_run_equals_the_period_interface_with_atp_interventions_and_stops():
    sim, calls = assert_same_run(load_scenario('short_line'), periods=6000, compiled=True)
    # the kernel runs up to an intervention or a stop; the braking and dwell run period by period
    assert 0 < sum(calls) < 6000 and len(calls) > 1
    assert sim.atp_interventions >= 1  # the commands overspeed: the ATP's branch ran


def test_compiled_run_on_a_line_with_grades_curves_tunnels_and_varying_forces():
    assert_same_run(scenario('crh3_luo_xu', VARIATION_AND_DISTURBANCE, **LINE), compiled=True)


def test_compiled_run_splits_at_failures_and_sensor_events():
    # The failures act period by period, the rest is compiled; an event that falls inside a
    # period (100.05 s) and one on a period boundary are both where the interface has them.
    _, calls = assert_same_run(scenario(plant=FAILURES_AND_SENSORS, **LINE), compiled=True)
    assert len(calls) >= 4 and sum(calls) < 4000 - (60 + 30) * 10


@pytest.mark.parametrize('plant', [
    {'modes': [{'name': 'open', 'from_m': 0, 'davis_kn_kmh': {'a': 2.25, 'b': 0.0, 'c': 3e-4}},
               {'name': 'tunnel', 'from_m': 14e3, 'davis_kn_kmh': {'a': 2.25, 'b': 0.0,
                                                                    'c': 9e-4}}]},
    {'abrupt_changes': [{'start_s': 100, 'end_s': 110, 'grade_per_mille': 30}]},
    {'actuators': {'time_constant_s': 0.5, 'rate_limit_n_per_s': 1e5}},
    {'disturbance': {'kind': 'random', 'amplitude_n': 5e3, 'hold_s': 2.0, 'seed': 4}},
], ids=['modes by region', 'abrupt change', 'actuator lag', 'random disturbance'])
def test_where_the_compiled_path_does_not_apply_the_periods_run_one_by_one(plant):
    assert_same_run(scenario(plant=plant, **LINE), periods=1500, compiled=False)


def test_compiled_multi_car_run_equals_the_period_interface():
    _, calls = assert_same_run(load_scenario('mao_4car'), 'multi_car', periods=3000,
                               compiled=True)
    # all but the first periods, in which the train stands at its start and the model's
    # ``step`` holds it (the kernel does not)
    assert 2990 <= sum(calls) < 3000


def test_compiled_multi_car_run_hands_boundary_crossings_to_the_interface():
    # A car that reaches another line segment within a period: the interface splits the step
    # there, so the compiled kernel stops before that period and resumes after it.
    _, calls = assert_same_run(scenario('crh2_4car_mao', VARIATION_AND_DISTURBANCE, **LINE),
                               'multi_car', periods=3000, compiled=True)
    assert len([c for c in calls if c]) > 10 and sum(calls) < 3000


@pytest.mark.parametrize('rows, reason', [
    ([[1e4, 1e4]], r'shape \(1, 2\): need one row per period of 4 forces'),
    ([[1e4] * 4, [1e4, math.nan, 0, 0]], r'row 1: non-finite force'),
    ([[1e4] * 4, [math.inf] * 4], r'row 1: non-finite force'),
    ([[1e4] * 4, [1e4] * 3], 'table of forces'),
    (['a', 'b', 'c', 'd'], 'table of forces'),
])
def test_bad_commands_are_rejected_before_anything_runs(rows, reason):
    sim = TrainSimulation(scenario())
    sim.run_commands([[5e4] * 4] * 10, PERIOD_NS)
    before = (sim.stamp_ns, sim.state.copy(), sim.commanded, sim.applied)
    with pytest.raises(CommandRejected, match=reason):
        sim.run_commands(rows, PERIOD_NS)
    assert (sim.stamp_ns, sim.commanded, sim.applied) == (before[0], before[2], before[3])
    assert np.array_equal(sim.state, before[1])


@pytest.mark.parametrize('period_ns', [0, -5, 0.1, True])
def test_the_period_must_be_a_positive_whole_number_of_nanoseconds(period_ns):
    with pytest.raises(ValueError, match='period_ns must be a positive integer'):
        TrainSimulation(scenario()).run_commands([[0.0] * 4], period_ns)


def test_exact_sum_is_math_fsum_to_the_last_bit():
    rng = np.random.default_rng(7)
    scratch = np.empty(17)
    cases = [np.array([1e16, 1.0, -1e16, 1e-3]), np.array([0.1] * 10), np.zeros(3),
             np.array([1e300, 1e300, -1e300]), np.array([-2.5e5, 2.5e5, 1e-300])]
    for _ in range(2000):
        n = int(rng.integers(1, 16))
        values = rng.standard_normal(n) * 10.0 ** rng.integers(-20, 20, n)
        values[rng.random(n) < 0.3] *= -1.0
        cases.append(values)
    # Sums that end on a rounding tie: the half-even correction decides them.
    cases += [np.array([1.0, 2.0 ** -53, 2.0 ** -106]), np.array([1.0, 2.0 ** -53, -2.0 ** -106]),
              np.array([1.0 + 2.0 ** -52, 2.0 ** -53, -2.0 ** -107])]
    for values in cases:
        assert exact_sum(values, len(values), scratch) == math.fsum(values), values.tolist()


def test_compiled_atp_look_up_is_the_sampled_curve():
    run = RunSupervision.for_scenario(scenario(**LINE))
    stations = np.array(run.stations_m, dtype=float)
    positions = np.concatenate([np.linspace(-100.0, 60e3, 20011), stations,
                                stations - run.STOP_WINDOW_M, stations + 1e-9])
    for name in ('ebi', 'permitted'):
        offsets, xs, vs = run.packed_curve(name)
        positions_ = np.concatenate([positions, xs, xs[offsets[1:] - 1] + 1e-7])
        for leg in range(len(run.legs)):
            for x in positions_:
                assert limit_at(leg, offsets, xs, vs, x) == \
                    run.sampled_curve(name, x, leg), (name, leg, x)
