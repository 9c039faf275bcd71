"""Issue 14, defect 1: a train's braking is bounded by wheel-rail adhesion (mu m g, lower on a
wet rail) and by the data's ETCS decelerations; a file whose forces exceed the bound loads with
a warning naming the figure and the bound. The bound is computed here from the file itself,
independently of the loader."""

import copy
import json
import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ato_common import units
from ato_common.scenario import parse_scenario
from ato_common.trains import (
    ADHESION_COEFFICIENT,
    TRAIN_PRESETS,
    TractionCharacteristic,
    bound_braking,
    train_preset,
)
from ato_common.ttobench import load_train
from ato_common.validation import ConfigError, DataWarning

SAMPLES = Path(__file__).resolve().parents[2] / 'tests' / 'data' / 'ttobench'
TRAIN_FILES = sorted((SAMPLES / 'trains').glob('*.json'))
G = units.STANDARD_GRAVITY
SPEEDS = [0.0, 5.0, 19.9, 20.0, 40.0, 59.0, 60.0, 90.0]


def documented_bound(data: dict, rail: str) -> float:
    """From the file: adhesion mu g on the static mass over the equivalent mass (the mass
    cancels: mu g / (1 + rho)), and the
    highest ETCS deceleration where the file has ETCS braking data, m/s^2."""
    rho = data.get('rho', {'unit': '-', 'value': 0.0})
    rho = rho['value'] / (100.0 if rho['unit'] == '%' else 1.0)
    bound = ADHESION_COEFFICIENT[rail] * G / (1.0 + rho)
    etcs = data.get('ETCS braking data')
    if etcs:
        bound = min(bound, max(d for _, d in etcs['A_brake_emergency']['values']
                               + etcs['A_brake_service']['values']))
    return bound


def assert_within(train, bound, supervision=None):
    traction, mass = train.traction, train.mass_kg
    # a relative 1e-12 for the product and quotient by the mass
    assert traction.max_service_brake_force_n / mass <= bound * (1 + 1e-12)
    assert traction.max_emergency_brake_force_n / mass <= bound * (1 + 1e-12)
    assert traction.max_emergency_brake_force_n >= traction.max_service_brake_force_n
    assert -traction.limits_at(10.0)[0] == traction.max_service_brake_force_n
    if supervision is not None:
        for v in SPEEDS:
            assert supervision.emergency_deceleration(v) <= bound * (1 + 1e-12)
            assert supervision.service_deceleration(v) <= bound * (1 + 1e-12)


def scenario_with(train_section, tmp_path=None):
    return parse_scenario({
        'name': 'b', 'train': train_section,
        'line': {'name': 'l', 'length_m': 20000,
                 'stations': [{'name': 'A', 'position_m': 0}, {'name': 'B', 'position_m': 19000}],
                 'speed_limits': [{'start_m': 0, 'speed_kmh': 160}]},
        'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.4,
                     'max_jerk_mps3': 0.5}}, base=tmp_path)


@pytest.mark.filterwarnings('ignore::ato_common.validation.DataWarning')
@pytest.mark.parametrize('rail', ['dry', 'wet'])
@pytest.mark.parametrize('path', TRAIN_FILES, ids=lambda p: p.stem)
def test_every_sample_train_brakes_within_its_documented_bound(path, rail):
    data = json.loads(path.read_text())
    scenario = scenario_with({'ttobench': str(path), 'rail': rail})
    assert_within(scenario.train, documented_bound(data, rail), scenario.supervision)


@pytest.mark.parametrize('rail', ['dry', 'wet'])
@pytest.mark.parametrize('preset', sorted(TRAIN_PRESETS))
def test_every_preset_brakes_within_adhesion(preset, rail):
    scenario = scenario_with({'preset': preset, 'rail': rail})
    assert_within(scenario.train, ADHESION_COEFFICIENT[rail] * G, scenario.supervision)
    if rail == 'dry':  # the presets' own figures are within the dry-rail bound: unchanged
        assert scenario.train == train_preset(preset)


