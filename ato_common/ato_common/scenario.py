"""Scenarios: a line, a train and the run settings, loaded from YAML and validated.

``load_scenario(name_or_path)`` accepts the name of a built-in scenario (a YAML file shipped in
``ato_common/scenarios``) or a path to a user's file. Every error names the file and the field.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import yaml

from ato_common import units
from ato_common.line import Line, parse_line
from ato_common.plant_setup import PlantSetup, parse_plant_setup
from ato_common.trains import TRAIN_PRESETS, TrainParameters, train_preset
from ato_common.validation import ConfigError, Fields

DEFAULT_SCENARIO = 'short_line'


@dataclass(frozen=True)
class PlanningLimits:
    """The train's dynamic limits used to plan the reference (not the physical limits)."""

    max_acceleration_mps2: float
    service_deceleration_mps2: float
    max_jerk_mps3: float
    speed_margin_mps: float


@dataclass(frozen=True)
class RunSettings:
    controller_rate_hz: float
    initial_position_m: float
    end_time_s: float  # 0: the end of the reference plus settle_time_s
    settle_time_s: float


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    source: str
    origin: str          # where it was loaded from, for messages
    train: TrainParameters
    line: Line
    planning: PlanningLimits
    run: RunSettings
    plant: PlantSetup = PlantSetup()  # what varies, actuators, failures, sensors


def builtin_scenarios() -> list[str]:
    folder = resources.files('ato_common') / 'scenarios'
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith('.yaml'))


def load_scenario(name_or_path: str) -> Scenario:
    """Load a built-in scenario by name or a scenario file by path; raise ConfigError if invalid."""
    if name_or_path in builtin_scenarios():
        origin = f'built-in scenario {name_or_path}'
        text = (resources.files('ato_common') / 'scenarios' / f'{name_or_path}.yaml').read_text()
    else:
        path = Path(name_or_path)
        if not path.is_file():
            raise ConfigError(f"scenario '{name_or_path}' is neither a built-in scenario "
                              f"({', '.join(builtin_scenarios())}) nor a readable file")
        origin = str(path)
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as error:
            raise ConfigError(f'{path}: cannot read: {error}') from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise ConfigError(f'{origin}: not valid YAML: {error}') from None
    try:
        return parse_scenario(data, origin)
    except ConfigError as error:
        raise ConfigError(f'{origin}: {error}') from None


def parse_scenario(data, origin: str = '<memory>') -> Scenario:
    f = Fields(data, '')
    train_fields = f.section('train', required=True)
    preset = train_fields.text('preset')
    if preset not in TRAIN_PRESETS:
        raise ConfigError(f"{train_fields.where}.preset: unknown train '{preset}'; valid: "
                          f"{', '.join(sorted(TRAIN_PRESETS))}")
    train = train_preset(preset)
    train_fields.reject_unknown()

    line = parse_line(f.raw('line', required=True), 'line')

    p = f.section('planning', required=True)
    planning = PlanningLimits(
        max_acceleration_mps2=p.number('max_acceleration_mps2', minimum=0.01, maximum=2.0),
        service_deceleration_mps2=p.number('service_deceleration_mps2', minimum=0.01, maximum=2.0),
        max_jerk_mps3=p.number('max_jerk_mps3', minimum=0.01, maximum=5.0),
        speed_margin_mps=units.kmh_to_mps(p.number('speed_margin_kmh', 0.0, minimum=0.0,
                                                   maximum=100.0)),
    )
    p.reject_unknown()

    r = f.section('run')
    run = RunSettings(
        controller_rate_hz=r.number('controller_rate_hz', 10.0, minimum=0.1, maximum=1000.0),
        initial_position_m=r.number('initial_position_m', line.stations[0].position_m,
                                    minimum=0.0, maximum=line.length_m),
        end_time_s=r.number('end_time_s', 0.0, minimum=0.0),
        settle_time_s=r.number('settle_time_s', 10.0, minimum=0.0),
    )
    r.reject_unknown()
    stations = [s.position_m for s in line.stations[:-1]]
    if run.initial_position_m not in stations:
        raise ConfigError(f'run.initial_position_m: the run starts at a station other than the '
                          f'last one ({", ".join(f"{p:g}" for p in stations)} m), got '
                          f'{run.initial_position_m:g}')
    scenario = Scenario(
        name=f.text('name'), description=f.text('description', ''),
        source=f.text('source', 'suite'), origin=origin, train=train, line=line,
        planning=planning, run=run, plant=parse_plant_setup(f.raw('plant'), train, 'plant'))
    f.reject_unknown()
    return scenario
