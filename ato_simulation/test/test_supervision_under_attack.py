"""Issue 29's acceptance in the offline loop (``ato_simulation.loop.run_offline``, the PID):
stuck drives (300 kN from 0 s and from cruise, 100 kN), an odometer scale error of +/-10 %, a
position bias of +/-200 m and a failed speed sensor; and the rogue ATO (full traction every
step) on the plant itself. In every case the train's true front never passes the end of
authority of the leg under supervision, the authority at Midway moves on only after a
continuous standstill of its dwell, and the true speed never exceeds the ceiling (the MRSP plus
dV_ebi), on short_line as it ships: with the balise groups the loader places on it
(``ato_common.line.default_balise_groups``) and the odometry accuracy it declares
(SUBSET-041 5.3.1: +/-(5 m + 5 %) of the distance since the last balise group; the speed's
+/-(2 km/h + 2 % of the speed))."""

from __future__ import annotations

import copy
from importlib import resources

import numpy as np
import pytest
import yaml

from ato_common.braking_curves import DV_EBI_KMH, RunSupervision, ceiling_margin
from ato_common.line import BALISE_GROUP_SPACING_M
from ato_common.scenario import parse_scenario
from ato_simulation.loop import run_offline
from train_plant_node.simulation import TrainSimulation

PERIOD_NS = 100_000_000


def short_line(plant: dict) -> object:
    """short_line as it ships, with ``plant``."""
    text = resources.files('ato_common').joinpath('scenarios/short_line.yaml').read_text()
    data = copy.deepcopy(yaml.safe_load(text))
    assert 'balise_groups' not in data['line'] and 'plant' not in data
    data['plant'] = plant
    scenario = parse_scenario(data)
    assert scenario.line.balise_groups_m and scenario.supervision.odometry_accuracy == 0.05
    return scenario


def check_supervised(scenario, positions, speeds) -> None:
    """The bounds of the module's docstring, on the true front and speed after each period."""
    run = RunSupervision.for_scenario(scenario)
    mrsp = np.array([run.legs[0].mrsp(x) for x in positions])
    ceiling = mrsp + np.array([ceiling_margin(v, DV_EBI_KMH) for v in mrsp])
    assert np.all(speeds <= ceiling), (speeds - ceiling).max()
    midway, terminus = (leg.end_of_authority_m for leg in run.legs)
    past = np.flatnonzero(positions >= midway)
    if past.size:  # past Midway's EOA: only after a continuous standstill of the dwell there
        low, _ = run.stop_zone(0)
        odometry = scenario.supervision
        interval = odometry.location_accuracy_m + odometry.odometry_accuracy \
            * BALISE_GROUP_SPACING_M
        before = slice(0, past[0])
        at_stop = (speeds[before] <= run.STANDSTILL_MPS) & (positions[before] >= low - interval)
        assert _longest_run(at_stop) >= run.dwell_s(0) * 1e9 // PERIOD_NS
    assert positions.max() < terminus


def _longest_run(flags: np.ndarray) -> int:
    longest = current = 0
    for flag in flags:
        current = current + 1 if flag else 0
        longest = max(longest, current)
    return longest


STUCK = {'actuator': 'traction', 'kind': 'stuck'}
CASES = {
    'stuck 300 kN from 0 s': {'failures': [{**STUCK, 'start_s': 0, 'force_n': 3e5}]},
    'stuck 300 kN from cruise': {'failures': [{**STUCK, 'start_s': 200, 'force_n': 3e5}]},
    'stuck 100 kN': {'failures': [{**STUCK, 'start_s': 0, 'force_n': 1e5}]},
    'odometer scale +10 %': {'sensors': {'position': {'scale_error': 0.1},
                                         'speed': {'scale_error': 0.1}}},
    'odometer scale -10 %': {'sensors': {'position': {'scale_error': -0.1},
                                         'speed': {'scale_error': -0.1}}},
    'position bias +200 m': {'sensors': {'position': {'bias': 200.0}}},
    'position bias -200 m': {'sensors': {'position': {'bias': -200.0}}},
    'failed speed sensor': {'sensors': {'speed': {'failed_from_s': 100.0}}},
}


@pytest.mark.parametrize('case', list(CASES))
def test_the_pid_under_attack_never_passes_an_end_of_authority(case):
    scenario = short_line(CASES[case])
    run = run_offline(scenario, 'pid')
    check_supervised(scenario, run.positions, run.speeds)


def test_the_rogue_ato_never_passes_an_end_of_authority():
    scenario = short_line({})
    sim = TrainSimulation(scenario)
    positions, speeds = np.empty(13000), np.empty(13000)
    for k in range(13000):
        sim.apply_command((1e9,))
        sim.advance(PERIOD_NS)
        positions[k], speeds[k] = sim.lead_position(), sim.lead_speed()
    check_supervised(scenario, positions, speeds)
    assert sim.atp.leg == 1 and speeds[-1] == 0.0  # stands before Terminus' EOA


def test_a_nominal_run_has_no_intervention_with_the_declared_odometry():
    run = run_offline(short_line({}), 'pid')
    assert run.atp_interventions == 0 and run.positions[-1] == pytest.approx(36000.0, abs=0.5)
