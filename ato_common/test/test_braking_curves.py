"""Braking-curve supervision: MRSP with the train length, deceleration curves against closed
forms, gradient correction, the order of the ETCS curves, authority ends."""

import math

import numpy as np
import pytest

from ato_common import units
from ato_common.braking_curves import (
    CURVE_NAMES,
    DV_EBI_KMH,
    DecelerationCurve,
    RunSupervision,
    SpeedSupervision,
    SupervisionSettings,
    ceiling_margin,
    constant_deceleration,
    deceleration_curve,
    interpolate,
    most_restrictive_speed_profile,
    tabulated_deceleration,
)
from ato_common.line import Line, PiecewiseConstant, Station
from ato_common.scenario import load_scenario


def line(limits=((0.0, 300.0),), grades=((0.0, 0.0),), length=40000.0):
    return Line('t', length, (Station('A', 0.0, 0.0), Station('B', length, 0.0)),
                PiecewiseConstant([s for s, _ in limits], [units.kmh_to_mps(v) for _, v in limits]),
                PiecewiseConstant([s for s, _ in grades],
                                  [units.per_mille_to_sine(g) for _, g in grades]))


SETTINGS = SupervisionSettings(constant_deceleration(1.2), constant_deceleration(0.9))


def test_mrsp_applies_a_decrease_at_its_start_and_an_increase_after_the_train():
    limits = PiecewiseConstant([0.0, 1000.0, 1100.0, 3000.0], [80.0, 40.0, 60.0, 70.0])
    mrsp = most_restrictive_speed_profile(limits, 5000.0, 200.0)
    assert mrsp(999.0) == 80.0 and mrsp(1000.0) == 40.0
    # the 60 section is shorter than the train behind the 40 one: 40 holds until 1300 m
    assert mrsp(1299.0) == 40.0 and mrsp(1300.0) == 60.0
    assert mrsp(3199.0) == 60.0 and mrsp(3200.0) == 70.0


def test_level_deceleration_curve_is_the_closed_form():
    curve = deceleration_curve(line(), 30000.0, 10.0, 90.0, constant_deceleration(0.8))
    for d in (0.0, 100.0, 2000.0, 4000.0):
        assert curve(30000.0 - d) == pytest.approx(math.sqrt(100.0 + 2 * 0.8 * d), rel=1e-9)
    assert curve(30000.0 - 6000.0) == math.inf  # beyond 90 m/s the curve does not restrict


def test_gradient_corrects_the_deceleration():
    level = deceleration_curve(line(), 30000.0, 0.0, 90.0, constant_deceleration(0.8))
    down = deceleration_curve(line(grades=((0.0, -10.0),)), 30000.0, 0.0, 90.0,
                              constant_deceleration(0.8))
    up = deceleration_curve(line(grades=((0.0, 10.0),)), 30000.0, 0.0, 90.0,
                            constant_deceleration(0.8))
    d = 1500.0
    g_sine = units.STANDARD_GRAVITY * units.per_mille_to_sine(10.0)
    assert down(30000.0 - d) == pytest.approx(math.sqrt(2 * (0.8 - g_sine) * d), rel=1e-9)
    assert up(30000.0 - d) == pytest.approx(math.sqrt(2 * (0.8 + g_sine) * d), rel=1e-9)
    assert down(30000.0 - d) < level(30000.0 - d) < up(30000.0 - d)
    # a grade change inside the curve: exact piecewise v^2
    mixed = deceleration_curve(line(grades=((0.0, 0.0), (29000.0, -10.0))), 30000.0, 0.0,
                               90.0, constant_deceleration(0.8))
    expected = 2 * (0.8 - g_sine) * 1000.0 + 2 * 0.8 * 500.0
    assert mixed(28500.0) == pytest.approx(math.sqrt(expected), rel=1e-9)


def test_tabulated_deceleration_holds_each_value_up_to_the_next_speed():
    table = tabulated_deceleration([0.0, 20.0, 40.0], [0.9, 0.8, 0.7])
    assert table(0.0) == 0.9 and table(19.9) == 0.9 and table(20.0) == 0.8
    assert table(100.0) == 0.7


def test_ceiling_margins_follow_the_etcs_defaults():
    assert units.mps_to_kmh(ceiling_margin(units.kmh_to_mps(80.0), DV_EBI_KMH)) == \
        pytest.approx(7.5)
    assert units.mps_to_kmh(ceiling_margin(units.kmh_to_mps(160.0), DV_EBI_KMH)) == \
        pytest.approx(11.25)
    assert units.mps_to_kmh(ceiling_margin(units.kmh_to_mps(300.0), DV_EBI_KMH)) == \
        pytest.approx(15.0)


@pytest.fixture(scope='module')
def supervision():
    return SpeedSupervision(line(((0.0, 300.0), (20000.0, 160.0), (25000.0, 300.0))), SETTINGS,
                            200.0, 0.0, 38000.0)


