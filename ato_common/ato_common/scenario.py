"""Scenarios: a line, a train and the run settings, loaded from YAML and validated.

``load_scenario(name_or_path)`` accepts the name of a built-in scenario (a YAML file shipped in
``ato_common/scenarios``) or a path to a user's file. Every error names the file and the field.

The train is a preset (``train: {preset: name}``) or a TTOBench train file
(``train: {ttobench: path}``); the line is inline (the schema of :mod:`ato_common.line`) or a
TTOBench track (``line: {ttobench: path, dwell_s: 30}``), optionally with a TTOBench journey
(``journey: {ttobench: path}``) whose stopping points become the run's stations. Relative paths
are taken from the scenario file's folder. The optional ``supervision`` section sets the times
and distances of the braking-curve supervision (:mod:`ato_common.braking_curves`). The optional
``uncertainty`` section is the distribution of the scenario's uncertain train, line and sensors
(the schema of :mod:`ato_common.uncertainty`): a campaign whose file gives no uncertainty draws
from it; a single run (the nodes, ``make demo``, ``make compare``) never reads it. The
``timetable`` section chooses the driving strategy of the target curve (:class:`Timetable`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Mapping

from ato_common import trains, ttobench, units
from ato_common.braking_curves import (
    SupervisionSettings,
    constant_deceleration,
    tabulated_deceleration,
)
from ato_common.files import load_yaml, load_yaml_text
from ato_common.line import Line, PiecewiseConstant, default_balise_groups, parse_line
from ato_common.plant_setup import PlantSetup, parse_plant_setup
from ato_common.trains import TRAIN_PRESETS, TrainParameters, train_preset
from ato_common.uncertainty import Distribution, parse_uncertainty
from ato_common.validation import ConfigError, Fields

DEFAULT_SCENARIO = 'short_line'


@dataclass(frozen=True)
class PlanningLimits:
    """The train's dynamic limits used to plan the reference (not the physical limits)."""

    max_acceleration_mps2: float
    service_deceleration_mps2: float
    max_jerk_mps3: float
    speed_margin_mps: float


STRATEGIES = ('fastest', 'timetable')
# The running-time supplement (recovery margin) on the shortest running time when no times are
# given. UIC Code 451-1 (4th ed., 2000, "Timetable recovery margins to guarantee timekeeping")
# sets the recovery margin as a share of the minimum running time (plus a figure per distance)
# by train type and speed; 7 % is the figure the suite's issue 17 took for high-speed trains,
# not a value read from the leaflet's table (which the suite does not reproduce).
DEFAULT_SUPPLEMENT_PERCENT = 7.0
# The train is replanned when it is this far behind the plan, s.
DEFAULT_REPLAN_DELAY_S = 10.0


@dataclass(frozen=True)
class Timetable:
    """How the target curve is driven (``timetable:`` of a scenario file).

    ``strategy``: ``fastest`` (flat out within the limits) or ``timetable`` (least traction
    energy meeting each stop's arrival time and every window of the journey; the default when
    the journey gives times). ``supplement_percent``: without times, each leg's target running
    time is its shortest one plus this share. ``run_infeasible``: a journey whose windows cannot
    all be met is refused unless this is true (then it is run as close as possible).
    ``replan_delay_s``: the rest of the leg is planned again from the measured state once the
    train is this far behind the plan (0: never). The regenerative brake's efficiency, which
    the plan values braking at, is the train's (``TrainParameters.regenerative_efficiency``)."""

    strategy: str = 'fastest'
    supplement_percent: float = DEFAULT_SUPPLEMENT_PERCENT
    run_infeasible: bool = False
    replan_delay_s: float = DEFAULT_REPLAN_DELAY_S


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
    supervision: SupervisionSettings
    plant: PlantSetup = PlantSetup()  # what varies, actuators, failures, sensors
    journey: ttobench.TTOBenchJourney | None = None  # timing points of a TTOBench journey
    timetable: Timetable = Timetable()
    #: the ``uncertainty:`` section, parsed (None: absent); read by campaigns only
    uncertainty: Mapping[str, Distribution] | None = None


def builtin_scenarios() -> list[str]:
    folder = resources.files('ato_common') / 'scenarios'
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith('.yaml'))


