"""The ATO envelope: saturation-aware anti-windup of the position error, the integral of the
speed error, in the controller host, the same for every law (on for every law or off for every
law).

While the actuators cannot give what a law wants, the reference runs away from the train: the
position error, the integral of the speed error, winds up, and a law acting on it keeps its
command at the limit and, once the limit lets go, catches up at overspeed. The envelope gives
the law the reference position x* - delta instead, back-calculated so that what the law wants
tracks what it gets (Astrom & Hagglund, *Advanced PID Control*, ISA 2006, section 3.5, with a
tracking time constant Tt):

    delta' = (F_wanted - F_commanded) / (M_nom kp Tt),   at most v* - v

while the limit holds the train back as it falls further behind (the excess force and the speed
error v* - v of one sign; ahead of the reference under a braking limit the same with both
signs turned), with kp the law's own position gain about cruise (``ControlLaw.feedback_gains``;
a law with no position feedback, kp = 0, has no position error to wind up and is given the
reference itself). Capped at the rate the train falls behind, the shift at most holds the law's
position error where it was when the limit took hold (conditional integration): a law that
saturates because it oscillates against its limits (a wish beyond the traction limit one period,
beyond the brake the next) keeps the position feedback that holds it to the reference.
Otherwise delta is released towards 0 with a bounded catch-up: the law's reference runs
at most ``catch_up_speed_mps`` faster than the reference, or along a braking curve
sqrt(2 b |delta|) (b ``catch_up_deceleration_mps2``) to where a standing reference stands, so
the train still reaches every stop instead of overspeeding to make up the distance. delta
never exceeds the position error itself (the law's reference lies between the train and the
reference; a replanned reference that starts where the train is takes delta back to 0). The
speed, acceleration and jerk of the reference are the reference's: the speed error is a state,
not an integral, and shifting it within the period it acts in would close a loop through the
law's speed gain in every step. Unsaturated, delta stays 0 and every law runs on the reference
itself. The shift is the host's state: a law switch keeps it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ato_common.types import ReferencePoint
from ato_controller_node.laws.base import FeedbackGains, setting


@dataclass(frozen=True)
class EnvelopeSettings:
    tracking_time_s: float = setting(2.5, minimum=0.01, maximum=100.0, units='s',
                                     description='tracking time constant Tt of the position '
                                                 'shift under saturation')
    catch_up_speed_mps: float = setting(1.0, minimum=0.0, maximum=20.0, units='m/s',
                                        description='out of saturation, the distance lost to '
                                        'it is made up at most this much faster than the '
                                        'reference (or along catch_up_deceleration_mps2)')
    catch_up_deceleration_mps2: float = setting(0.3, minimum=0.01, maximum=2.0,
                                                units='m/s^2', description='the lost distance '
                                                'd is also closed at up to sqrt(2 b d): a '
                                                'braking curve to where the reference stands')


class Envelope:
    """The shift delta of the reference position a law is given; see the module docstring."""

    def __init__(self, settings: EnvelopeSettings | None = None):
        self.settings = settings if settings is not None else EnvelopeSettings()
        self.shift_m = 0.0          # delta

    def reference(self, reference: ReferencePoint, position: float) -> ReferencePoint:
        """The reference the law is given now: the reference itself while nothing is shifted;
        the shift is first bounded by the position error ``reference.position - position``."""
        delta = self.shift_m
        if delta == 0.0:
            return reference
        error = reference.position - position
        if delta > 0.0 and error < delta:      # (a NaN position bounds nothing)
            delta = max(error, 0.0)
        elif delta < 0.0 and error > delta:
            delta = min(error, 0.0)
        self.shift_m = delta
        return ReferencePoint(reference.time_s, reference.position - delta, reference.speed,
                              reference.acceleration, reference.jerk)

    def update(self, excess_n: float, reference_speed: float, dt: float, mass_kg: float,
               gains: FeedbackGains, speed_error: float = 0.0) -> None:
        """After a step: ``excess_n`` = wanted - commanded force (0 unsaturated),
        ``speed_error`` = v* - v."""
        s = self.settings
        stiffness = mass_kg * gains.position_per_s2 * s.tracking_time_s
        if excess_n * speed_error > 0.0 and stiffness > 0.0:
            # the train falls further behind (or ahead) while the limit holds it: at most
            # as fast as it does
            rate = excess_n / stiffness
            rate = min(rate, speed_error) if rate > 0.0 else max(rate, speed_error)
            self.shift_m += dt * rate
            return
        lost = abs(self.shift_m)
        if lost == 0.0:
            return
        speed = max(s.catch_up_speed_mps, math.sqrt(2.0 * s.catch_up_deceleration_mps2 * lost)
                    - max(reference_speed, 0.0))
        step = min(lost, speed * dt)
        self.shift_m -= step if self.shift_m > 0.0 else -step
