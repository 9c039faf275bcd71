"""PID with feedforward: the industrial ATO baseline.

Feedforward of the nominal train model (mass times the reference acceleration plus the nominal
Davis resistance at the measured speed and the known grade force) and PID feedback on the
position error with the speed error as its derivative, all scaled by the nominal mass so that
gains are train-independent:

    e_x = x* - x - delta,  e_v = v* - v,  I = integral of e_x
    F = M_nom (a* + kp e_x + kd e_v + ki I) + R_nom(v) + G(x)

G(x) is the grade force of the nominal train at its measured position from the gradient profile
the controller knows (``TrainKnowledge.grade_force_n``: on-board track data; zero where it is
hidden, and with ``grade_feedforward`` off). With the default gains the error dynamics
s^3 + kd s^2 + kp s + ki have a triple pole at -0.4 rad/s (kd = 3w, kp = 3w^2, ki = w^3): well
damped, far below the 10 Hz sampling and the actuator lag. The integral removes the steady error
of resistance mismatch and of the grades not fed forward.

Checked on every built-in scenario with `make compare` (RMS speed error 0.003-0.03 km/h, stop
errors under 0.02 m on short_line, jinan_xuzhou, liu_li_2020, luo_xu_crh3, mao_4car; on
mao_2017_modes the error comes from the power-limited motors after the failure, not the gains):
the default gains were kept; the applied force's max jerk stays at 0.1-0.3 m/s^3 there.

Anti-windup (Astrom & Hagglund, Advanced PID Control, ISA 2006, section 3.5 "Windup":
back-calculation with a tracking time constant Tt, and conditional integration). Two states wind
up while the command is saturated: the integral I and the position error itself (the integral of
the speed error, which keeps growing while the train cannot follow). Both are handled:

- the position error the law acts on is ``x* - x - delta``: while saturated, the law's own
  reference shift delta is back-calculated, delta' = (F_wanted - F_commanded) / (M kp Tt), so the
  wanted force tracks the commanded one with the time constant Tt (``tracking_time_s``; 0 turns
  it off) instead of running away; out of saturation delta is released towards 0, the law's
  reference x* - delta running at max(v* + ``catch_up_speed_mps``, sqrt(2 b |delta|)) with b
  ``catch_up_deceleration_mps2``: the train makes up the lost distance a little faster than the
  reference while it runs, and along a braking curve to where it stands (so it still reaches
  every stop), instead of catching up at overspeed; delta never exceeds the position error
  itself (a replanned reference that starts where the train is takes it back to 0);
- conditional integration: while the command is saturated the integrator only moves in the
  direction that leaves saturation.

Unsaturated, delta stays 0 and the law is the PID above. Bumpless transfer: on take-over the
integrator is set so that the first command equals the last one (within the integrator's limit)
and delta starts at 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ato_common.types import ReferencePoint
from ato_controller_node.laws.base import ControlLaw, LawOutput, Measurement, setting


@dataclass(frozen=True)
class PidSettings:
    kp_position: float = setting(0.48, minimum=0.0, maximum=100.0, units='1/s^2',
                                 description='gain on the position error')
    kd_speed: float = setting(1.2, minimum=0.0, maximum=100.0, units='1/s',
                              description='gain on the speed error')
    ki_position: float = setting(0.064, minimum=0.0, maximum=100.0, units='1/s^3',
                                 description='gain on the integral of the position error')
    integral_limit_mps2: float = setting(0.5, minimum=0.0, maximum=5.0, units='m/s^2',
                                         description='bound of the integral action ki*I')
    grade_feedforward: bool = setting(True, minimum=0, maximum=1, units='-',
                                      description='feed the known grade force forward (the '
                                      "knowledge's gradient profile; zero where it is hidden)")
    tracking_time_s: float = setting(2.5, minimum=0.0, maximum=100.0, units='s',
                                     description='anti-windup tracking time constant Tt of the '
                                     'position error under saturation (back-calculation; 0: '
                                     'off, the position error winds up)')
    catch_up_speed_mps: float = setting(1.0, minimum=0.0, maximum=20.0, units='m/s',
                                        description='out of saturation, the distance lost to '
                                        'it is made up at most this much faster than the '
                                        'reference (or along catch_up_deceleration_mps2)')
    catch_up_deceleration_mps2: float = setting(0.3, minimum=0.01, maximum=2.0,
                                                units='m/s^2', description='the lost distance '
                                                'd is also closed at up to sqrt(2 b d): a '
                                                'braking curve to where the reference stands')


class PidLaw(ControlLaw):
    name = 'pid'
    paper = None
    summary = 'PID on position/speed error with nominal-model feedforward (industrial baseline)'
    Settings = PidSettings

    def __init__(self, train, dt, settings=None):
        super().__init__(train, dt, settings)
        self.integral = 0.0
        self.delta = 0.0          # the back-calculated shift of the position reference, m
        self._pending_error = 0.0
        self._speed = 0.0         # the reference speed of this period, m/s

    def _unbounded_parts(self, m: Measurement, r: ReferencePoint) -> tuple[float, float]:
        """(force without the integral term, N per unit of integral action)."""
        s = self.settings
        mass = self.train.nominal_mass_kg
        feedback = s.kp_position * (r.position - m.position - self.delta) + s.kd_speed * (
            r.speed - m.speed)
        force = mass * (r.acceleration + feedback) + self.train.nominal_davis.force(m.speed)
        if s.grade_feedforward:
            force += self.train.grade_force_n(m.car_positions or m.position)
        return force, mass

    def _clamp_integral(self) -> None:
        s = self.settings
        if s.ki_position > 0.0:
            bound = s.integral_limit_mps2 / s.ki_position
            self.integral = min(max(self.integral, -bound), bound)

    def reset(self, measurement, reference, last_force_n):
        self.delta = 0.0
        ki = self.settings.ki_position
        if last_force_n is None or ki <= 0.0:
            self.integral = 0.0  # nothing to take over from
            return
        base, per_action = self._unbounded_parts(measurement, reference)
        self.integral = (last_force_n - base) / per_action / ki
        self._clamp_integral()

    def update_settings(self, settings) -> None:
        # Keep the integral action ki*I across a change of ki, so a gain change is bumpless.
        old_ki, new_ki = self.settings.ki_position, settings.ki_position
        self.integral = self.integral * old_ki / new_ki if old_ki > 0.0 and new_ki > 0.0 else 0.0
        super().update_settings(settings)
        self._clamp_integral()
        if settings.tracking_time_s <= 0.0:
            self.delta = 0.0

    def step(self, measurement, reference):
        # delta forgives part of the position error, never more than there is: when the
        # reference comes back to the train (a replanned reference starts where it is), so does
        # the law's
        error = reference.position - measurement.position
        if self.delta > 0.0:
            self.delta = min(self.delta, max(error, 0.0))
        elif self.delta < 0.0:
            self.delta = max(self.delta, min(error, 0.0))
        base, per_action = self._unbounded_parts(measurement, reference)
        force = base + per_action * self.settings.ki_position * self.integral
        self._pending_error = reference.position - measurement.position - self.delta
        self._speed = reference.speed
        return LawOutput(force, {'integral_action_mps2': self.settings.ki_position * self.integral,
                                 'windup_shift_m': self.delta})

    def after_saturation(self, wanted_n, commanded_n, commanded_forces_n=(), applied_n=None):
        s = self.settings
        saturated = commanded_n != wanted_n
        if s.tracking_time_s > 0.0 and s.kp_position > 0.0:
            if saturated:
                # back-calculation: the wanted force tracks the commanded one in Tt
                self.delta += self.dt * (wanted_n - commanded_n) / (
                    self.train.nominal_mass_kg * s.kp_position * s.tracking_time_s)
            else:
                # release towards 0: the law's reference runs at most catch_up_speed_mps
                # faster than the reference, or along a braking curve to where it stands
                lost = abs(self.delta)
                speed = max(s.catch_up_speed_mps, math.sqrt(
                    2.0 * s.catch_up_deceleration_mps2 * lost) - max(self._speed, 0.0))
                step = min(lost, speed * self.dt)
                self.delta -= step if self.delta > 0.0 else -step
        error = self._pending_error
        saturated_high = commanded_n < wanted_n
        saturated_low = commanded_n > wanted_n
        if (saturated_high and error > 0.0) or (saturated_low and error < 0.0):
            return  # integrating would push further into the limit
        if s.ki_position <= 0.0:
            return  # no integral action: do not store a state that a later ki would release
        self.integral += error * self.dt
        self._clamp_integral()