def load_scenario(name_or_path: str) -> Scenario:
    """Load a built-in scenario by name or a scenario file by path; raise ConfigError if invalid."""
    if name_or_path in builtin_scenarios():
        origin = f'built-in scenario {name_or_path}'
        folder = resources.files('ato_common') / 'scenarios'
        data = load_yaml_text((folder / f'{name_or_path}.yaml').read_text(), origin)
        base = Path(str(folder))
    else:
        path = Path(name_or_path)
        if not path.is_file():
            raise ConfigError(f"scenario '{name_or_path}' is neither a built-in scenario "
                              f"({', '.join(builtin_scenarios())}) nor a readable file")
        origin = str(path)
        base = path.parent
        data = load_yaml(path)
    try:
        return parse_scenario(data, origin, base)
    except ConfigError as error:
        raise ConfigError(f'{origin}: {error}') from None


def _file(fields: Fields, key: str, base: Path) -> Path:
    path = Path(fields.text(key)).expanduser()
    path = path if path.is_absolute() else base / path
    if not path.is_file():
        raise ConfigError(f'{fields.where}.{key}: no such file {path}')
    return path


def _parse_train(f: Fields, base: Path) -> tuple[TrainParameters, ttobench.TTOBenchTrain | None]:
    fields = f.section('train', required=True)
    # The rail condition sets the wheel-rail adhesion that bounds the braking (trains.py).
    rail = fields.text('rail', 'dry')
    if rail not in trains.RAIL_CONDITIONS:
        raise ConfigError(f"{fields.where}.rail: unknown rail condition '{rail}'; valid: "
                          f"{', '.join(trains.RAIL_CONDITIONS)}")
    if fields.has('ttobench'):
        loaded = ttobench.load_train(_file(fields, 'ttobench', base), rail)
        train = _regeneration(fields, loaded.parameters)
        fields.reject_unknown()
        return train, loaded
    preset = fields.text('preset')
    if preset not in TRAIN_PRESETS:
        raise ConfigError(f"{fields.where}.preset: unknown train '{preset}'; valid: "
                          f"{', '.join(sorted(TRAIN_PRESETS))}")
    train = _regeneration(fields, train_preset(preset))
    fields.reject_unknown()
    if rail == 'dry':
        return train, None  # every preset is within the dry-rail bound (a test checks it)
    # A preset gives only its equivalent mass: adhesion is taken on it.
    bounded = trains.bound_braking(train.traction, train.mass_kg, rail)
    return replace(train, traction=bounded.traction), None


def _regeneration(fields: Fields, train: TrainParameters) -> TrainParameters:
    """The train with the section's ``regenerative_efficiency`` if it gives one (default:
    the train's: a TTOBench file's ``efficiency reg brake``, 0 for a preset)."""
    if not fields.has('regenerative_efficiency'):
        return train
    return replace(train, regenerative_efficiency=fields.number(
        'regenerative_efficiency', minimum=0.0, maximum=1.0))


def _parse_line(f: Fields, base: Path) -> tuple[Line, ttobench.TTOBenchJourney | None]:
    raw = f.raw('line', required=True)
    if not (isinstance(raw, dict) and 'ttobench' in raw):
        line = parse_line(raw, 'line')
        journey_section = f.section('journey')
        if journey_section.has('ttobench'):
            raise ConfigError('journey.ttobench: a TTOBench journey needs a TTOBench track '
                              '(line.ttobench)')
        journey_section.reject_unknown()
        return line, None
    fields = f.section('line')
    path = _file(fields, 'ttobench', base)
    track = ttobench.load_track(path, fields.number('dwell_s', 0.0, minimum=0.0))
    fields.reject_unknown()
    journey_fields = f.section('journey')
    if journey_fields.has('ttobench'):
        journey_path = _file(journey_fields, 'ttobench', base)
        journey_fields.reject_unknown()
        journey = ttobench.load_journey(journey_path)
        return ttobench.apply_journey(track, journey, str(journey_path)), journey
    journey_fields.reject_unknown()
    return track.line, None


def _declares_balise_groups(f: Fields) -> bool:
    """The scenario's inline line gives ``balise_groups`` (an empty list: none at all); a
    TTOBench track has none to give."""
    raw = f.raw('line')
    return isinstance(raw, dict) and 'ttobench' not in raw and \
        raw.get('balise_groups') is not None


def _capped(line: Line, speed: float) -> Line:
    """The line's static limits capped at the train's maximum speed (part of the MRSP)."""
    limits = line.speed_limit_mps
    capped = PiecewiseConstant(limits.starts, [min(v, speed) for v in limits.values])
    return replace(line, speed_limit_mps=capped)


