"""TTOBench (Kouzoupis, Pendharkar & Corman 2023, BSD-2) tracks, trains and journeys as the
suite's Line, TrainParameters and stops.

The format is the one documented in the TTOBench library (``tracks/README.md``,
``trains/README.md``, ``journeys/README.md``): JSON files whose quantities carry their units
(``{"unit": "kN", "value": 200}`` or ``{"units": {...}, "values": [...]}``). Every quantity is
converted to SI here, by the unit it declares; an unknown unit is an error naming the file and
the field, as is any rule of the format that a file breaks.

Mapping (simplifications are stated where they are made):

* track ``stops`` -> stations (``stop_<i>``, dwell given by the scenario or a journey);
  ``speed limits`` -> static limits; ``gradients`` (per mille) -> grade sines;
  ``curvatures`` (position, radius at start, radius at end; signed, ``infinity`` = straight) ->
  curves with the curvature varying linearly between the two radii (clothoids); ``tunnels``
  (position, length, cross section) -> tunnels with their cross section. The length of the
  track is its last stop. Track ``ETCS braking data`` (M_NVAVADH, Kt_int) is read and
  validated; the suite's simplified supervision does not use it.
* train -> TrainParameters: equivalent mass = mass (1 + rho); r0 + r1 V + r2 V^2 (kN, V in km/h)
  -> Davis in N with v in m/s (nominal = true: TTOBench gives one law); traction force and
  power; service braking force = regenerative + pneumatic braking force (the regenerative power
  limit is kept in ``TTOBenchTrain`` but not in the suite's force model); emergency braking =
  the highest ETCS emergency deceleration times the equivalent mass if given, else the service
  force. Both are bounded by wheel-rail adhesion (mu m g, ``trains.ADHESION_COEFFICIENT``) and
  by the highest ETCS deceleration of their kind times the equivalent mass; a figure a bound
  lowers is a ``DataWarning`` (real files give regenerative plus pneumatic forces of 10 m/s^2
  and more). ``max speed``, comfort limits, efficiencies, the tunnel resistance table and
  the ETCS braking data (its tables bounded by adhesion too) stay on ``TTOBenchTrain``.
* journey -> the run's stations (stopping points: an arrival and a departure at one position
  give the dwell) and passing points (their upper speed bound becomes a speed restriction at
  that position, 1 m long, that the train-length rule then extends); time windows are kept for
  the planner.
"""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, overload

from ato_common import units
from ato_common.files import load_json
from ato_common.line import (
    MAX_GRADIENT_PER_MILLE,
    Curve,
    Line,
    PiecewiseConstant,
    Station,
    Tunnel,
    signed_curves,
)
from ato_common.trains import (
    DavisResistance,
    TractionCharacteristic,
    TrainParameters,
    adhesion_braking_limit_n,
    bound_braking,
)
from ato_common.validation import ConfigError, DataWarning, unknown_field_message

ID_PATTERN = re.compile(r'^[A-Za-z0-9_]+$')

# The fields of each object of the format (TTOBench's READMEs; its validator rejects any other
# field, and so does this reader: a misspelt optional field would otherwise pass as absent).
METADATA_FIELDS = ('id', 'library version', 'description', 'created by', 'license')
TRACK_FIELDS = ('metadata', 'altitude', 'stops', 'speed limits', 'gradients', 'curvatures',
                'tunnels', 'ETCS braking data')
TRACK_ETCS_FIELDS = ('M_NVAVADH', 'Kt_int')
TRAIN_FIELDS = ('metadata', 'num seats', 'num coaches', 'length', 'mass', 'rho',
                'max traction power', 'max reg braking power', 'max traction force',
                'max reg braking force', 'max pn braking force', 'max acceleration',
                'max deceleration', 'max speed', 'rolling resistance r0', 'rolling resistance r1',
                'rolling resistance r2', 'efficiency traction', 'efficiency reg brake',
                'tunnel resistance', 'ETCS braking data')
TRAIN_ETCS_FIELDS = ('A_brake_emergency', 'A_brake_service', 'K_dry_rst', 'K_wet_rst',
                     'T_traction', 'T_be', 'T_bs', 'v_uncertainty')
JOURNEY_FIELDS = ('metadata', 'timing points')
JOURNEY_METADATA_FIELDS = METADATA_FIELDS + ('associated track',)
# Length of the speed restriction standing for a passing point's upper speed bound, m.
PASSING_POINT_RESTRICTION_M = 1.0


# Unit conversions to SI, by the unit string the file declares.
def _identity(x: float) -> float:
    return x


def kn_per_kmh_to_n_s_per_m(coefficient: float) -> float:
    """A linear resistance coefficient in kN/(km/h) -> N/(m/s)."""
    return units.kn_to_n(coefficient) * units.KMH_PER_MPS


def kn_per_kmh2_to_n_s2_per_m2(coefficient: float) -> float:
    """A quadratic resistance coefficient in kN/(km/h)^2 -> N/(m/s)^2."""
    return units.kn_to_n(coefficient) * units.KMH_PER_MPS ** 2


def percent_to_fraction(value: float) -> float:
    return value / 100.0