def test_targets_are_the_lower_limit_and_the_end_of_authority(supervision):
    kinds = [(t.kind, t.location_m, round(units.mps_to_kmh(t.speed_mps), 6))
             for t in supervision.targets]
    assert kinds == [('speed_decrease', 20000.0, 160.0), ('end_of_authority', 38000.0, 0.0)]
    assert supervision.end_of_authority_m == 38000.0 + SETTINGS.eoa_beyond_stop_m
    assert supervision.supervised_location_m == supervision.end_of_authority_m + \
        SETTINGS.overlap_m


def test_the_curves_are_ordered_as_etcs_orders_them(supervision):
    order = ('ebi', 'sbi', 'warning', 'permitted', 'indication')
    for x in np.arange(0.0, 38200.0, 37.0):
        values = [supervision.curve(name, x) for name in order]
        assert all(a >= b - 1e-9 for a, b in zip(values, values[1:])), (x, values)
        if supervision.curve('sbi', x) > supervision.release_speed_mps:  # not the floor
            assert supervision.curve('ebd', x) >= supervision.curve('ebi', x) - 1e-9
            assert supervision.curve('sbd', x) >= supervision.curve('sbi', x) - 1e-9
        assert supervision.permitted_speed(x) <= supervision.mrsp(x)


def test_the_permitted_curve_is_the_service_curve_shifted_by_the_reaction_times(supervision):
    # at speed v the permitted curve is where the SBD is, v (T_bs + T_driver) further on
    eoa = supervision.end_of_authority_m
    stop = supervision.stopping_point_m
    shift = SETTINGS.service_brake_build_up_s + SETTINGS.driver_reaction_s
    for v in (5.0, 20.0, 40.0):
        d_sbd = v * v / (2 * 0.9)
        x = eoa - d_sbd - v * shift
        # floored at the release speed up to the stopping point
        expected = max(v, supervision.release_speed_mps) if x < stop else v
        assert supervision.permitted_speed(x) == pytest.approx(expected, rel=1e-3)
    # the release speed: the EBI's at the stopping point; the curve from there to the EOA,
    # zero from the EOA on
    assert 5.0 < supervision.release_speed_mps <= SETTINGS.release_speed_max_mps
    assert supervision.curve('ebi', stop - 1e-3) == pytest.approx(supervision.release_speed_mps,
                                                                  rel=1e-4)
    assert 0.0 < supervision.curve('ebi', stop + 25.0) < supervision.release_speed_mps
    assert supervision.curve('ebi', eoa) == 0.0
    # the EBD ends at the EOA (not the SvL: the overlap is left as a margin); the speed
    # target's EBD at V_target + dV_ebi
    assert supervision.curve('ebd', eoa - 1e-6) < 0.1
    assert supervision.curve('ebd', eoa - 1.0) < math.sqrt(2 * 1.2 * 1.0) + 1e-6
    v_ebd = units.kmh_to_mps(160.0) + ceiling_margin(units.kmh_to_mps(160.0), DV_EBI_KMH)
    assert supervision.curves['ebd'][0](20000.0) == pytest.approx(v_ebd, rel=1e-9)


def test_far_from_targets_the_permitted_speed_is_the_mrsp_and_zero_beyond_the_svl(supervision):
    assert supervision.permitted_speed(5000.0) == pytest.approx(units.kmh_to_mps(300.0))
    assert supervision.permitted_speed(22000.0) == pytest.approx(units.kmh_to_mps(160.0))
    assert supervision.permitted_speed(38000.0) > 0.0  # the stopping point is inside the MA
    assert supervision.permitted_speed(supervision.supervised_location_m + 1.0) == 0.0
    for name in CURVE_NAMES:
        assert supervision.curve(name, supervision.supervised_location_m + 1.0) == 0.0


def test_a_run_has_one_authority_per_leg():
    run = RunSupervision(line(length=40000.0), SETTINGS, 200.0, [0.0, 15000.0, 40000.0],
                         ['A', 'M', 'B'])
    assert [t.kind for t in run.legs[0].targets] == ['stop']
    assert [t.kind for t in run.legs[1].targets] == ['end_of_authority']
    assert run.leg_at(14000.0) == 0 and run.leg_at(15000.0) == 1
    # approaching the intermediate stop the first leg's curve restricts; past it, it does not
    assert run.permitted_speed(14990.0) < 10.0
    assert run.permitted_speed(15010.0) == pytest.approx(units.kmh_to_mps(300.0))


@pytest.mark.parametrize('name', ['short_line', 'jinan_xuzhou', 'mao_2017_modes'])
def test_the_sampled_limits_match_the_exact_curves_and_never_exceed_them(name):
    scenario = load_scenario(name)
    supervision = RunSupervision.for_scenario(scenario)
    positions = np.random.default_rng(7).uniform(0.0, scenario.line.length_m + 500.0, 4000)
    for curve in ('ebi', 'permitted'):
        for leg in supervision.legs:
            sampled = leg.sampled(curve)
            for x in positions:
                exact = leg.curve(curve, x)
                assert sampled(x) <= exact + 1e-9
                assert sampled(x) >= exact - 0.01  # within 0.036 km/h between samples
            for x in sampled.positions:  # exact at every sample
                assert sampled(x) == pytest.approx(leg.curve(curve, x), abs=1e-9)