#: the odometry's declared accuracy in ``supervision:`` and the largest value each may take
ODOMETRY_ACCURACY_BOUNDS = {'location_accuracy_m': 1000.0, 'odometry_accuracy': 0.5,
                            'speed_accuracy_mps': 10.0, 'speed_accuracy_share': 0.5}


def _parse_supervision(f: Fields, train: TrainParameters,
                       loaded: ttobench.TTOBenchTrain | None) -> SupervisionSettings:
    """Decelerations from the train (its ETCS tables if TTOBench gives them, else its braking
    forces over its mass), times from the train's ETCS data, then the scenario's overrides."""
    defaults = SupervisionSettings(
        emergency_deceleration=constant_deceleration(
            train.traction.max_emergency_brake_force_n / train.mass_kg),
        service_deceleration=constant_deceleration(
            train.traction.max_service_brake_force_n / train.mass_kg))
    times = {}
    if loaded is not None and loaded.braking is not None:
        data = loaded.braking
        defaults = SupervisionSettings(
            emergency_deceleration=tabulated_deceleration(*zip(*data.emergency)),
            service_deceleration=tabulated_deceleration(*zip(*data.service)))
        times = {'traction_cut_off_s': data.traction_cut_off_s,
                 'emergency_brake_build_up_s': data.emergency_brake_build_up_s,
                 'service_brake_build_up_s': data.service_brake_build_up_s}
    s = f.section('supervision')
    values = {}
    for key in ('traction_cut_off_s', 'emergency_brake_build_up_s', 'service_brake_build_up_s',
                'warning_s', 'driver_reaction_s', 'indication_s', 'eoa_beyond_stop_m',
                'overlap_m'):
        default = times.get(key, getattr(defaults, key))
        values[key] = s.number(key, default, minimum=0.0, maximum=1000.0)
    for key, most in ODOMETRY_ACCURACY_BOUNDS.items():
        values[key] = s.number(key, 0.0, minimum=0.0, maximum=most)
    s.reject_unknown()
    return SupervisionSettings(defaults.emergency_deceleration, defaults.service_deceleration,
                               traction_acceleration_mps2=train.traction.max_traction_force_n
                               / train.mass_kg, **values)


def _journey_gives_times(journey: ttobench.TTOBenchJourney | None) -> bool:
    return journey is not None and any(
        p.earliest_s is not None or p.latest_s is not None for p in journey.timing_points[1:])


def _parse_timetable(f: Fields, journey: ttobench.TTOBenchJourney | None) -> Timetable:
    t = f.section('timetable')
    default = 'timetable' if _journey_gives_times(journey) else 'fastest'
    strategy = t.text('strategy', default)
    if strategy not in STRATEGIES:
        raise ConfigError(f"{t.where}.strategy: unknown strategy '{strategy}'; valid: "
                          f"{', '.join(STRATEGIES)}")
    flag = t.raw('run_infeasible')
    if flag is not None and not isinstance(flag, bool):
        raise ConfigError(f'{t.where}.run_infeasible: must be true or false, got {flag!r}')
    timetable = Timetable(
        strategy=strategy,
        supplement_percent=t.number('supplement_percent', DEFAULT_SUPPLEMENT_PERCENT,
                                    minimum=0.0, maximum=100.0),
        run_infeasible=bool(flag),
        replan_delay_s=t.number('replan_delay_s', DEFAULT_REPLAN_DELAY_S, minimum=0.0,
                                maximum=3600.0))
    t.reject_unknown()
    return timetable


def parse_scenario(data, origin: str = '<memory>', base: Path | None = None) -> Scenario:
    """``base``: the folder relative TTOBench paths are taken from (the scenario file's)."""
    base = base or Path.cwd()
    f = Fields(data, '')
    train, loaded_train = _parse_train(f, base)
    line, journey = _parse_line(f, base)
    if not _declares_balise_groups(f):  # the default placement, on the run's final stations
        line = replace(line, balise_groups_m=default_balise_groups(line))
    if loaded_train is not None:
        line = _capped(line, loaded_train.max_speed_mps)

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
        planning=planning, run=run, supervision=_parse_supervision(f, train, loaded_train),
        plant=parse_plant_setup(f.raw('plant'), train, 'plant'), journey=journey,
        timetable=_parse_timetable(f, journey),
        uncertainty=(None if f.raw('uncertainty') is None
                     else parse_uncertainty(f.raw('uncertainty'), 'uncertainty')))
    f.reject_unknown()
    return scenario
