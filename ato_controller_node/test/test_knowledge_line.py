"""The controller side of the line between truth and knowledge: it knows only what
``ato_common.knowledge.knowledge_of`` gives it, so the plant's truth cannot change a command."""

import ast
import importlib.util
import math
from dataclasses import replace
from pathlib import Path

import pytest

from ato_common.knowledge import knowledge_of
from ato_common.plant_setup import (
    ActuatorFailure,
    ActuatorSettings,
    Disturbance,
    QuantitySensor,
    ResistanceVariation,
    SensorSetup,
    Sinusoid,
)
from ato_common.scenario import load_scenario
from ato_common.trains import DavisResistance
from ato_common.types import ReferencePoint, TrainState
from ato_controller_node.host import ControllerHost
from ato_controller_node.laws import LAWS

RATES_HZ = (10.0, 200.0, 1000.0, 10000.0)  # the scenarios' rate, then faster ones (compare.py)
STEPS = 200


def with_other_truth(scenario):
    """The scenario with another truth: failures, resistance variation, disturbance, sensor
    noise and failures, actuator lag, simulated resistance; the nominal train and modes kept."""
    names, davis = scenario.train.actuator_names, scenario.train.davis
    plant = replace(
        scenario.plant,
        resistance_variation=ResistanceVariation(Sinusoid(0.3, 0.1), None, Sinusoid(0.1, 0.05)),
        disturbance=Disturbance('fast', 2e4, 0.5),
        actuators=ActuatorSettings(0.8, 5e4),
        failures=(ActuatorFailure(names[0], 'partial', 1.0, effectiveness=0.5),),
        sensors=SensorSetup(QuantitySensor(noise_std=0.5),
                            QuantitySensor(noise_std=0.05, failed_from_s=3.0, failed_until_s=4.0),
                            QuantitySensor(dropout_probability=0.3), seed=11))
    train = replace(scenario.train, davis=DavisResistance(3.0 * davis.a_n, davis.b_n_s_per_m,
                                                          2.0 * davis.c_n_s2_per_m2))
    return replace(scenario, plant=plant, train=train)


def measured_state(k: int, t: float, cars: tuple[str, ...], car_length_m: float) -> TrainState:
    """A made-up measured state near the reference of :func:`reference_at`, a few samples
    missing (NaN) so that the host's hold path runs too."""
    x = 0.5 * t * t + 3.0 * math.sin(0.7 * t) if t < 20.0 else 200.0 + 20.0 * (t - 20.0)
    v = min(t, 20.0) + 0.4 * math.cos(1.3 * t)
    position = math.nan if k % 37 == 5 else x
    return TrainState(0, cars, tuple(position - i * car_length_m for i in range(len(cars))),
                      (v,) * len(cars), (0.1,) * len(cars), (0.0,) * len(cars))


def reference_at(t: float) -> ReferencePoint:
    if t < 20.0:
        return ReferencePoint(t, 0.5 * t * t, t, 1.0)
    return ReferencePoint(t, 200.0 + 20.0 * (t - 20.0), 20.0, 0.0)


def commands(knowledge, law: str, dt: float, start_s: float) -> list[str]:
    host = ControllerHost(knowledge, dt, law)
    cars = tuple(c.name for c in knowledge.cars) or ('train',)
    results = []
    for k in range(STEPS):
        t = start_s + k * dt
        state = measured_state(k, t - start_s, cars, knowledge.car_length_m)
        results.append(repr(host.step(host.measurement(t, state), reference_at(t - start_s))))
    return results  # repr: bit-identical floats, NaN estimates included


def fitting_rate(knowledge, law: str) -> float | None:
    cars = len(knowledge.cars) or 1
    for rate in RATES_HZ:
        if not LAWS[law](knowledge, 1.0 / rate).fits(knowledge, cars):
            return rate
    return None