@pytest.mark.parametrize('name', ['short_line', 'jinan_xuzhou', 'mao_2017_modes'])
def test_a_limit_asks_only_the_curves_that_restrict_near_and_is_the_same_bit_for_bit(name):
    """``curve`` asks the curves whose span meets the position's interval and reads the ceiling
    from a table (``restricting``): equal, sign and all, to the lowest of every curve and the
    ceiling, at random positions, at every bound and a hair either side, off the line and at
    NaN."""
    import struct
    scenario = load_scenario(name)
    supervision = RunSupervision.for_scenario(scenario)
    rng = np.random.default_rng(11)
    for leg in supervision.legs:
        for curve_name in CURVE_NAMES:
            bounds, near = leg.restricting(curve_name)
            assert len(near) == len(bounds) + 1
            positions = list(rng.uniform(-500.0, scenario.line.length_m + 500.0, 1500))
            positions.append(math.nan)  # not placed: every curve is asked, as before
            for x in bounds + [-math.inf, math.inf, 0.0, leg.supervised_location_m]:
                positions += [x, math.nextafter(x, -math.inf), math.nextafter(x, math.inf)]
            for x in positions:
                every = min((c(x) for c in leg.curves[curve_name]), default=math.inf)
                if curve_name == 'sbi':
                    every = min(every, leg.curve('ebi', x))
                whole = 0.0 if x > leg.supervised_location_m else max(
                    min(every, leg.ceiling_at(curve_name, x)), 0.0)
                assert struct.pack('<d', leg.curve(curve_name, x)) == struct.pack('<d', whole), \
                    (curve_name, x)
            # a curve left out of an interval is infinite everywhere in it
            for (curves, _), a, b in zip(near, [-math.inf] + bounds, bounds + [math.inf]):
                for c in leg.curves[curve_name]:
                    if c not in curves:
                        for x in (a, math.nextafter(b, a), 0.5 * (a + b)):
                            if math.isfinite(x):
                                assert c(x) == math.inf


def test_the_run_supervision_is_built_once_per_content():
    """A campaign's runs of one scenario share one supervision; any change of what it is built
    from (here a dwell, the train's length) builds another, equal to one built afresh."""
    import dataclasses

    import ato_common.braking_curves as braking_curves
    scenario = load_scenario('short_line')
    first = RunSupervision.for_scenario(scenario)
    assert RunSupervision.for_scenario(load_scenario('short_line')) is first
    stations = list(scenario.line.stations)
    stations[1] = dataclasses.replace(stations[1], dwell_s=stations[1].dwell_s + 5.0)
    other_dwell = dataclasses.replace(scenario, line=dataclasses.replace(
        scenario.line, stations=type(scenario.line.stations)(stations)))
    longer = dataclasses.replace(scenario, train=dataclasses.replace(
        scenario.train, length_m=scenario.train.length_m + 50.0))
    for changed in (other_dwell, longer):
        again = RunSupervision.for_scenario(changed)
        assert again is not first
        braking_curves._RUNS.clear()
        fresh = RunSupervision.for_scenario(changed)
        assert fresh is not again
        assert again.dwells_s == fresh.dwells_s
        for leg, fresh_leg in zip(again.legs, fresh.legs):
            assert leg.end_of_authority_m == fresh_leg.end_of_authority_m
            xs = np.linspace(leg.start_m, leg.supervised_location_m, 200)
            assert [leg.curve('ebi', x) for x in xs] == [fresh_leg.curve('ebi', x) for x in xs]
    assert other_dwell.line.stations[1].dwell_s != scenario.line.stations[1].dwell_s


def test_a_curve_read_at_one_position_is_numpys_interpolation_bit_for_bit():
    """The scalar look-up (``interpolate``) gives np.interp's value exactly: between samples,
    at every sample, at repeated samples and on flat and vertical pieces."""
    rng = np.random.default_rng(7)
    for _ in range(300):
        n = int(rng.integers(1, 60))
        xs = np.sort(rng.uniform(0.0, 5000.0, n))
        if n > 3:
            xs[2] = xs[1]  # a repeated position
        ys = rng.uniform(0.0, 90.0, n)
        if n > 5:
            ys[4] = ys[3]  # a flat piece
        queries = np.concatenate([rng.uniform(xs[0], xs[-1], 40), xs])
        for x in queries:
            assert interpolate(float(x), xs.tolist(), ys.tolist()) == float(np.interp(x, xs, ys))
    curve = deceleration_curve(line(), 20000.0, 0.0, units.kmh_to_mps(300.0),
                               constant_deceleration(0.5))
    positions = np.linspace(curve.start_m - 100.0, curve.target_m + 100.0, 2001)
    assert [curve(float(x)) for x in positions] == curve.at(positions).tolist()
    assert isinstance(curve, DecelerationCurve)
