"""The plant's safety functions: command watchdog and ATP over-speed intervention."""

import pytest

from ato_common.scenario import parse_scenario
from train_plant_node.simulation import (
    EMERGENCY_BRAKE,
    NORMAL,
    SERVICE_BRAKE,
    CommandRejected,
    SafetySettings,
    TrainSimulation,
)

PERIOD_NS = 100_000_000


def scenario(limit_kmh=300.0):
    return parse_scenario({
        'name': 's', 'train': {'preset': 'crh3_luo_xu'},
        'line': {'name': 'l', 'length_m': 100000,
                 'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 90000}],
                 'speed_limits': [{'start_m': 0, 'speed_kmh': limit_kmh}]},
        'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.5}})


def moving_sim(**safety):
    sim = TrainSimulation(scenario(), safety=SafetySettings(**safety))
    sim.apply_command((300e3,))
    for _ in range(300):
        sim.advance(PERIOD_NS)
    return sim


def test_watchdog_service_then_emergency_braking_and_recovery():
    sim = moving_sim(watchdog_periods=3, emergency_periods=6)
    brakes = sim.scenario.train.traction
    states = []
    for _ in range(7):
        sim.command_missed()
        states.append((sim.watchdog, sim.applied[0]))
    assert [s for s, _ in states] == [NORMAL, NORMAL, SERVICE_BRAKE, SERVICE_BRAKE,
                                      SERVICE_BRAKE, EMERGENCY_BRAKE, EMERGENCY_BRAKE]
    assert states[2][1] == -brakes.max_service_brake_force_n
    assert states[-2][1] == 0.0  # the emergency brake's demand: traction cut, brake building up
    for _ in range(20):  # T_be = 2 s
        sim.command_missed()
        sim.advance(PERIOD_NS)
    assert sim.applied[0] == -brakes.max_emergency_brake_force_n
    v = sim.truth().speeds[0]
    sim.advance(PERIOD_NS)
    assert sim.truth().speeds[0] < v
    sim.apply_command((100e3,))  # a valid command ends it
    assert sim.watchdog == NORMAL and sim.applied == (100e3,)


def test_rejected_commands_do_not_feed_the_watchdog_by_themselves():
    sim = moving_sim()
    with pytest.raises(CommandRejected):
        sim.apply_command((float('nan'),))
    assert sim.watchdog == NORMAL  # the node counts a missed period, the simulation does not guess


def test_atp_intervenes_above_the_ebi_until_back_under_the_permitted_speed():
    sim = TrainSimulation(scenario(limit_kmh=30.0))
    # Ceiling supervision at 30 km/h: EBI = MRSP + dV_ebi (7.5 km/h, ETCS default below 110)
    assert sim.atp.intervention_speed(sim.odometry) == pytest.approx((30.0 + 7.5) / 3.6)
    assert sim.atp.permitted_speed(sim.odometry) == pytest.approx(30.0 / 3.6)
    trace = []
    for _ in range(1200):
        sim.apply_command((300e3,))  # the ATO keeps asking for full traction
        sim.advance(PERIOD_NS)
        trace.append((sim.truth().speeds[0], sim.atp_intervention, sim.applied[0]))
    speeds = [v for v, _, _ in trace]
    assert max(speeds) <= (37.5 + 0.5) / 3.6  # caught within a control period of the EBI
    assert sim.atp_interventions >= 1
    during = [a for v, on, a in trace if on]
    assert during and all(a <= 0.0 for a in during)  # traction cut, the brake building up
    assert min(during) == -sim.scenario.train.traction.max_emergency_brake_force_n
    released = [v for (v, on, _), (_, was_on, _) in zip(trace[1:], trace) if was_on and not on]
    assert released and all(v <= 30.0 / 3.6 + 1e-9 for v in released)


def test_atp_supervises_the_braking_curve_to_the_stop():
    """Near the end of authority the EBI follows the braking curve, far below the line limit:
    a train that does not brake for the stop is emergency-braked before the station."""
    sim = TrainSimulation(scenario(limit_kmh=300.0))
    sim.state = sim.model.initial_state(87000.0, 200.0 / 3.6)  # 3 km before B, 200 km/h
    assert 200.0 / 3.6 < sim.atp.intervention_speed(sim.odometry)  # not yet
    for _ in range(3000):
        sim.apply_command((0.0,))  # coasting: the ATO does not brake
        sim.advance(PERIOD_NS)
        if sim.truth().speeds[0] == 0.0:
            break
    assert sim.atp_interventions >= 1
    # stopped before the supervised location (EOA 50 m and overlap 50 m past the stop)
    assert sim.truth().positions[0] < 90000.0 + 100.0
