"""Property test of the supervision (issue 13): on random lines, stops and train data, a train
that obeys the braking curves stays within its authority. Obeying the EBI means the worst the
supervision allows: at any position, at the EBI's speed, the train keeps that speed for the
traction cut-off and emergency brake build-up times, then brakes with its emergency
deceleration (plus the gradient). It must stand still before the stop's EOA (the overlap to the
SvL is left unused, see ``ato_common.braking_curves``), and pass every
lower limit's start at most at that limit plus dV_ebi. The braking is integrated exactly
(constant deceleration within each gradient section)."""

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from ato_common import units
from ato_common.braking_curves import (
    DV_EBI_KMH,
    RunSupervision,
    SupervisionSettings,
    ceiling_margin,
    constant_deceleration,
)
from ato_common.line import Line, PiecewiseConstant, Station


@st.composite
def runs(draw):
    length = draw(st.floats(5000.0, 60000.0))
    stops = sorted(draw(st.lists(st.floats(1000.0, length - 500.0), min_size=1, max_size=3,
                                 unique=True)))
    stops = [s for i, s in enumerate(stops) if i == 0 or s - stops[i - 1] > 500.0]
    starts = [0.0] + sorted(draw(st.lists(st.floats(10.0, length - 10.0), max_size=5)))
    limits = [units.kmh_to_mps(draw(st.floats(40.0, 400.0))) for _ in starts]
    grade_starts = [0.0] + sorted(draw(st.lists(st.floats(10.0, length - 10.0), max_size=5)))
    grades = [draw(st.floats(-0.02, 0.02)) for _ in grade_starts]
    line = Line('random', length, tuple(Station(f's{i}', x, 0.0)
                                        for i, x in enumerate([0.0] + stops)),
                PiecewiseConstant(starts, limits), PiecewiseConstant(grade_starts, grades))
    times = st.floats(0.0, 5.0)
    supervision = SupervisionSettings(
        emergency_deceleration=constant_deceleration(draw(st.floats(0.4, 1.5))),
        service_deceleration=constant_deceleration(draw(st.floats(0.3, 1.0))),
        traction_cut_off_s=draw(times), emergency_brake_build_up_s=draw(times),
        service_brake_build_up_s=draw(times), eoa_beyond_stop_m=draw(st.floats(0.0, 200.0)),
        overlap_m=draw(st.floats(0.0, 200.0)))
    max_speed = units.kmh_to_mps(draw(st.floats(120.0, 500.0)))
    run = RunSupervision(line, supervision, draw(st.floats(20.0, 400.0)),
                         [0.0] + stops, max_speed_mps=max_speed)
    return line, supervision, run


def brake_to_stop(line, deceleration, position, speed, lower_limits):
    """Exact braking: v^2 falls by 2 (A + g sin) per metre within each gradient section. Checks
    the speed at every lower limit's start on the way (``lower_limits``: (location, speed))."""
    square = speed * speed
    x = position
    starts = line.grade_sine.starts
    while square > 0.0:
        following = [s for s in starts if s > x + 1e-9]
        section_end = following[0] if following else math.inf
        rate = 2.0 * (deceleration + units.STANDARD_GRAVITY * line.grade_sine(x + 1e-9))
        assert rate > 0.0
        for location, limit in lower_limits:
            if x <= location <= min(section_end, x + square / rate):
                v_there = math.sqrt(max(square - rate * (location - x), 0.0))
                assert v_there <= limit * (1 + 1e-9) + 1e-6, (location, v_there, limit)
        if x + square / rate <= section_end:
            return x + square / rate
        square -= rate * (section_end - x)
        x = section_end
    return x


@settings(max_examples=150, deadline=None)
@given(runs(), st.data())
def test_a_train_that_obeys_the_ebi_stops_within_its_authority(case, data):
    line, supervision, run = case
    deceleration = supervision.emergency_deceleration(0.0)
    delay = supervision.traction_cut_off_s + supervision.emergency_brake_build_up_s
    leg = data.draw(st.integers(0, len(run.legs) - 1))
    authority = run.legs[leg]
    eoa = authority.end_of_authority_m
    lower = [(t.location_m, t.speed_mps + ceiling_margin(t.speed_mps, DV_EBI_KMH))
             for t in authority.targets if t.kind == 'speed_decrease']
    for _ in range(20):
        x = data.draw(st.floats(authority.start_m, eoa))
        for speed in (run.curve('ebi', x, leg), run.sampled_curve('ebi', x, leg)):
            assert speed <= authority.max_speed_mps + ceiling_margin(authority.max_speed_mps,
                                                                     DV_EBI_KMH) + 1e-9
            # the delay at constant speed (its distance checked against lower limits too)
            reached = x + speed * delay
            for location, limit in lower:
                if x <= location <= reached:
                    assert speed <= limit * (1 + 1e-9) + 1e-6
            stop = brake_to_stop(line, deceleration, reached, speed, lower)
            assert stop <= eoa + 1e-6 * max(1.0, eoa), (x, speed, stop, eoa)


@settings(max_examples=100, deadline=None)
@given(runs())
def test_the_sampled_limits_never_exceed_the_exact_ones(case):
    """The tables the plant supervises with are on the safe side between their samples, the
    release speed's kink, its step at the stopping point and the EOA's step included."""
    _line, _supervision, run = case
    for leg, authority in enumerate(run.legs):
        xs = [authority.start_m + k * (authority.supervised_location_m - authority.start_m)
              / 997.0 for k in range(998)]
        xs += [authority.end_of_authority_m - 1e-4, authority.end_of_authority_m,
               authority.stopping_point_m - 1e-4, authority.stopping_point_m]
        for name in ('ebi', 'permitted'):
            for x in xs:
                assert run.sampled_curve(name, x, leg) <= run.curve(name, x, leg) + 1e-9