CONVERSIONS = {
    'length': {'m': _identity, 'km': lambda x: x * 1000.0},
    'speed': {'km/h': units.kmh_to_mps, 'm/s': _identity},
    'slope': {'permil': units.per_mille_to_sine, 'per mille': units.per_mille_to_sine},
    'mass': {'kg': _identity, 't': units.tonnes_to_kg},
    'force': {'kN': units.kn_to_n, 'N': _identity},
    'power': {'kW': units.kw_to_w, 'W': _identity, 'MW': lambda x: x * 1e6},
    'acceleration': {'m/s^2': _identity},
    'fraction': {'%': percent_to_fraction, '-': _identity},
    'time': {'s': _identity},
    'area': {'m^2': _identity},
    'linear resistance': {'kN/(km/h)': kn_per_kmh_to_n_s_per_m},
    'quadratic resistance': {'kN/(km/h)^2': kn_per_kmh2_to_n_s2_per_m2},
    'count': {'-': _identity},
}


class _Reader:
    """Field access with errors naming the file and the field."""

    def __init__(self, path: Path, data: Any, where: str = ''):
        self.path, self.data, self.where = path, data, where

    def _place(self, field_name: str) -> str:
        return f'{self.where}.{field_name}' if self.where else field_name

    def fail(self, field_name: str, what: str) -> ConfigError:
        return ConfigError(f'{self.path}: {self._place(field_name)}: {what}')

    def only(self, valid: tuple[str, ...]) -> None:
        """Reject any field of this object that is not one of ``valid``, naming the file, the
        field, its likely intended name and the valid names."""
        if not isinstance(self.data, dict):
            raise ConfigError(f'{self.path}: {self.where or "the file"}: expected an object')
        unknown = [str(k) for k in self.data if k not in valid]
        if unknown:
            place = f'{self.where}: ' if self.where else ''
            raise ConfigError(f'{self.path}: {place}'
                              f'{unknown_field_message(unknown, valid, quote=repr)}')

    def get(self, key: str, required: bool = True) -> Any:
        if not isinstance(self.data, dict):
            raise ConfigError(f'{self.path}: {self.where or "the file"}: expected an object')
        if key not in self.data or self.data[key] is None:
            if required:
                raise self.fail(key, 'required field is missing')
            return None
        return self.data[key]

    def number(self, value: Any, field_name: str, minimum: float | None = None,
               exclusive: bool = False, allow_infinity: bool = False) -> float:
        if allow_infinity and isinstance(value, str) and value.strip().lower() in (
                'infinity', 'inf', '+infinity', '-infinity', '-inf'):
            return -math.inf if value.strip().startswith('-') else math.inf
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(field_name, f'must be a number, got {value!r}')
        value = float(value)
        if math.isnan(value) or (math.isinf(value) and not allow_infinity):
            raise self.fail(field_name, f'must be finite, got {value!r}')
        if minimum is not None and (value < minimum or (exclusive and value == minimum)):
            raise self.fail(field_name, f'must be {">" if exclusive else ">="} {minimum:g}, '
                            f'got {value:g}')
        return value

    def unit(self, key: str, declared: Any, quantity: str):
        table = CONVERSIONS[quantity]
        if declared not in table:
            raise self.fail(key, f'unit {declared!r} is not a {quantity} unit this reader knows '
                            f'({", ".join(table)})')
        return table[declared]

    @overload
    def scalar(self, key: str, quantity: str, required: Literal[True] = True,
               minimum: float | None = None, exclusive: bool = False) -> float: ...

    @overload
    def scalar(self, key: str, quantity: str, required: bool,
               minimum: float | None = None, exclusive: bool = False) -> float | None: ...

    def scalar(self, key: str, quantity: str, required: bool = True, minimum: float | None = None,
               exclusive: bool = False) -> float | None:
        """A {"unit": ..., "value": ...} field in SI (None: absent and not ``required``)."""
        entry = self.get(key, required)
        if entry is None:
            return None
        if not isinstance(entry, dict) or 'value' not in entry:
            raise self.fail(key, 'expected {"unit": ..., "value": ...}')
        _Reader(self.path, entry, self._place(key)).only(('unit', 'value'))
        convert = self.unit(f'{key}.unit', entry.get('unit'), quantity)
        return convert(self.number(entry['value'], f'{key}.value', minimum, exclusive))

    @overload
    def table(self, key: str, columns: list[tuple[str, str]], required: Literal[True] = True
              ) -> list[list[Any]]: ...

    @overload
    def table(self, key: str, columns: list[tuple[str, str]], required: bool
              ) -> list[list[Any]] | None: ...

    def table(self, key: str, columns: list[tuple[str, str]], required: bool = True
              ) -> list[list[Any]] | None:
        """Rows of a {"units": {column: unit}, "values": [[...]]} field, each value converted;
        a column's quantity may be 'raw' (kept as given)."""
        entry = self.get(key, required)
        if entry is None:
            return None
        if not isinstance(entry, dict) or not isinstance(entry.get('values'), list):
            raise self.fail(key, 'expected {"units": {...}, "values": [[...], ...]}')
        declared = entry.get('units', {})
        if len(columns) == 1 and 'unit' in entry:
            _Reader(self.path, entry, self._place(key)).only(('unit', 'values'))
            declared = {columns[0][0]: entry['unit']}
        else:
            _Reader(self.path, entry, self._place(key)).only(('units', 'values'))
            if isinstance(declared, dict):
                _Reader(self.path, declared, self._place(f'{key}.units')).only(
                    tuple(name for name, quantity in columns if quantity != 'raw'))
        converters: list[Any] = []
        for name, quantity in columns:
            if quantity == 'raw':
                converters.append(None)
                continue
            if not isinstance(declared, dict) or name not in declared:
                raise self.fail(f'{key}.units', f'the unit of {name!r} is missing')
            converters.append(self.unit(f'{key}.units.{name}', declared[name], quantity))
        rows = []
        for i, row in enumerate(entry['values']):
            cells = row if len(columns) > 1 else [row]
            if not isinstance(cells, list) or len(cells) != len(columns):
                raise self.fail(f'{key}.values[{i}]', f'expected {len(columns)} values '
                                f'({", ".join(n for n, _ in columns)}), got {row!r}')
            converted = []
            for j, ((name, _), convert, cell) in enumerate(zip(columns, converters, cells)):
                if convert is None:
                    converted.append(cell)
                else:
                    converted.append(convert(self.number(
                        cell, f'{key}.values[{i}][{j}] ({name})',
                        allow_infinity=name.startswith('radius'))))
            rows.append(converted)
        return rows