def test_the_wet_rail_bound_is_lower():
    assert ADHESION_COEFFICIENT['wet'] < ADHESION_COEFFICIENT['dry']
    dry = scenario_with({'preset': 'crh3_luo_xu'}).train.traction
    wet = scenario_with({'preset': 'crh3_luo_xu', 'rail': 'wet'}).train.traction
    assert wet.max_emergency_brake_force_n < dry.max_emergency_brake_force_n


def test_a_file_whose_forces_exceed_adhesion_warns_naming_figure_and_bound(tmp_path):
    # the KISS file: 400 kN regenerative + 2970 kN pneumatic on 297 t (10.3 m/s^2 with rho)
    path = SAMPLES / 'trains' / 'CH_Stadler_KISS_SBB.json'
    with pytest.warns(DataWarning) as caught:
        train = load_train(path)
    messages = [str(w.message) for w in caught]
    assert any(str(path) in m and 'max reg braking force + max pn braking force 3370.0 kN' in m
               and 'wheel-rail adhesion bound 436.9 kN (mu 0.15 on a dry rail x 297 t x g)' in m
               for m in messages), messages
    assert train.parameters.traction.max_service_brake_force_n == pytest.approx(0.15 * 297e3 * G)


def test_a_file_within_the_bound_loads_without_a_warning(recwarn):
    load_train(SAMPLES / 'trains' / 'CN_Beijing_Subway.json')
    assert not [w for w in recwarn if issubclass(w.category, DataWarning)]


def test_an_unknown_rail_condition_is_rejected():
    with pytest.raises(ConfigError, match=r"train.rail: unknown rail condition 'icy'; valid: "
                                          r'dry, wet'):
        scenario_with({'preset': 'crh3_luo_xu', 'rail': 'icy'})


def test_the_emergency_brake_is_never_below_the_service_brake():
    traction = TractionCharacteristic(300e3, 8e6, 500e3, 400e3)
    bounded = bound_braking(traction, 400e3, 'dry', emergency_limit_n=300e3)
    assert bounded.traction.max_service_brake_force_n == 500e3
    assert bounded.traction.max_emergency_brake_force_n == 500e3


force_kn = st.floats(0.0, 5000.0, allow_nan=False)
decelerations = st.lists(st.floats(0.05, 3.0, allow_nan=False), min_size=1, max_size=4)


@st.composite
def train_files(draw):
    data = json.loads((SAMPLES / 'trains' / 'CH_Stadler_FLIRT_TPF.json').read_text())
    data = copy.deepcopy(data)
    data['mass'] = {'unit': draw(st.sampled_from(['kg', 't'])), 'value': 0.0}
    # masses and forces of real trains (ttobench's plausibility bounds: 58.6 m long, its 2.6 MW)
    mass_t = draw(st.floats(30.0, 1000.0))
    data['mass']['value'] = mass_t * (1000.0 if data['mass']['unit'] == 'kg' else 1.0)
    data['rho'] = {'unit': '%', 'value': draw(st.floats(0.0, 30.0))}
    weight_kn = mass_t * G
    regenerative, pneumatic = draw(force_kn), draw(force_kn)
    if regenerative + pneumatic < 0.0021 * weight_kn:
        pneumatic = 0.0021 * weight_kn
    share = min(1.0, 1.99 * weight_kn / (regenerative + pneumatic))
    data['max reg braking force'] = {'unit': 'kN', 'value': regenerative * share}
    data['max pn braking force'] = {'unit': 'kN', 'value': pneumatic * share}
    if draw(st.booleans()):
        etcs = data['ETCS braking data']
        for key in ('A_brake_emergency', 'A_brake_service'):
            values = draw(decelerations)
            etcs[key]['values'] = [[20.0 * i, d] for i, d in enumerate(values)]
    else:
        del data['ETCS braking data']
    return data


@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=train_files(), rail=st.sampled_from(['dry', 'wet']))
@pytest.mark.filterwarnings('ignore::ato_common.validation.DataWarning')
def test_no_train_from_any_file_brakes_beyond_its_documented_bound(tmp_path, data, rail):
    path = tmp_path / 'train.json'
    path.write_text(json.dumps(data))
    scenario = scenario_with({'ttobench': str(path), 'rail': rail})
    bound = documented_bound(data, rail)
    assert math.isfinite(bound)
    assert_within(scenario.train, bound, scenario.supervision)
