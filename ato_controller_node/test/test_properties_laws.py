"""Property-based: every law's step, through the host, on random and extreme measurements and
references gives a finite command within the actuator limits, and bounded estimates."""

import math
from dataclasses import replace

from hypothesis import given, settings
from hypothesis import strategies as st

from ato_common.scenario import load_scenario
from ato_common.types import ReferencePoint
from ato_controller_node.host import ControllerHost
from ato_controller_node.laws import LAWS
from ato_controller_node.laws.base import Measurement, TrainKnowledge

TRAIN = TrainKnowledge.of(load_scenario('short_line').train)


def train_for(law: str) -> TrainKnowledge:
    """The short_line train with as many actuators as the law drives."""
    count = LAWS[law].actuators
    if count is None:
        return TRAIN
    return replace(TRAIN, actuator_names=tuple(f'motor_{i + 1}' for i in range(count)))
extreme = st.floats(allow_nan=True, allow_infinity=True) | st.floats(-1e6, 1e6) | \
    st.sampled_from([0.0, -0.0, 1e-300, 1e300, -1e300])


# the laws that can drive this train at 10 Hz (the multi-car and high-rate laws have their own
# property tests next to their other tests)
FITTING = sorted(name for name, law in LAWS.items()
                 if law(train_for(name), 0.1).fits(train_for(name)) is None)


@settings(max_examples=150, deadline=None)
@given(st.sampled_from(FITTING),
       st.lists(st.tuples(extreme, extreme, extreme, extreme, extreme), min_size=1, max_size=30))
def test_commands_are_finite_and_within_limits(law, samples):
    host = ControllerHost(train_for(law), 0.1, law)
    for k, (x, v, x_ref, v_ref, a_ref) in enumerate(samples):
        result = host.step(Measurement(0.1 * k, x, v), ReferencePoint(0.1 * k, x_ref, v_ref, a_ref))
        assert all(math.isfinite(f) for f in result.forces_n)
        speed = v if math.isfinite(v) else 0.0
        low, high = TRAIN.traction.limits_at(speed)
        high = max(high, TRAIN.traction.max_traction_force_n)
        assert low - 1e-6 <= result.total_force_n <= high + 1e-6
        for value in result.estimates.values():
            assert math.isfinite(value)
    if law == 'luo_xu':
        assert 0.7 * TRAIN.nominal_mass_kg <= host.law.mass_hat <= 1.5 * TRAIN.nominal_mass_kg