def _read_json(path: str | Path) -> tuple[Path, Any]:
    path = Path(path)
    return path, load_json(path)


def _metadata_id(reader: _Reader, fields: tuple[str, ...] = METADATA_FIELDS) -> str:
    metadata = _Reader(reader.path, reader.get('metadata'), 'metadata')
    metadata.only(fields)
    identifier = metadata.get('id')
    if not isinstance(identifier, str) or not ID_PATTERN.match(identifier):
        raise metadata.fail('id', f'must contain only letters, numbers and underscores, got '
                            f'{identifier!r}')
    metadata.get('library version')
    return identifier


def _increasing(reader: _Reader, key: str, positions: list[float], strict: bool = True) -> None:
    for i, (a, b) in enumerate(zip(positions, positions[1:])):
        if b < a or (strict and b == a):
            raise reader.fail(f'{key}.values[{i + 1}]', f'positions must '
                              f'{"strictly " if strict else ""}increase, got {a:g} then {b:g} m')


@dataclass(frozen=True)
class TTOBenchTrack:
    id: str
    line: Line
    stops_m: tuple[float, ...]
    etcs_m_nvavadh: float | None = None
    etcs_kt_int: float | None = None


def load_track(path: str | Path, dwell_s: float = 0.0) -> TTOBenchTrack:
    """A TTOBench track as a Line; every stop becomes a station with ``dwell_s``."""
    path, data = _read_json(path)
    reader = _Reader(path, data)
    reader.only(TRACK_FIELDS)
    identifier = _metadata_id(reader)
    reader.scalar('altitude', 'length', required=False)
    stops = _stops(reader)
    length = stops[-1]
    limits = _sections(reader, 'speed limits', 'velocity', 'speed', length, True)
    assert limits is not None  # required
    for i, (_, speed) in enumerate(limits):
        if speed <= 0.0:
            raise reader.fail(f'speed limits.values[{i}]', 'the speed limit must be > 0')
    grades = _sections(reader, 'gradients', 'slope', 'slope', length, False) or [[0.0, 0.0]]
    steepest = units.per_mille_to_sine(MAX_GRADIENT_PER_MILLE)
    for i, (_, sine) in enumerate(grades):
        if abs(sine) > steepest:
            per_mille = 1000.0 * math.tan(math.asin(sine))
            raise reader.fail(f'gradients.values[{i}]', f'{per_mille:g} per mille is steeper '
                              f'than any line worked by adhesion (at most '
                              f'{MAX_GRADIENT_PER_MILLE:g} per mille: ato_common.line)')
    m_nvavadh = kt_int = None
    etcs = reader.get('ETCS braking data', required=False)
    if etcs is not None:
        sub = _Reader(path, etcs, 'ETCS braking data')
        sub.only(TRACK_ETCS_FIELDS)
        m_nvavadh = sub.scalar('M_NVAVADH', 'fraction')
        kt_int = sub.scalar('Kt_int', 'fraction')

    stations = tuple(Station(f'stop_{i}', s, dwell_s if 0 < i < len(stops) - 1 else 0.0)
                     for i, s in enumerate(stops))
    line = Line(identifier, length, stations,
                PiecewiseConstant([r[0] for r in limits], [r[1] for r in limits]),
                PiecewiseConstant([r[0] for r in grades], [r[1] for r in grades]),
                _curves(reader, length), _tunnels(reader, length))
    return TTOBenchTrack(identifier, line, tuple(stops), m_nvavadh, kt_int)


def _stops(reader: _Reader) -> list[float]:
    stops = [row[0] for row in reader.table('stops', [('position', 'length')])]
    if len(stops) < 2:
        raise reader.fail('stops.values', 'at least two stops (origin and destination) are '
                          'needed')
    if stops[0] != 0.0:
        raise reader.fail('stops.values[0]', f'the first stop must be at 0 m, got {stops[0]:g}')
    _increasing(reader, 'stops', stops)
    return stops


