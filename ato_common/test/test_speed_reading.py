"""A speed sensor's reading (``ato_common.plant_setup.speed_reading``): its bias acts in full
from 30 km/h and in proportion to the speed below, so the reading keeps the sign of the speed
and is 0 only at true standstill (on the starting commit a bias of -0.2 m/s read a train
creeping at 0.05 m/s as running backwards)."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ato_common.plant_setup import (
    SPEED_BIAS_FULL_MPS,
    SPEED_BIAS_MAX_MPS,
    QuantitySensor,
    speed_reading,
)


@given(speed=st.floats(-100.0, 100.0), bias=st.floats(-SPEED_BIAS_MAX_MPS, SPEED_BIAS_MAX_MPS),
       scale=st.floats(-0.1, 0.1))
def test_a_speed_reading_keeps_the_sign_of_the_speed_and_reads_0_only_at_standstill(
        speed, bias, scale):
    reading = speed_reading(QuantitySensor(bias=bias, scale_error=scale), speed)
    assert (reading == 0.0) == (speed == 0.0)
    assert math.copysign(1.0, reading) == math.copysign(1.0, speed) or speed == 0.0
    if abs(speed) >= SPEED_BIAS_FULL_MPS:
        assert reading == pytest.approx((1.0 + scale) * speed + bias * math.copysign(1.0, speed))
