"""The most restrictive speed profile against a brute-force computation in exact arithmetic: on
random limit tables (positions on a decimetre grid, where sums such as 504.3 + 200 round
below the exact value, and arbitrary floats), on the case of issue 14, and on every TTOBench
sample track with every sample train."""

import math
from fractions import Fraction
from pathlib import Path

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from ato_common.braking_curves import most_restrictive_speed_profile, tail_clear_position
from ato_common.line import PiecewiseConstant
from ato_common.ttobench import load_track, load_train

SAMPLES = Path(__file__).resolve().parents[2] / 'tests' / 'data' / 'ttobench'


def brute_force(limits: PiecewiseConstant, end_m: float, length_m: float, x: float) -> float:
    """The lowest static limit over the train, [x - L, x], with the positions taken as the
    exact rationals their floats are: a section [s, e) counts when s <= x and x - L < e."""
    exact_x, exact_length = Fraction(x), Fraction(length_m)
    return min(v for s, e, v in limits.segments(end_m)
               if Fraction(s) <= exact_x and exact_x - exact_length < Fraction(e))


def probe_points(limits: PiecewiseConstant, end_m: float, length_m: float,
                 profile: PiecewiseConstant) -> list[float]:
    """Every float at which either function can change (the starts, the exact sum e + L rounded
    down and up, the profile's own starts) with its neighbours, inside [0, end)."""
    points = set(profile.starts)
    for s, e, _ in limits.segments(end_m):
        points.add(s)
        exact = Fraction(e) + Fraction(length_m)
        nearest = float(exact)
        points.update((nearest, math.nextafter(nearest, -math.inf),
                       math.nextafter(nearest, math.inf)))
    around = set()
    for p in points:
        around.update((p, math.nextafter(p, -math.inf), math.nextafter(p, math.inf)))
    return sorted(p for p in around if 0.0 <= p < end_m)


def assert_matches_brute_force(limits, end_m, length_m):
    profile = most_restrictive_speed_profile(limits, end_m, length_m)
    assert profile.starts[0] == 0.0
    assert all(a != b for a, b in zip(profile.values, profile.values[1:])), 'redundant steps'
    for x in probe_points(limits, end_m, length_m, profile):
        assert profile(x) == brute_force(limits, end_m, length_m, x), (
            f'at {x!r} m: profile {profile(x)}, brute force '
            f'{brute_force(limits, end_m, length_m, x)} (limits {limits.starts}, '
            f'{limits.values}, train {length_m!r} m)')


def test_a_raise_whose_end_plus_the_train_rounds_down_is_kept():
    # issue 14: 504.3 + 200 rounds to a float below the exact sum, where the tail is still in
    # the 110 section; the raise to 125 km/h must be kept, one float later
    limits = PiecewiseConstant([0.0, 504.3, 2140.4], [110.0, 125.0, 110.0])
    profile = most_restrictive_speed_profile(limits, 5000.0, 200.0)
    assert profile.values == [110.0, 125.0, 110.0]
    assert profile.starts[1] == math.nextafter(504.3 + 200.0, math.inf)
    assert Fraction(profile.starts[1]) - 200 >= Fraction(504.3)
    assert Fraction(math.nextafter(profile.starts[1], 0.0)) - 200 < Fraction(504.3)
    assert_matches_brute_force(limits, 5000.0, 200.0)


def test_the_tail_clear_position_is_the_first_float_past_the_exact_sum():
    for end, length in ((504.3, 200.0), (0.1, 0.2), (1e16, 1.0), (2140.4, 200.0), (3.0, 4.0)):
        clear = tail_clear_position(end, length)
        assert Fraction(clear) >= Fraction(end) + Fraction(length)
        assert Fraction(math.nextafter(clear, -math.inf)) < Fraction(end) + Fraction(length)


speeds = st.sampled_from([40.0, 60.0, 80.0, 110.0, 125.0, 160.0, 200.0, 250.0, 300.0])
decimetres = st.integers(1, 60000).map(lambda d: d / 10.0)
floats = st.floats(0.001, 6000.0, allow_nan=False, allow_infinity=False)


@st.composite
def limit_tables(draw):
    grid = draw(st.booleans())
    positions = st.lists(decimetres if grid else floats, min_size=0, max_size=8, unique=True)
    starts = [0.0] + sorted(draw(positions))
    values = [draw(speeds) for _ in starts]
    length = draw(st.sampled_from([25.0, 200.0, 201.4, 400.0]) | decimetres | floats)
    end = starts[-1] + draw(st.sampled_from([0.1, 1.0, 150.0, 5000.0]) | floats)
    return PiecewiseConstant(starts, values), end, length


@settings(max_examples=400, deadline=None)
@given(limit_tables())
@example((PiecewiseConstant([0.0, 504.3, 2140.4], [110.0, 125.0, 110.0]), 5000.0, 200.0))
@example((PiecewiseConstant([0.0, 0.1], [80.0, 160.0]), 10.0, 0.2))
def test_the_profile_is_the_lowest_limit_under_the_train(table):
    limits, end, length = table
    assert_matches_brute_force(limits, end, length)


@pytest.mark.parametrize('train', sorted((SAMPLES / 'trains').glob('*.json')), ids=lambda p: p.stem)
def test_every_sample_track_with_every_sample_train(train):
    length = load_train(train).parameters.length_m
    for track in sorted((SAMPLES / 'tracks').glob('*.json')):
        line = load_track(track).line
        assert_matches_brute_force(line.speed_limit_mps, line.length_m, length)