def _sections(reader: _Reader, key: str, column: str, quantity: str, length: float,
              required: bool) -> list[list[Any]] | None:
    """The rows of a piecewise quantity of the track: from 0 m, increasing, each starting
    before the end of the track."""
    rows = reader.table(key, [('position', 'length'), (column, quantity)], required)
    if rows is None:
        return None
    positions = [r[0] for r in rows]
    if not rows:
        raise reader.fail(f'{key}.values', 'must not be empty')
    if positions[0] != 0.0:
        raise reader.fail(f'{key}.values[0]', f'the first entry must start at 0 m, got '
                          f'{positions[0]:g}')
    _increasing(reader, key, positions)
    if positions[-1] >= length:
        raise reader.fail(f'{key}.values[{len(rows) - 1}]', f'starts at {positions[-1]:g} m, '
                          f'not before the end of the track ({length:g} m)')
    return rows


def _curves(reader: _Reader, length: float) -> tuple[Curve, ...]:
    """The curvatures as curves, their radii signed as the file signs them (``Curve``)."""
    rows = reader.table('curvatures', [('position', 'length'), ('radius at start', 'length'),
                                       ('radius at end', 'length')], required=False)
    if not rows:
        return ()
    positions = [r[0] for r in rows]
    if positions[0] != 0.0:
        raise reader.fail('curvatures.values[0]', 'the first entry must start at 0 m')
    _increasing(reader, 'curvatures', positions)
    curves: list[Curve] = []
    ends = positions[1:] + [length]
    for i, ((start, r_start, r_end), end) in enumerate(zip(rows, ends)):
        if r_start == 0.0 or r_end == 0.0:
            raise reader.fail(f'curvatures.values[{i}]', 'a radius of 0 m is not a curve')
        if start >= length:
            raise reader.fail(f'curvatures.values[{i}]', 'starts beyond the end of the track')
        if math.isinf(r_start) and math.isinf(r_end):
            continue  # straight
        curves.extend(signed_curves(start, end - start, r_start, r_end))
    return tuple(curves)


def _tunnels(reader: _Reader, length: float) -> tuple[Tunnel, ...]:
    rows = reader.table('tunnels', [('position', 'length'), ('length', 'length'),
                                    ('cross section', 'area')], required=False)
    if not rows:
        return ()
    _increasing(reader, 'tunnels', [r[0] for r in rows])
    tunnels = []
    for i, (start, tunnel_length, section) in enumerate(rows):
        if tunnel_length < 0.0 or section <= 0.0:
            raise reader.fail(f'tunnels.values[{i}]', 'the length must be >= 0 and the cross '
                              'section > 0')
        if start + tunnel_length > length:
            raise reader.fail(f'tunnels.values[{i}]', f'ends at {start + tunnel_length:g} m, '
                              f'beyond the end of the track ({length:g} m)')
        if tunnel_length > 0.0:
            tunnels.append(Tunnel(start, tunnel_length, cross_section_m2=section))
    return tuple(tunnels)


@dataclass(frozen=True)
class ETCSBrakingData:
    """Train-side ETCS braking data of TTOBench (decelerations by speed, SI)."""

    emergency: tuple[tuple[float, float], ...]   # (speed m/s, deceleration m/s^2)
    service: tuple[tuple[float, float], ...]
    k_dry_rst: float
    k_wet_rst: float
    traction_cut_off_s: float
    emergency_brake_build_up_s: float
    service_brake_build_up_s: float
    speed_uncertainty: float  # fraction


@dataclass(frozen=True)
class TTOBenchTrain:
    id: str
    parameters: TrainParameters
    max_speed_mps: float
    max_acceleration_mps2: float | None
    max_deceleration_mps2: float | None
    max_regenerative_braking_power_w: float
    efficiency_traction: float | None
    efficiency_regenerative_brake: float | None
    tunnel_resistance: tuple[tuple[float, float], ...] = ()  # (cross section m^2, N/(m/s)^2)
    braking: ETCSBrakingData | None = None
    sources: dict = field(default_factory=dict)
    braking_notes: tuple[str, ...] = ()  # what the physical braking bounds changed (warned)
    braking_bound_mps2: float = math.inf  # the documented bound on the braking deceleration


def _deceleration_table(reader: _Reader, key: str) -> tuple[tuple[float, float], ...]:
    rows = reader.table(key, [('velocity', 'speed'), ('deceleration', 'acceleration')])
    if not rows:
        raise reader.fail(f'{key}.values', 'must not be empty')
    _increasing(reader, key, [r[0] for r in rows])
    for i, (_, deceleration) in enumerate(rows):
        if deceleration <= 0.0:
            raise reader.fail(f'{key}.values[{i}]', 'decelerations are positive by convention')
    return tuple((r[0], r[1]) for r in rows)


def _bounded_table(table: tuple[tuple[float, float], ...], bound_mps2: float
                   ) -> tuple[tuple[float, float], ...]:
    return tuple((speed, min(deceleration, bound_mps2)) for speed, deceleration in table)


