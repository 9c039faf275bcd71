"""Speed supervision of a movement authority: the most restrictive speed profile and the braking
curves to its targets, organised as ETCS names them (SUBSET-026 section 3.13), simplified.

What is modelled (all in SI, positions along the line, the front of the train):

* MRSP, the most restrictive speed profile: the static speed limits, where a higher limit takes
  effect only once the whole train (its length) has left the lower one (SUBSET-026 3.13.7).
* Targets: the start of every lower MRSP section (a speed target), and the end of the movement
  authority (EOA, a zero-speed target) with its supervised location SvL = EOA + overlap.
* EBD, the emergency brake deceleration curve: from the EOA (speed 0; see the deviation below) or
  from a speed target at V_target + dV_ebi(V_target) (3.13.8.3), integrated backwards with the
  train's emergency deceleration plus the gradient (g sin(theta), uphill helps, downhill
  hinders; 3.13.4).
* SBD, the service brake deceleration curve: from the EOA or the speed target, with the service
  deceleration plus the gradient (3.13.8.4).
* Curves derived from them by shifting each point earlier by the distance run at that speed
  during a time (3.13.9.3): EBI = EBD shifted by the traction cut-off and emergency brake
  build-up times; SBI = SBD shifted by the service brake build-up time (and never above EBI);
  warning = SBI shifted by T_warning; permitted = SBI shifted by T_driver; indication =
  permitted shifted by T_indication.
* Ceiling supervision (3.13.9.2): warning, SBI and EBI sit dV_warning, dV_sbi and dV_ebi above
  the MRSP, each dV interpolated linearly in the MRSP speed between its two ETCS default values.

Simplified against SUBSET-026: the gradient is the one at the front of the train (not the
lowest under the whole train); no speed-dependent brake build-up, no correction factors Kdry/Kwet
or Kv/Kr/Kt (the deceleration tables are taken as already corrected), no guidance curve (the
odometry's confidence interval and speed accuracy are the plant's ATP's, which looks these
curves up at the max safe front end). ``permitted_speed(position)`` is the minimum of the MRSP
and the permitted curves of every target: the speed an ATO target must stay below.

Deviation from SUBSET-026, on the safe side: the EBD of a zero-speed target ends at the EOA,
not at the SvL (3.13.8.3). An emergency brake triggered on the EBI therefore stops the train
before the EOA, whatever the ATO commands and whatever fault a traction drive has; the overlap
from the EOA to the SvL is never used by the supervision and is left as the margin for a brake
that performs below its nominal data (a wet rail, a late build-up).

Release speed (3.13.9.4, simplified): towards a zero-speed target (a stop, the end of the
authority) the EBI, SBI, warning, permitted and indication curves are floored at the release
speed V_release up to the stopping point, follow their curve from there to the EOA and are zero
beyond it (passing the EOA trips the emergency brake). V_release is the EBI's speed at the
stopping point (from it, an emergency brake triggered at the stopping point stops the train
before the EOA), at most ``release_speed_max_mps``.

Stops (:class:`RunSupervision`): the authority of a leg ends at its stop; it moves on to the
next leg only once the train has stood still at the stop (from ``STOP_WINDOW_M`` before the
stopping point to the SvL) without a break for the station's dwell time. Until then the braking
curves to the stop, its EOA and its SvL are supervised, wherever the train is.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ato_common import units
from ato_common.identity import Undescribable, content_key
from ato_common.line import Line, PiecewiseConstant

# ETCS default ceiling-supervision margins (SUBSET-026 A.3.1): dV at and below V_min, at and
# above V_max, linear in between.
DV_EBI_KMH = (7.5, 15.0)
DV_SBI_KMH = (5.5, 10.0)
DV_WARNING_KMH = (4.0, 5.0)
DV_SPEEDS_KMH = (110.0, 210.0)
#: the limits with a ceiling: their dV over the MRSP (None: the MRSP itself); the EBD and SBD
#: have none
CEILING_DV_KMH: dict[str, tuple[float, float] | None] = {
    'ebi': DV_EBI_KMH, 'sbi': DV_SBI_KMH, 'warning': DV_WARNING_KMH, 'permitted': None,
    'indication': None}

# Integration step of the deceleration curves (m) and the speed up to which they are drawn.
CURVE_STEP_M = 2.0
CURVE_HEADROOM_MPS = 10.0

# Distance before a step of a limit at which a sampled limit takes its second sample, m.
SAMPLE_EDGE_M = 1e-3

CURVE_NAMES = ('ebd', 'ebi', 'sbd', 'sbi', 'warning', 'permitted', 'indication')


@dataclass(frozen=True)
class SupervisionSettings:
    """The train's braking capability and the supervision's times and distances."""

    emergency_deceleration: Callable[[float], float]  # A_brake_emergency(v) on level track
    service_deceleration: Callable[[float], float]    # A_brake_service(v) on level track
    traction_cut_off_s: float = 1.0       # T_traction
    emergency_brake_build_up_s: float = 2.0  # T_be
    service_brake_build_up_s: float = 2.0    # T_bs
    warning_s: float = 2.0                # T_warning
    driver_reaction_s: float = 4.0        # T_driver
    indication_s: float = 4.0             # T_indication
    eoa_beyond_stop_m: float = 50.0       # stopping point -> end of authority
    overlap_m: float = 50.0               # EOA -> supervised location
    release_speed_max_mps: float = 40.0 / 3.6  # the highest release speed (V_release)
    # The on-board odometry's declared accuracy (SUBSET-026 3.6.4, SUBSET-041 5.3.1): its
    # confidence interval is location_accuracy_m + odometry_accuracy times the distance run
    # since the last relevant balise group, on each side of the estimated front end; the
    # speed's is speed_accuracy_mps + speed_accuracy_share times the estimated speed. Zero
    # (the default): the odometry declares itself exact.
    # The train's highest acceleration by its own traction on level track (its starting effort
    # over its mass), train data the ATP anticipates a control cycle with (0: none given).
    traction_acceleration_mps2: float = 0.0
    location_accuracy_m: float = 0.0
    odometry_accuracy: float = 0.0
    speed_accuracy_mps: float = 0.0
    speed_accuracy_share: float = 0.0


def constant_deceleration(value: float) -> Callable[[float], float]:
    return lambda speed: value


def tabulated_deceleration(speeds: Sequence[float], decelerations: Sequence[float]
                           ) -> Callable[[float], float]:
    """A deceleration table by speed (TTOBench A_brake_*): stepwise, each value holding from its
    speed up to the next one, as ETCS brake tables are."""
    speeds, values = list(speeds), list(decelerations)
    return lambda speed: values[max(bisect_right(speeds, speed) - 1, 0)]


def ceiling_margin(limit_mps: float, margins_kmh: tuple[float, float]) -> float:
    """dV(V_MRSP) of SUBSET-026 3.13.9.2.3: margins_kmh at V_min and V_max, linear between."""
    v_kmh = units.mps_to_kmh(limit_mps)
    (low, high), (v_low, v_high) = margins_kmh, DV_SPEEDS_KMH
    share = min(max((v_kmh - v_low) / (v_high - v_low), 0.0), 1.0)
    return units.kmh_to_mps(low + share * (high - low))


def tail_clear_position(end_m: float, train_length_m: float) -> float:
    """The first position (a float) of the front at which the tail has left a section ending at
    ``end_m``: the smallest float x with x - train_length_m >= end_m in exact arithmetic.

    ``end_m + train_length_m`` rounded to nearest can fall one unit in the last place short of
    the exact sum; the front there still has its tail (x - L, exactly) inside the section. The
    rounding error of the sum is found exactly (Knuth's TwoSum) and the sum rounded up when it
    fell short, so no tolerance is involved."""
    total = end_m + train_length_m
    if not math.isfinite(total):
        return total
    length_part = total - end_m
    end_part = total - length_part
    error = (end_m - end_part) + (train_length_m - length_part)
    return math.nextafter(total, math.inf) if error > 0.0 else total


def most_restrictive_speed_profile(limits: PiecewiseConstant, end_m: float,
                                   train_length_m: float) -> PiecewiseConstant:
    """MRSP(x) = the lowest static limit over [x - train length, x]: a decrease applies at its
    start, an increase once the train's tail has passed it.

    A section [s, e) restricts a front position x when s <= x and x - L < e, exactly (the
    positions taken as the floats they are); ``tail_clear_position`` gives the float where the
    second condition ends, so the comparison is exact and no breakpoint is lost to rounding."""
    sections = [(s, e, v, tail_clear_position(e, train_length_m))
                for s, e, v in limits.segments(end_m)]
    candidates = sorted({s for s, _, _, _ in sections}
                        | {min(clear, end_m) for _, _, _, clear in sections} - {end_m})
    starts: list[float] = []
    values: list[float] = []
    for x in candidates:
        value = min(v for s, _, v, clear in sections if s <= x < clear)
        if not values or value != values[-1]:
            starts.append(x)
            values.append(value)
    return PiecewiseConstant(starts, values)


@dataclass(frozen=True)
class Target:
    """A place where the train must be at or below a speed. ``kind`` is 'speed_decrease',
    'stop' (an intermediate station stop, ending the leg's authority) or 'end_of_authority'."""

    kind: str
    location_m: float      # where the speed must be reached (the stopping point for a stop)
    speed_mps: float
    name: str = ''


def interpolate(x: float, xs: list[float], ys: list[float]) -> float:
    """``np.interp(x, xs, ys)`` for one ``x`` within ``[xs[0], xs[-1]]`` (``xs`` increasing), bit
    for bit: the same interval (the last sample at or before ``x``), the sample itself where
    ``x`` is one, else ``slope * (x - xs[j]) + ys[j]`` with numpy's slope and its fallbacks for
    a NaN (an infinite slope). A supervision evaluates its curves at one position every
    control period; numpy's call costs more to set up than the search and the line."""
    j = bisect_right(xs, x) - 1
    if j >= len(xs) - 1:
        return ys[-1]
    if j < 0:
        return ys[0]
    if x == xs[j]:
        return ys[j]
    slope = (ys[j + 1] - ys[j]) / (xs[j + 1] - xs[j])
    value = slope * (x - xs[j]) + ys[j]
    if value != value:  # NaN: as numpy, from the other end, then the equal samples
        value = slope * (x - xs[j + 1]) + ys[j + 1]
        if value != value and ys[j] == ys[j + 1]:
            value = ys[j]
    return value


class DecelerationCurve:
    """Speed against position, sampled, increasing speed towards smaller positions. Between its
    last sample and the target location it holds its final speed (a shifted curve reaches the
    target speed before the target); a zero-speed curve holds zero beyond."""

    def __init__(self, positions: np.ndarray, speeds: np.ndarray, target_m: float):
        order = np.argsort(positions)
        self.positions = positions[order]
        self.speeds = speeds[order]
        self.start_m = float(self.positions[0])
        self.end_m = float(self.positions[-1])
        self.end_speed = float(self.speeds[-1])
        self.target_m = target_m
        # the samples as Python floats, for one position at a time (``interpolate``)
        self._positions: list[float] = self.positions.tolist()
        self._speeds: list[float] = self.speeds.tolist()

    def __call__(self, position: float) -> float:
        """The curve's speed; infinite where it does not restrict (before its start, after
        a speed target)."""
        if position < self.start_m:
            return math.inf
        if position > self.end_m:
            if position <= self.target_m or self.end_speed == 0.0:
                return self.end_speed
            return math.inf
        return interpolate(float(position), self._positions, self._speeds)

    def at(self, positions: np.ndarray) -> np.ndarray:
        """The curve's speed at every position of an array (the rules of ``__call__``)."""
        speeds = np.interp(positions, self.positions, self.speeds)
        beyond = np.where((positions <= self.target_m) | (self.end_speed == 0.0),
                          self.end_speed, math.inf)
        speeds = np.where(positions > self.end_m, beyond, speeds)
        return np.where(positions < self.start_m, math.inf, speeds)

    def edges(self) -> tuple[float, ...]:
        """The positions where the curve has a kink or a step."""
        return self.start_m, self.end_m, self.target_m

    def span(self) -> tuple[float, float]:
        """(first, last): the positions between which the curve restricts; infinite outside
        (the rules of ``__call__``: from its start; beyond its end, up to the target, or for
        good if its final speed is zero)."""
        return self.start_m, math.inf if self.end_speed == 0.0 else max(self.end_m,
                                                                         self.target_m)

    def shifted(self, time_s: float) -> 'DecelerationCurve':
        """The curve a train must be on ``time_s`` earlier (SUBSET-026 3.13.9.3: each point moves
        back by the distance run at its speed in that time)."""
        return DecelerationCurve(self.positions - self.speeds * time_s, self.speeds.copy(),
                                 self.target_m)


def deceleration_curve(line: Line, location_m: float, speed_mps: float, top_speed_mps: float,
                       deceleration: Callable[[float], float]) -> DecelerationCurve:
    """Backwards from (location, speed): d(v^2)/dx = -2 (A(v) + g sin(theta(x))), up to
    ``top_speed_mps`` or the start of the line. The gradient term is the line's grade only."""
    positions, squares = [location_m], [speed_mps * speed_mps]
    x, y = location_m, speed_mps * speed_mps
    top = top_speed_mps * top_speed_mps
    while x > 0.0 and y < top:
        step = min(CURVE_STEP_M, x)
        # Stop the step at a gradient change so each step sees one gradient.
        grade_index = bisect_right(line.grade_sine.starts, x - 1e-9) - 1
        if grade_index >= 0 and x - line.grade_sine.starts[grade_index] > 1e-9:
            step = min(step, x - line.grade_sine.starts[grade_index])
        sine = line.grade_sine(x - 0.5 * step)

        def slope(square: float) -> float:
            return 2.0 * (deceleration(math.sqrt(max(square, 0.0)))
                          + units.STANDARD_GRAVITY * sine)
        middle = max(y + 0.5 * step * slope(y), 0.0)
        # Where the brake cannot even hold the speed on a descent, the curve falls backwards:
        # the train must come to it slower still (down to standstill).
        x, y = x - step, max(y + step * slope(middle), 0.0)
        positions.append(x)
        squares.append(y)
    return DecelerationCurve(np.array(positions), np.sqrt(np.array(squares)), location_m)


class ReleasedCurve:
    """A supervision curve to a zero-speed target with its release speed: the curve, floored at
    ``release_mps`` before the stopping point, the curve itself from there to the EOA, and zero
    from the EOA on (see the module's docstring). It has a kink where the curve meets the release
    speed (``end_m``), a step at the stopping point (``release_end_m``) for the curves below the
    EBI there, and a step at the EOA (``target_m``), all sampled by
    :meth:`SpeedSupervision.sampled`."""

    def __init__(self, curve: DecelerationCurve, release_mps: float, release_end_m: float,
                 eoa_m: float):
        self.curve = curve
        self.release_mps = release_mps
        self.positions = curve.positions
        self.start_m = curve.start_m
        # Where the curve comes down to the release speed (its speeds fall with position).
        self.end_m = float(np.interp(release_mps, curve.speeds[::-1], curve.positions[::-1]))
        self.release_end_m = release_end_m
        self.target_m = eoa_m

    def edges(self) -> tuple[float, ...]:
        """The positions where the curve has a kink or a step."""
        return self.start_m, self.end_m, self.release_end_m, self.target_m

    def span(self) -> tuple[float, float]:
        """As :meth:`DecelerationCurve.span`: the curve's own, and zero from the EOA on."""
        return min(self.curve.span()[0], self.target_m), math.inf

    def __call__(self, position: float) -> float:
        if position >= self.target_m:
            return 0.0
        if position >= self.release_end_m:
            return self.curve(position)
        return max(self.curve(position), self.release_mps)

    def at(self, positions: np.ndarray) -> np.ndarray:
        speeds = self.curve.at(positions)
        floored = np.where(positions >= self.release_end_m, speeds,
                           np.maximum(speeds, self.release_mps))
        return np.where(positions >= self.target_m, 0.0, floored)


class SpeedSupervision:
    """The supervision of one movement authority: MRSP, targets, the braking curves of each."""

    def __init__(self, line: Line, settings: SupervisionSettings, train_length_m: float,
                 start_m: float, stopping_point_m: float, final: bool = True,
                 stop_name: str = '', max_speed_mps: float = math.inf):
        self.settings = settings
        self.start_m = start_m
        mrsp = most_restrictive_speed_profile(line.speed_limit_mps, line.length_m,
                                              train_length_m)
        # The train's design maximum speed bounds every limit (the ceiling of SUBSET-026 3.11).
        self.max_speed_mps = max_speed_mps
        self.mrsp = PiecewiseConstant(mrsp.starts, [min(v, max_speed_mps) for v in mrsp.values])
        self.stopping_point_m = stopping_point_m
        # The authority ends beyond the stopping point (platform end, overrun), also at the
        # last station of a line: the track does not end where the line description does.
        eoa = stopping_point_m + settings.eoa_beyond_stop_m
        self.end_of_authority_m = eoa
        self.supervised_location_m = eoa + settings.overlap_m
        kind = 'end_of_authority' if final else 'stop'
        self.targets: list[Target] = []
        previous = None
        for s, _end, v in self.mrsp.segments(line.length_m):
            if previous is not None and v < previous and start_m < s < stopping_point_m:
                self.targets.append(Target('speed_decrease', s, v))
            previous = v
        self.targets.append(Target(kind, stopping_point_m, 0.0, stop_name))
        top = max(self.mrsp.values) + units.kmh_to_mps(DV_EBI_KMH[1]) + CURVE_HEADROOM_MPS
        self.curves: dict[str, list] = {name: [] for name in CURVE_NAMES}
        self.release_speed_mps = 0.0
        self._sampled: dict[str, SampledLimit] = {}
        self._restricting: dict[str, tuple[list[float], list[tuple[tuple, float]]]] = {}
        for target in self.targets:
            if target.kind == 'speed_decrease':
                ebd_from = (target.location_m,
                            target.speed_mps + ceiling_margin(target.speed_mps, DV_EBI_KMH))
                sbd_from = (target.location_m, target.speed_mps)
            else:
                ebd_from = (eoa, 0.0)  # not the SvL: the deviation of the module's docstring
                sbd_from = (eoa, 0.0)
            ebd = deceleration_curve(line, *ebd_from, top, settings.emergency_deceleration)
            sbd = deceleration_curve(line, *sbd_from, top, settings.service_deceleration)
            ebi = ebd.shifted(settings.traction_cut_off_s + settings.emergency_brake_build_up_s)
            sbi = sbd.shifted(settings.service_brake_build_up_s)
            permitted = sbi.shifted(settings.driver_reaction_s)
            plain = {'ebd': ebd, 'ebi': ebi, 'sbd': sbd, 'sbi': sbi,
                     'warning': sbi.shifted(settings.warning_s), 'permitted': permitted,
                     'indication': permitted.shifted(settings.indication_s)}
            curves: dict[str, DecelerationCurve | ReleasedCurve] = dict(plain)
            if target.kind != 'speed_decrease':
                self.release_speed_mps = max(min(settings.release_speed_max_mps,
                                                 ebi(stopping_point_m)), 0.0)
                for name in ('ebi', 'sbi', 'warning', 'permitted', 'indication'):
                    curves[name] = ReleasedCurve(plain[name], self.release_speed_mps,
                                                 stopping_point_m, eoa)
            for name in CURVE_NAMES:
                self.curves[name].append(curves[name])

    def curve(self, name: str, position_m: float) -> float:
        """The named supervision limit at a position: the lowest of its curves and of the
        ceiling (the MRSP plus the name's dV; the EBD and SBD have no ceiling). Only the
        curves that restrict near the position are asked, and the ceiling is read from a
        table (:meth:`restricting`): the same values, bit for bit."""
        if position_m == position_m:
            bounds, near = self._restricting.get(name) or self.restricting(name)
            curves, ceiling = near[bisect_right(bounds, position_m)]
        else:  # NaN: every curve, as they answer it
            curves, ceiling = tuple(self.curves[name]), self.ceiling_at(name, position_m)
        # the lowest of the curves' values, as min() of them in their order would give it; most
        # positions have none or one curve near (a generator for those would cost more than
        # the look-up)
        if not curves:
            lowest = math.inf
        elif len(curves) == 1:
            lowest = curves[0](position_m)
        else:
            lowest = min([c(position_m) for c in curves])
        if name == 'sbi':
            lowest = min(lowest, self.curve('ebi', position_m))
        if position_m > self.supervised_location_m:
            return 0.0
        return max(min(lowest, ceiling), 0.0)

    def restricting(self, name: str) -> tuple[list[float], list[tuple[tuple, float]]]:
        """(bounds, near): the ends of the spans of the named curves and the starts of the MRSP's
        sections, sorted, and for each interval between two of them (``near[bisect_right(bounds,
        x)]`` for a position x) the curves whose span meets it, in their order, and the ceiling
        there (``ceiling_at``, the same in the whole interval). Built on first use and kept: a
        supervision asks a limit at one position every control period, and most curves (the
        targets far ahead or behind) are infinite there."""
        curves = self.curves[name]
        spans = [c.span() for c in curves]
        bounds = sorted({x for span in spans for x in span if math.isfinite(x)}
                        | set(self.mrsp.starts))
        edges = [-math.inf] + bounds + [math.inf]
        near = [(tuple(c for c, (first, last) in zip(curves, spans) if first <= b and last >= a),
                 self.ceiling_at(name, a)) for a, b in zip(edges, edges[1:])]
        self._restricting[name] = bounds, near
        return bounds, near

    def ceiling_at(self, name: str, position_m: float) -> float:
        """The ceiling of a named limit at a position: the MRSP plus the name's dV (``ebi``,
        ``sbi``, ``warning``), the MRSP itself (``permitted``, ``indication``), none (inf) for
        the EBD and SBD."""
        if name not in CEILING_DV_KMH:
            return math.inf
        mrsp = self.mrsp(position_m)
        dv = CEILING_DV_KMH[name]
        return mrsp + ceiling_margin(mrsp, dv) if dv else mrsp

    def binding_target(self, position_m: float) -> Target | None:
        """The target whose permitted curve is the permitted speed at a position (None where
        the MRSP is)."""
        speeds = [c(position_m) for c in self.curves['permitted']]
        lowest = min(range(len(speeds)), key=speeds.__getitem__)
        return self.targets[lowest] if speeds[lowest] < self.mrsp(position_m) else None

    def ceiling(self, name: str) -> tuple[list[float], list[float]]:
        """The ceiling of a named limit section by section, (starts, speeds): the MRSP plus
        the name's dV (``ebi``, ``sbi``, ``warning``), the MRSP itself (``permitted``,
        ``indication``). A train whose front may lie anywhere in an interval is bound by the
        lowest ceiling over it (SUBSET-026 3.6.4: the max safe front end for the start of a
        restriction, the min safe front end for its end)."""
        dv = CEILING_DV_KMH.get(name)
        return (list(self.mrsp.starts),
                [v + (ceiling_margin(v, dv) if dv else 0.0) for v in self.mrsp.values])

    def permitted_speed(self, position_m: float) -> float:
        """min(MRSP, the permitted curves of every target), m/s; 0 beyond the SvL."""
        return self.curve('permitted', position_m)

    def sampled(self, name: str) -> 'SampledLimit':
        """The named limit tabulated once (see :class:`SampledLimit`), for supervision every
        control period; built on first use and kept."""
        if name not in self._sampled:
            boundaries = [x for x in self.mrsp.starts if x <= self.supervised_location_m]
            boundaries += [self.start_m, self.supervised_location_m]
            samples = []
            for curve in self.curves[name]:
                boundaries += curve.edges()
                samples.append(curve.positions)
            edges = np.array(boundaries)
            xs = np.unique(np.concatenate(samples + [edges, edges - SAMPLE_EDGE_M]))
            xs = xs[xs <= self.supervised_location_m]
            self._sampled[name] = SampledLimit(xs.tolist(), self._curve_at(name, xs).tolist())
        return self._sampled[name]

    def _curve_at(self, name: str, xs: np.ndarray) -> np.ndarray:
        """``curve(name, x)`` for every x of an array (the same rules, vectorised)."""
        lowest = np.full(xs.shape, math.inf)
        for c in self.curves[name]:
            lowest = np.minimum(lowest, c.at(xs))
        if name == 'sbi':
            lowest = np.minimum(lowest, self._curve_at('ebi', xs))
        dv = {'ebi': DV_EBI_KMH, 'sbi': DV_SBI_KMH, 'warning': DV_WARNING_KMH}
        if name in dv or name in ('permitted', 'indication'):
            margins = [ceiling_margin(v, dv[name]) if name in dv else 0.0
                       for v in self.mrsp.values]
            section = np.maximum(np.searchsorted(self.mrsp.starts, xs, side='right') - 1, 0)
            lowest = np.minimum(lowest, (np.array(self.mrsp.values) + np.array(margins))[section])
        return np.where(xs > self.supervised_location_m, 0.0, np.maximum(lowest, 0.0))


class SampledLimit:
    """A supervision limit tabulated along an authority: linear between the samples of its
    curves, with a sample on each side of every step (MRSP changes, curve ends) and zero beyond
    the last sample (the SvL). Between two samples the exact limit is the lowest of linear
    pieces and a constant ceiling, a concave function, so the chord never lies above it: the
    table is exact at the samples and on the safe side between them. About 0.5 us per look-up
    instead of several for the exact curves."""

    def __init__(self, positions: list[float], speeds: list[float]):
        self.positions = positions
        self.speeds = speeds

    def __call__(self, position_m: float) -> float:
        xs = self.positions
        i = bisect_right(xs, position_m)
        if i == 0:
            return self.speeds[0]
        if i == len(xs):
            return self.speeds[-1] if position_m == xs[-1] else 0.0
        x0, x1 = xs[i - 1], xs[i]
        v0, v1 = self.speeds[i - 1], self.speeds[i]
        return v0 + (v1 - v0) * (position_m - x0) / (x1 - x0)


#: how many scenarios' supervisions a process keeps (RunSupervision.for_scenario)
RUN_CACHE_SIZE = 8
_RUNS: dict[str, 'RunSupervision'] = {}


class RunSupervision:
    """One movement authority per leg of a run (station to station). The leg in force is the
    supervised train's state (the plant's ATP, ``train_plant_node.atp``, keeps it): it moves on
    to the next leg only once the train has stood still at the leg's stop (``at_stop``: from
    ``STOP_WINDOW_M`` before the stopping point to the SvL, at most ``STANDSTILL_MPS``) without
    a break for the stop's dwell time. Look-ups without a leg take ``leg_at``: the leg of a
    train that stopped at every earlier station (for plans and figures, not for supervising a
    train)."""

    STOP_WINDOW_M = 0.5
    STANDSTILL_MPS = 0.01

    def __init__(self, line: Line, settings: SupervisionSettings, train_length_m: float,
                 stations_m: Sequence[float], names: Sequence[str] = (),
                 dwells_s: Sequence[float] = (), max_speed_mps: float = math.inf):
        self.stations_m = list(stations_m)
        names = list(names) or [''] * len(stations_m)
        self.dwells_s = list(dwells_s) or [0.0] * len(stations_m)
        self.legs = [SpeedSupervision(line, settings, train_length_m, origin, destination,
                                      final=i == len(stations_m) - 2, stop_name=names[i + 1],
                                      max_speed_mps=max_speed_mps)
                     for i, (origin, destination) in enumerate(zip(stations_m, stations_m[1:]))]

    @classmethod
    def for_scenario(cls, scenario) -> 'RunSupervision':
        """The run of a scenario (:class:`ato_common.scenario.Scenario`): from its initial
        station through every later one, bounded by the train's design maximum speed.

        Built once per content in a process (:data:`_RUNS`, the last few): the supervision is
        read-only once built (its sampled tables are filled in on first use, from its own
        content), and a campaign's or a comparison's runs of one scenario would otherwise build
        the same braking curves again for every run."""
        stations = [s for s in scenario.line.stations
                    if s.position_m >= scenario.run.initial_position_m - 1e-9]
        arguments = (scenario.line, scenario.supervision, scenario.train.length_m,
                     [s.position_m for s in stations], [s.name for s in stations],
                     [s.dwell_s for s in stations],
                     getattr(scenario.train, 'max_speed_mps', math.inf))
        try:
            key = repr(content_key(arguments))
        except Undescribable:
            return cls(*arguments)
        run = _RUNS.pop(key, None) or cls(*arguments)
        _RUNS[key] = run  # the newest last
        while len(_RUNS) > RUN_CACHE_SIZE:
            _RUNS.pop(next(iter(_RUNS)))
        return run

    def leg_at(self, position_m: float) -> int:
        passed = bisect_right(self.stations_m, position_m + self.STOP_WINDOW_M) - 1
        return min(max(passed, 0), len(self.legs) - 1)

    def stop_zone(self, leg: int) -> tuple[float, float]:
        """(from, to) m: where a train standing still has stopped at the leg's stop (up to the
        SvL: a train that overran its EOA has stopped there too); empty (inf, -inf) on the last
        leg, whose authority never moves on."""
        if leg >= len(self.legs) - 1:
            return math.inf, -math.inf
        return (self.stations_m[leg + 1] - self.STOP_WINDOW_M,
                self.legs[leg].supervised_location_m)

    def at_stop(self, leg: int, position_m: float, speed_mps: float) -> bool:
        low, high = self.stop_zone(leg)
        return abs(speed_mps) <= self.STANDSTILL_MPS and low <= position_m <= high

    def dwell_s(self, leg: int) -> float:
        """How long the train stands at the leg's stop before the authority moves on."""
        return self.dwells_s[leg + 1]

    def target_monitoring(self, leg: int, position_m: float) -> bool:
        """The EBI is that of the leg's stop (its braking curve or release speed), not the
        ceiling: an intervention there holds until standstill (SUBSET-026 3.13.10.4)."""
        supervision = self.legs[leg]
        mrsp = supervision.mrsp(position_m)
        return supervision.curves['ebi'][-1](position_m) < mrsp + ceiling_margin(mrsp,
                                                                                  DV_EBI_KMH)

    def permitted_speed(self, position_m: float, leg: int | None = None) -> float:
        return self.legs[self.leg_at(position_m) if leg is None else leg].permitted_speed(
            position_m)

    def curve(self, name: str, position_m: float, leg: int | None = None) -> float:
        return self.legs[self.leg_at(position_m) if leg is None else leg].curve(name, position_m)

    def sampled_curve(self, name: str, position_m: float, leg: int | None = None) -> float:
        """``curve(name, position_m, leg)`` from the tabulated limits (exact at the samples,
        never above the exact limit between them); for supervision at every control period."""
        leg = self.leg_at(position_m) if leg is None else leg
        return self.legs[leg].sampled(name)(position_m)
    def packed_curve(self, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every leg's ``sampled(name)`` table in flat arrays, for compiled look-ups: (offsets,
        positions, speeds), leg i's samples at ``offsets[i]:offsets[i + 1]``."""
        tables = [leg.sampled(name) for leg in self.legs]
        offsets = np.cumsum([0] + [len(t.positions) for t in tables]).astype(np.int64)
        positions = np.array([x for t in tables for x in t.positions], dtype=float)
        speeds = np.array([v for t in tables for v in t.speeds], dtype=float)
        return offsets, positions, speeds
