"""Line description: stations, static speed limits, gradients, curves and tunnels, in SI.

One schema, one loader, shared by the plant (line forces at each car's position) and the profile
(speed limits and stations). Piecewise quantities are given by their start position and hold
until the next entry starts.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass

from ato_common import units
from ato_common.validation import ConfigError, Fields

CURVE_RESISTANCE_N_PER_KN_M = 600.0        # w_c = 600 / R  [N/kN], R in m
TUNNEL_RESISTANCE_N_PER_KN_PER_M = 0.00013  # w_t = 0.00013 L_t  [N/kN], L_t in m
# The steepest gradient a file may give, per mille (either sign): steeper than any line worked
# by adhesion. The steepest in service is a Lisbon tramway's (Calcada de Sao Francisco, about
# 138 per mille, with every axle powered); main lines stay under 80 per mille (Uetlibergbahn
# 79) and high-speed lines under 40 (the list of the steepest gradients on adhesion railways,
# e.g. Wikipedia's). A steeper grade is a rack or cable railway, or a wrong figure or unit.
MAX_GRADIENT_PER_MILLE = 140.0
# The default placement of balise groups on a line that declares none (``default_balise_groups``):
# precise-stopping groups this far before each stopping point, m. An ATO stops to within half a
# metre only if its position is corrected close to the stop (platform doors need it): metro
# lines put several balises over the stopping stage, the last at the stopping point (Beijing's
# Yizhuang line has five); the suite puts one where the final braking begins and one at the
# platform, after which the odometry's interval is 5 m + 5 % of 20 m (SUBSET-041 5.3.1.1) ...
BALISE_GROUPS_BEFORE_STOP_M = (200.0, 20.0)
# ... and groups spread evenly between them, none further than this apart, m: ETCS level 2
# lines put a balise group at each block marker board, every 1-2 km on high-speed lines, so
# that the odometry's interval (5 % of the distance since the last group) stays under 80 m.
BALISE_GROUP_SPACING_M = 1500.0
# ... on a line of at most this length, m (the longest high-speed line, Beijing-Hong Kong, is
# under 2,500 km): a longer one declares its groups (or none) rather than get thousands
DEFAULT_BALISE_LINE_MAX_M = 5.0e6


@dataclass(frozen=True)
class Station:
    name: str
    position_m: float
    dwell_s: float


@dataclass(frozen=True)
class Curve:
    """A curve of constant radius, or, with ``end_radius_m``, a transition (clothoid) whose
    curvature 1/R varies linearly from 1/radius_m to 1/end_radius_m (inf: straight). Radii are
    signed as TTOBench signs them: positive a right-hand curve, negative a left-hand one
    (in the running direction); a transition from one to the other passes through straight.
    The resistance takes the magnitude of the curvature."""

    start_m: float
    length_m: float
    radius_m: float
    end_radius_m: float | None = None

    def curvature_at(self, position: float) -> float:
        """1/R at a position inside the curve (signed as the radii), 1/m."""
        start = 1.0 / self.radius_m
        if self.end_radius_m is None:
            return start
        share = (position - self.start_m) / self.length_m
        return start + share * (1.0 / self.end_radius_m - start)


def signed_curves(start_m: float, length_m: float, radius_m: float,
                  end_radius_m: float | None = None) -> tuple[Curve, ...]:
    """A curve as ``Curve``s whose curvature keeps one sign: a transition from a right-hand
    to a left-hand radius (or back) is cut where it passes through straight, so that the
    resistance (the magnitude of the curvature) stays linear in position along each."""
    if end_radius_m is None or (radius_m > 0.0) == (end_radius_m > 0.0):
        return (Curve(start_m, length_m, radius_m, end_radius_m),)
    first, last = 1.0 / radius_m, 1.0 / end_radius_m
    straight = length_m * first / (first - last)
    return (Curve(start_m, straight, radius_m, math.copysign(math.inf, radius_m)),
            Curve(start_m + straight, length_m - straight, math.copysign(math.inf, end_radius_m),
                  end_radius_m))


@dataclass(frozen=True)
class Tunnel:
    start_m: float
    length_m: float
    cross_section_m2: float | None = None  # TTOBench tunnels give it (train-specific drag)


class PiecewiseConstant:
    """value(s) = values[i] for starts[i] <= s < starts[i+1]; before the first start: values[0]."""

    def __init__(self, starts: list[float], values: list[float]):
        self.starts = list(starts)
        self.values = list(values)

    def __call__(self, position: float) -> float:
        i = bisect_right(self.starts, position) - 1
        return self.values[max(i, 0)]

    def segments(self, end: float) -> list[tuple[float, float, float]]:
        """[(start, end, value)] up to ``end``."""
        bounds = self.starts[1:] + [end]
        return [(s, min(e, end), v) for s, e, v in zip(self.starts, bounds, self.values) if s < end]


@dataclass(frozen=True)
class Line:
    name: str
    length_m: float
    stations: tuple[Station, ...]
    speed_limit_mps: PiecewiseConstant
    grade_sine: PiecewiseConstant      # sin(track angle), positive uphill in the running direction
    curves: tuple[Curve, ...] = ()
    tunnels: tuple[Tunnel, ...] = ()
    #: where the line's balise groups lie, m, increasing: the fixed points at which an on-board
    #: odometry relocates the train (SUBSET-026 3.6.4, the last relevant balise group)
    balise_groups_m: tuple[float, ...] = ()

    def line_force_per_kg(self, position: float, gravity: float = units.STANDARD_GRAVITY) -> float:
        """Specific force of the line opposing motion at a position, m/s^2 (negative downhill).

        Grade: g sin(theta). Curve: 600/R N/kN, tunnel without limiting gradient: 0.00013 L_t
        N/kN (the Chinese traction-calculation rules, as reconstructed for Liu & Li eqs 3-4).
        A transition curve uses its local curvature in 600/R.
        """
        per_kn = 0.0
        for curve in self.curves:
            if curve.start_m <= position < curve.start_m + curve.length_m:
                per_kn += CURVE_RESISTANCE_N_PER_KN_M * abs(curve.curvature_at(position))
        for tunnel in self.tunnels:
            if tunnel.start_m <= position < tunnel.start_m + tunnel.length_m:
                per_kn += TUNNEL_RESISTANCE_N_PER_KN_PER_M * tunnel.length_m
        return gravity * (self.grade_sine(position) + per_kn / 1000.0)


def _ascending(starts: list[float], where: str) -> None:
    for previous, current in zip(starts, starts[1:]):
        if current <= previous:
            raise ConfigError(f'{where}: start_m must increase, got {previous:g} then {current:g}')


def _radius(item: Fields, key: str) -> float:
    """A signed curve radius (``Curve``): any number but 0."""
    radius = item.number(key)
    if radius == 0.0:
        raise ConfigError(f'{item.where}.{key}: a radius of 0 m is not a curve (the sign gives '
                          'the direction: positive right, negative left)')
    return radius


def _balise_groups(f: Fields, length: float, where: str) -> tuple[float, ...]:
    """``balise_groups: [{position_m: ...}, ...]``: on the line, strictly increasing."""
    positions: list[float] = []
    for item in f.items('balise_groups'):
        position = item.number('position_m', minimum=0.0, maximum=length)
        item.reject_unknown()
        if positions and position <= positions[-1]:
            raise ConfigError(f'{item.where}.position_m: positions must increase, got '
                              f'{positions[-1]:g} then {position:g}')
        positions.append(position)
    return tuple(positions)


def default_balise_groups(line: Line) -> tuple[float, ...]:
    """Where an ETCS designer would put the balise groups of a line that declares none: one
    each ``BALISE_GROUPS_BEFORE_STOP_M`` before each stopping point after the first station
    (none behind the station before it), and between the line's start, these groups and
    the line's end, evenly spread groups no more than ``BALISE_GROUP_SPACING_M`` apart. No
    group at the line's ends: the first lies ahead of the train at its start, so a wrong start
    position is corrected once the train has run at most one spacing. ConfigError for a line
    longer than ``DEFAULT_BALISE_LINE_MAX_M``."""
    if line.length_m > DEFAULT_BALISE_LINE_MAX_M:
        raise ConfigError(f'line.balise_groups: a line of {line.length_m:g} m (longer than '
                          f'{DEFAULT_BALISE_LINE_MAX_M:g} m) gets no default placement of balise '
                          'groups: declare them (balise_groups: [] for none)')
    anchors = {0.0, line.length_m}
    positions = [s.position_m for s in line.stations]
    for previous, stop in zip(positions, positions[1:]):
        anchors.update(max(stop - d, previous) for d in BALISE_GROUPS_BEFORE_STOP_M)
    ordered = sorted(anchors)
    groups = set(ordered[1:-1])
    for a, b in zip(ordered, ordered[1:]):
        count = math.ceil((b - a) / BALISE_GROUP_SPACING_M - 1e-9)
        groups.update(a + (b - a) * k / count for k in range(1, count))
    return tuple(sorted(x for x in groups if 0.0 < x < line.length_m))


def parse_line(data, where: str = 'line') -> Line:
    f = Fields(data, where)
    name = f.text('name')
    length = f.number('length_m', minimum=0.0, exclusive_minimum=True)

    stations = []
    for item in f.items('stations', required=True):
        position = item.number('position_m', minimum=0.0, maximum=length)
        dwell_s = item.number('dwell_s', 0.0, minimum=0.0)
        stations.append(Station(item.text('name'), position, dwell_s))
        item.reject_unknown()
    if len(stations) < 2:
        raise ConfigError(f'{where}.stations: at least two stations (origin and destination) '
                          'are needed')
    for a, b in zip(stations, stations[1:]):
        if b.position_m <= a.position_m:
            raise ConfigError(f'{where}.stations: positions must increase ({a.name} at '
                              f'{a.position_m:g} m, then {b.name} at {b.position_m:g} m)')

    limit_starts, limits = [], []
    for item in f.items('speed_limits', required=True):
        limit_starts.append(item.number('start_m', minimum=0.0, maximum=length))
        speed_kmh = item.number('speed_kmh', minimum=0.0, exclusive_minimum=True)
        limits.append(units.kmh_to_mps(speed_kmh))
        item.reject_unknown()
    if not limits:
        raise ConfigError(f'{where}.speed_limits: at least one speed limit is needed')
    _ascending(limit_starts, f'{where}.speed_limits')
    if limit_starts[0] != 0.0:
        raise ConfigError(f'{where}.speed_limits[0].start_m: the first limit must start at 0 m')

    grade_starts, grades = [], []
    for item in f.items('gradients'):
        grade_starts.append(item.number('start_m', minimum=0.0, maximum=length))
        grades.append(units.per_mille_to_sine(item.number(
            'per_mille', minimum=-MAX_GRADIENT_PER_MILLE, maximum=MAX_GRADIENT_PER_MILLE)))
        item.reject_unknown()
    if not grade_starts or grade_starts[0] > 0.0:  # level until the first given grade
        grade_starts.insert(0, 0.0)
        grades.insert(0, 0.0)
    _ascending(grade_starts, f'{where}.gradients')

    curves: list[Curve] = []
    for item in f.items('curves'):
        start = item.number('start_m', minimum=0.0, maximum=length)
        curve_length = item.number('length_m', minimum=0.0, exclusive_minimum=True)
        radius = _radius(item, 'radius_m')
        end_radius = _radius(item, 'end_radius_m') if item.has('end_radius_m') else None
        curves.extend(signed_curves(start, curve_length, radius, end_radius))
        item.reject_unknown()
    tunnels = []
    for item in f.items('tunnels'):
        start = item.number('start_m', minimum=0.0, maximum=length)
        tunnel_length = item.number('length_m', minimum=0.0, exclusive_minimum=True)
        if start + tunnel_length > length:
            raise ConfigError(f'{item.where}.length_m: the tunnel ends at '
                              f'{start + tunnel_length:g} m, past the end of the line '
                              f'({length:g} m)')
        section = (item.number('cross_section_m2', minimum=0.0, exclusive_minimum=True)
                   if item.has('cross_section_m2') else None)
        tunnels.append(Tunnel(start, tunnel_length, section))
        item.reject_unknown()
    balise_groups = _balise_groups(f, length, where)
    f.reject_unknown()
    return Line(name, length, tuple(stations), PiecewiseConstant(limit_starts, limits),
                PiecewiseConstant(grade_starts, grades), tuple(curves), tuple(tunnels),
                balise_groups)