# Plausibility of a train's figures: load_train refuses a file outside these bounds, naming the
# figure. Wide enough for every real train from a tram to a heavy-haul freight train, narrow
# enough that a unit read wrong (t for kg, N for kN, W for kW: a factor of 1000) falls outside.
#: static mass per metre of train, t/m: EMUs about 2, locomotive-hauled trains 2-4, freight
#: wagons up to 8.8 (EN 15528's heaviest line category), heavy haul at 40 t per axle about 15
MASS_PER_METRE_T = (0.3, 20.0)
#: a force (the traction force; the service braking force) over the static weight: no
#: wheel-rail contact transmits twice the weight (adhesion is about 0.4 at best; braking data
#: of real files reach about 1, bounded later by adhesion), and a heavy freight train's
#: tractive effort is about 1 % of its weight
FORCE_OVER_WEIGHT = (0.002, 2.0)
#: traction power per tonne of static mass, kW/t: heavy freight about 1, EMUs 10-25
POWER_PER_TONNE_KW = (0.2, 100.0)
#: the running resistance at the maximum speed over the static weight: a few per cent on real
#: trains (at most)
RESISTANCE_OVER_WEIGHT_AT_MAX_SPEED = 0.2


@dataclass(frozen=True)
class _TrainFigures:
    """A train file's scalar figures, in SI."""

    mass: float
    equivalent_mass: float
    power: float
    traction_force: float
    regenerative_power: float
    service_force: float
    max_speed: float
    davis: DavisResistance
    efficiency_traction: float | None
    efficiency_brake: float | None
    length: float
    length_source: str
    max_acceleration: float | None
    max_deceleration: float | None


def _train_figures(reader: _Reader) -> _TrainFigures:
    reader.scalar('num seats', 'count', required=False, minimum=0.0)
    mass = reader.scalar('mass', 'mass', minimum=0.0, exclusive=True)
    rho = reader.scalar('rho', 'fraction', required=False, minimum=0.0) or 0.0
    regenerative_force = reader.scalar('max reg braking force', 'force', minimum=0.0)
    pneumatic_force = reader.scalar('max pn braking force', 'force', required=False,
                                    minimum=0.0) or 0.0
    if regenerative_force + pneumatic_force <= 0.0:
        raise reader.fail('max reg braking force', 'the train has no braking force (regenerative '
                          'plus pneumatic is 0)')
    length = reader.scalar('length', 'length', required=False, minimum=0.0, exclusive=True)
    coaches = reader.scalar('num coaches', 'count', required=False, minimum=1.0)
    if length is not None:
        length_source = f'{reader.path.name}: length'
    else:
        # The format makes the length optional; 25 m per coach, else a 200 m unit.
        length = 25.0 * coaches if coaches else 200.0
        length_source = ('not in the file: 25 m per coach' if coaches else
                         'not in the file: suite default 200 m')
    return _TrainFigures(
        mass=mass, equivalent_mass=mass * (1.0 + rho),
        power=reader.scalar('max traction power', 'power', minimum=0.0, exclusive=True),
        traction_force=reader.scalar('max traction force', 'force', minimum=0.0,
                                     exclusive=True),
        regenerative_power=reader.scalar('max reg braking power', 'power', minimum=0.0),
        service_force=regenerative_force + pneumatic_force,
        max_speed=reader.scalar('max speed', 'speed', minimum=0.0, exclusive=True),
        davis=DavisResistance(
            reader.scalar('rolling resistance r0', 'force', minimum=0.0),
            reader.scalar('rolling resistance r1', 'linear resistance'),
            reader.scalar('rolling resistance r2', 'quadratic resistance', minimum=0.0)),
        efficiency_traction=reader.scalar('efficiency traction', 'fraction', required=False,
                                          minimum=0.0, exclusive=True),
        efficiency_brake=reader.scalar('efficiency reg brake', 'fraction', required=False,
                                       minimum=0.0),
        length=length, length_source=length_source,
        max_acceleration=reader.scalar('max acceleration', 'acceleration', required=False,
                                       minimum=0.0, exclusive=True),
        max_deceleration=reader.scalar('max deceleration', 'acceleration', required=False,
                                       minimum=0.0, exclusive=True))


def _check_plausible(reader: _Reader, figures: _TrainFigures) -> None:
    """Refuse figures no train has (the bounds above), naming the field and its unit."""
    def declared(key: str) -> str:
        entry = reader.data.get(key)
        return f' (the file declares {entry.get("unit")!r})' if isinstance(entry, dict) else ''

    def outside(key: str, what: str, value: float, bounds: tuple[float, float],
                unit: str) -> None:
        low, high = bounds
        if not low <= value <= high:
            raise reader.fail(f'{key}.value', f'{what} is {value:.4g} {unit}, outside the '
                              f'{low:g}-{high:g} {unit} of real trains: a wrong figure or '
                              f'unit{declared(key)}')
    weight = figures.mass * units.STANDARD_GRAVITY
    outside('mass', f'{figures.mass / 1000.0:.6g} t over a length of {figures.length:g} m '
            f'({figures.length_source})', figures.mass / 1000.0 / figures.length,
            MASS_PER_METRE_T, 't/m')
    outside('max traction force', 'the traction force over the weight',
            figures.traction_force / weight, FORCE_OVER_WEIGHT, 'x weight')
    outside('max reg braking force', 'the regenerative plus pneumatic braking force over '
            'the weight', figures.service_force / weight, FORCE_OVER_WEIGHT, 'x weight')
    outside('max traction power', 'the traction power per tonne',
            figures.power / figures.mass, POWER_PER_TONNE_KW, 'kW/t')
    resistance = figures.davis.force(figures.max_speed) / weight
    if resistance > RESISTANCE_OVER_WEIGHT_AT_MAX_SPEED:
        raise reader.fail('rolling resistance r0', f'the running resistance at the maximum '
                          f'speed is {resistance:.3g} x the weight (real trains: a few per '
                          f'cent, at most {RESISTANCE_OVER_WEIGHT_AT_MAX_SPEED:g}): a wrong '
                          'figure or unit of r0, r1, r2 or max speed')