@pytest.mark.parametrize('name', ['mao_2017_modes', 'mao_4car', 'liu_li_2020', 'short_line'])
def test_the_plant_truth_does_not_change_a_command(name):
    scenario = load_scenario(name)
    knowledge, other = knowledge_of(scenario), knowledge_of(with_other_truth(scenario))
    assert with_other_truth(scenario) != scenario and other == knowledge
    ran = []
    for law in sorted(LAWS):
        rate = fitting_rate(knowledge, law)
        if rate is None:
            continue
        dt = 1.0 / rate
        # Mode switches by time: run across the first switch, 100 periods before it.
        modes = knowledge.modes
        start = modes[1].start - 100 * dt if len(modes) > 1 else 0.0
        ran.append(law)
        assert commands(knowledge, law, dt, start) == commands(other, law, dt, start), law
    assert ran


def test_the_host_takes_the_mode_from_the_knowledge():
    scenario = load_scenario('mao_2017_modes')
    knowledge = knowledge_of(scenario)
    host = ControllerHost(knowledge, 0.1, 'mao_2017')
    state = measured_state(0, 1.0, ('train',), 0.0)
    for t in (0.0, 399.9, 400.0, 850.0, 1500.0):
        assert host.measurement(t, state).mode == scenario.plant.known_mode(t, 0.0, 0)


# --- the static check ---------------------------------------------------------------------------

FORBIDDEN_MODULES = ('ato_common.plant_setup', 'train_plant_node')


def forbidden(module: str) -> bool:
    return any(module == m or module.startswith(m + '.') for m in FORBIDDEN_MODULES)


def offences(path: Path) -> list[str]:
    """Where a file of the controller package reads a ``.plant`` (a scenario's plant section:
    the truth) or imports the plant setup or the plant node."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        what = None
        if isinstance(node, ast.Attribute) and node.attr == 'plant':
            what = f'reads .plant ({ast.unparse(node)})'
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
              and node.func.id in ('getattr', 'hasattr') and len(node.args) > 1
              and isinstance(node.args[1], ast.Constant) and node.args[1].value == 'plant'):
            what = f'reads .plant ({ast.unparse(node)})'
        elif isinstance(node, ast.Import):
            bad = [a.name for a in node.names if forbidden(a.name)]
            what = f'imports {", ".join(bad)}' if bad else None
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            modules = [node.module] + [f'{node.module}.{a.name}' for a in node.names]
            bad = [m for m in modules if forbidden(m)]
            what = f'imports {bad[0]}' if bad else None
        if what:
            found.append((node.lineno, f'{path}:{node.lineno}: {what}'))
    return [text for _, text in sorted(found)]


def controller_sources() -> list[Path]:
    spec = importlib.util.find_spec('ato_controller_node')
    package = Path(next(iter(spec.submodule_search_locations))).resolve()
    return sorted(package.rglob('*.py'))


def test_the_controller_package_never_reads_the_plants_truth():
    sources = controller_sources()
    assert any(p.name == 'node.py' for p in sources) and any(p.name == 'host.py' for p in sources)
    found = [o for path in sources for o in offences(path)]
    for offence in found:
        print(offence)
    assert not found, 'the controller reads the plant\'s truth (use ato_common.knowledge):\n' \
        + '\n'.join(found)


def test_the_static_check_finds_each_kind_of_offence(tmp_path):
    bad = tmp_path / 'bad.py'
    bad.write_text('import train_plant_node.simulation\n'
                   'from ato_common import plant_setup\n'
                   'from ato_common.plant_setup import Mode\n'
                   'mode = self.scenario.plant.known_mode(0.0, 0.0, 0)\n'
                   "plant = getattr(scenario, 'plant')\n")
    assert [o.split(':')[1] for o in offences(bad)] == ['1', '2', '3', '4', '5']
    good = tmp_path / 'good.py'
    good.write_text('from ato_common.knowledge import knowledge_of\nplanted = 1\n')
    assert offences(good) == []