def _etcs_braking_data(reader: _Reader) -> ETCSBrakingData | None:
    etcs = reader.get('ETCS braking data', required=False)
    if etcs is None:
        return None
    sub = _Reader(reader.path, etcs, 'ETCS braking data')
    sub.only(TRAIN_ETCS_FIELDS)
    return ETCSBrakingData(
        emergency=_deceleration_table(sub, 'A_brake_emergency'),
        service=_deceleration_table(sub, 'A_brake_service'),
        k_dry_rst=sub.scalar('K_dry_rst', 'fraction', minimum=0.0, exclusive=True),
        k_wet_rst=sub.scalar('K_wet_rst', 'fraction', minimum=0.0, exclusive=True),
        traction_cut_off_s=sub.scalar('T_traction', 'time', minimum=0.0),
        emergency_brake_build_up_s=sub.scalar('T_be', 'time', minimum=0.0),
        service_brake_build_up_s=sub.scalar('T_bs', 'time', minimum=0.0),
        speed_uncertainty=sub.scalar('v_uncertainty', 'fraction', minimum=0.0))


def _bounded_braking(figures: _TrainFigures, braking: ETCSBrakingData | None, rail: str):
    """The braking capability (docs/guide/plant.md, "Braking bound"): the data's forces bounded
    by adhesion on the static mass and by the ETCS decelerations (their highest value, at the
    lowest speed) times the equivalent mass; the ETCS tables themselves by adhesion. Returns
    (traction characteristic, bounded ETCS data, notes of what a bound lowered, the bound on
    the braking deceleration)."""
    mass, equivalent_mass = figures.mass, figures.equivalent_mass
    emergency_force = (max(d for _, d in braking.emergency) * equivalent_mass if braking
                       else figures.service_force)
    unbounded = TractionCharacteristic(figures.traction_force, figures.power,
                                       figures.service_force, emergency_force)
    bounded = bound_braking(
        unbounded, mass, rail,
        service_limit_n=max(d for _, d in braking.service) * equivalent_mass if braking else None,
        emergency_limit_n=(max(d for _, d in braking.emergency) * equivalent_mass if braking
                           else None),
        names={'service': 'max reg braking force + max pn braking force',
               'emergency': 'ETCS braking data.A_brake_emergency x equivalent mass' if braking
               else 'the emergency braking force (the service force: no ETCS data)'})
    notes = list(bounded.notes)
    adhesion_mps2 = adhesion_braking_limit_n(mass, rail) / equivalent_mass
    if braking is not None:
        for key, table in (('A_brake_emergency', braking.emergency),
                           ('A_brake_service', braking.service)):
            highest = max(d for _, d in table)
            if highest > adhesion_mps2:
                notes.append(f'ETCS braking data.{key} {highest:g} m/s^2 exceeds the wheel-rail '
                             f'adhesion bound {adhesion_mps2:.3f} m/s^2 ({rail} rail); bounded')
        braking = ETCSBrakingData(
            _bounded_table(braking.emergency, adhesion_mps2),
            _bounded_table(braking.service, adhesion_mps2), braking.k_dry_rst,
            braking.k_wet_rst, braking.traction_cut_off_s, braking.emergency_brake_build_up_s,
            braking.service_brake_build_up_s, braking.speed_uncertainty)
    bound_mps2 = min(adhesion_mps2, max(d for _, d in braking.emergency + braking.service)
                     if braking else math.inf)
    return bounded.traction, braking, notes, bound_mps2


def load_train(path: str | Path, rail: str = 'dry') -> TTOBenchTrain:
    """A TTOBench train. Figures no train has (``_check_plausible``) are refused, naming the
    field. Its braking is bounded by wheel-rail adhesion on a ``rail`` ('dry' or 'wet') rail
    and by its ETCS decelerations where it has them (``trains.bound_braking``); each figure a
    bound lowers is a DataWarning naming the file, the figure and the bound."""
    path, data = _read_json(path)
    reader = _Reader(path, data)
    reader.only(TRAIN_FIELDS)
    identifier = _metadata_id(reader)
    figures = _train_figures(reader)
    tunnel = reader.table('tunnel resistance', [('cross section', 'area'),
                                                ('coefficient', 'quadratic resistance')],
                          required=False) or []
    braking = _etcs_braking_data(reader)
    _check_plausible(reader, figures)
    traction, braking, notes, bound_mps2 = _bounded_braking(figures, braking, rail)
    for note in notes:
        warnings.warn(f'{path}: {note}', DataWarning, stacklevel=2)
    # The regenerative brake returns its efficiency's share of the braking work up to its power
    # (none without a regenerative power).
    regenerating = figures.regenerative_power > 0.0
    parameters = TrainParameters(
        name=identifier,
        description=f'TTOBench train {identifier} ({path.name})',
        mass_kg=figures.equivalent_mass, davis=figures.davis, davis_nominal=figures.davis,
        traction=traction, actuator_names=('traction',), length_m=figures.length,
        max_speed_mps=figures.max_speed,
        regenerative_efficiency=(figures.efficiency_brake or 0.0) if regenerating else 0.0,
        regenerative_power_w=figures.regenerative_power,
        sources=_train_sources(path, rail, figures, braking is not None))
    return TTOBenchTrain(identifier, parameters, figures.max_speed, figures.max_acceleration,
                         figures.max_deceleration, figures.regenerative_power,
                         figures.efficiency_traction, figures.efficiency_brake,
                         tuple((r[0], r[1]) for r in tunnel), braking,
                         braking_notes=tuple(notes), braking_bound_mps2=bound_mps2)


def _train_sources(path: Path, rail: str, figures: _TrainFigures, etcs: bool) -> dict:
    return {'all': f'TTOBench train file {path} (BSD-2, Kouzoupis et al. 2023)',
            'mass_kg': 'mass times (1 + rho)', 'length_m': figures.length_source,
            'max_service_brake_force_n':
                'regenerative plus pneumatic braking force, bounded by adhesion '
                f'(mu on a {rail} rail x mass x g)'
                + (' and by the highest ETCS A_brake_service times the equivalent mass'
                   if etcs else ''),
            'max_emergency_brake_force_n':
                'the highest ETCS A_brake_emergency times the equivalent mass, bounded by '
                'adhesion' if etcs else 'the service braking force (no ETCS data)',
            'regenerative_efficiency, regenerative_power_w':
                'efficiency reg brake (0 without a regenerative power), max reg braking power'}


@dataclass(frozen=True)
class TimingPoint:
    position_m: float
    earliest_s: float | None
    latest_s: float | None
    lowest_speed_mps: float | None
    highest_speed_mps: float | None

    @property
    def is_stopping_point(self) -> bool:
        return self.lowest_speed_mps == 0.0 and self.highest_speed_mps == 0.0


@dataclass(frozen=True)
class TTOBenchJourney:
    id: str
    track_id: str
    timing_points: tuple[TimingPoint, ...]

    def stations(self) -> tuple[Station, ...]:
        """Stopping points as stations; an arrival and a departure at one position make one
        station whose dwell is the difference of their earliest times (0 if not given)."""
        stations: list[Station] = []
        stopping = [p for p in self.timing_points if p.is_stopping_point]
        i = 0
        while i < len(stopping):
            point = stopping[i]
            dwell = 0.0
            if i + 1 < len(stopping) and stopping[i + 1].position_m == point.position_m:
                departure = stopping[i + 1]
                if departure.earliest_s is not None and point.earliest_s is not None:
                    dwell = max(departure.earliest_s - point.earliest_s, 0.0)
                i += 1
            stations.append(Station(f'stop_{len(stations)}', point.position_m, dwell))
            i += 1
        return tuple(stations)

    def earliest_departure_s(self, position_m: float) -> float | None:
        """The lower time bound of the last stopping point at a position (the departure)."""
        times = [p.earliest_s for p in self.timing_points
                 if p.is_stopping_point and p.position_m == position_m]
        return times[-1] if times else None

    def passing_speed_bounds(self) -> tuple[tuple[float, float], ...]:
        """(position, highest speed) of every passing point with an upper speed bound."""
        return tuple((p.position_m, p.highest_speed_mps) for p in self.timing_points
                     if not p.is_stopping_point and p.highest_speed_mps is not None)


def load_journey(path: str | Path) -> TTOBenchJourney:
    path, data = _read_json(path)
    reader = _Reader(path, data)
    reader.only(JOURNEY_FIELDS)
    identifier = _metadata_id(reader, JOURNEY_METADATA_FIELDS)
    metadata = _Reader(path, reader.get('metadata'), 'metadata')
    track_id = metadata.get('associated track')
    if not isinstance(track_id, str) or not identifier.startswith(track_id + '_'):
        raise metadata.fail('id', f'must start with the associated track {track_id!r} and an '
                            f'underscore, got {identifier!r}')
    entry = reader.get('timing points')
    names = ('position', 'lower time constraint', 'upper time constraint',
             'lower speed constraint', 'upper speed constraint')
    quantities = ('length', 'time', 'time', 'speed', 'speed')
    if isinstance(entry, dict):
        _Reader(path, entry, 'timing points').only(('units', 'values'))
        declared = entry.get('units')
        if not isinstance(declared, dict):
            raise reader.fail('timing points.units', 'expected the unit of each column')
        _Reader(path, declared, 'timing points.units').only(names)
        converters = []
        for name, quantity in zip(names, quantities):
            if name not in declared:
                raise reader.fail('timing points.units', f'the unit of {name!r} is missing')
            converters.append(reader.unit(f'timing points.units.{name}', declared[name],
                                          quantity))
        rows = entry.get('values')
    else:
        # A bare list (early library versions): m, s, s, km/h, km/h as the tracks.
        converters = [_identity, _identity, _identity, units.kmh_to_mps, units.kmh_to_mps]
        rows = entry
    if not isinstance(rows, list) or len(rows) < 2:
        raise reader.fail('timing points', 'at least two timing points are needed')
    points = []
    for i, row in enumerate(rows):
        where = f'timing points[{i}]'
        if not isinstance(row, list) or len(row) != 5:
            raise reader.fail(where, 'expected [position, lower time, upper time, lower speed, '
                              f'upper speed], got {row!r}')
        if row[0] is None:
            raise reader.fail(f'{where}[0]', 'the position is required')
        position, t_low, t_high, v_low, v_high = (
            None if v is None else convert(reader.number(v, f'{where}[{j}] ({name})',
                                                         minimum=0.0))
            for j, (v, convert, name) in enumerate(zip(row, converters, names)))
        if t_low is not None and t_high is not None and t_low > t_high:
            raise reader.fail(where, f'lower time {t_low:g} s is after upper time {t_high:g} s')
        if v_low is not None and v_high is not None and v_low > v_high:
            raise reader.fail(where, f'lower speed {v_low:g} m/s is above upper speed '
                              f'{v_high:g} m/s')
        assert position is not None  # checked above
        points.append(TimingPoint(position, t_low, t_high, v_low, v_high))
    for i, (a, b) in enumerate(zip(points, points[1:])):
        if b.position_m < a.position_m:
            raise reader.fail(f'timing points[{i + 1}]', 'positions must not decrease')
        if b.position_m == a.position_m and not (a.is_stopping_point and b.is_stopping_point):
            raise reader.fail(f'timing points[{i + 1}]', 'equal positions are only allowed for '
                              'the arrival and departure stopping points of a station')
    for i in (0, len(points) - 1):
        if not points[i].is_stopping_point:
            raise reader.fail(f'timing points[{i}]', 'the first and last timing points must be '
                              'stopping points (both speed bounds 0)')
    return TTOBenchJourney(identifier, track_id, tuple(points))


def apply_journey(track: TTOBenchTrack, journey: TTOBenchJourney, journey_path: str) -> Line:
    """The track's line with the journey's stations and passing-point speed bounds."""
    line = track.line
    if journey.track_id != track.id:
        raise ConfigError(f'{journey_path}: metadata.associated track: the journey is for track '
                          f'{journey.track_id!r}, the scenario names track {track.id!r}')
    stations = journey.stations()
    for station in stations:
        if station.position_m > line.length_m:
            raise ConfigError(f'{journey_path}: timing points: stopping point at '
                              f'{station.position_m:g} m is beyond the end of track {track.id} '
                              f'({line.length_m:g} m)')
    limits = line.speed_limit_mps
    for position, bound in journey.passing_speed_bounds():
        limits = restrict(limits, position, position + PASSING_POINT_RESTRICTION_M, bound,
                          line.length_m)
    return Line(line.name, line.length_m, stations, limits, line.grade_sine, line.curves,
                line.tunnels)


def restrict(limits: PiecewiseConstant, start: float, end: float, speed: float,
             length: float) -> PiecewiseConstant:
    """``limits`` lowered to at most ``speed`` on [start, end)."""
    cuts = sorted({s for s in limits.starts} | {start, min(end, length)} - {length})
    values = [min(limits(x), speed) if start <= x < end else limits(x) for x in cuts]
    starts: list[float] = []
    merged: list[float] = []
    for x, v in zip(cuts, values):
        if not merged or v != merged[-1]:
            starts.append(x)
            merged.append(v)
    return PiecewiseConstant(starts, merged)


def scenario_data(track: str | Path, train: str | Path, journey: str | Path | None = None,
                  dwell_s: float = 30.0) -> dict:
    """A scenario (the mapping :func:`ato_common.scenario.parse_scenario` reads) running a
    TTOBench track with a TTOBench train. The planning limits are starting values for the user
    to edit: the train's comfort acceleration where it gives one, else 0.5 m/s^2; 70 % of the
    lower of its comfort and (lowest) service deceleration, so that the supervision's service
    curve stays above the plan; jerk 0.5 m/s^3; margin 2 km/h."""
    loaded = load_train(train)
    service = loaded.parameters.traction.max_service_brake_force_n / loaded.parameters.mass_kg
    if loaded.braking is not None:
        service = min(d for _, d in loaded.braking.service)
    deceleration = 0.7 * min(loaded.max_deceleration_mps2 or service, service)
    data = {
        'name': f'{Path(track).stem}__{Path(train).stem}',
        'description': f'TTOBench track {Path(track).name} with train {Path(train).name}',
        'source': 'TTOBench (Kouzoupis, Pendharkar & Corman 2023, BSD-2)',
        'train': {'ttobench': str(train)},
        'line': {'ttobench': str(track), 'dwell_s': dwell_s},
        'planning': {'max_acceleration_mps2': round(min(loaded.max_acceleration_mps2 or 0.5,
                                                        2.0), 3),
                     'service_deceleration_mps2': round(min(deceleration, 2.0), 3),
                     'max_jerk_mps3': 0.5, 'speed_margin_kmh': 2.0},
    }
    if journey is not None:
        data['journey'] = {'ttobench': str(journey)}
    return data

