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

These published defaults are checked on every built-in scenario by `make compare` (its page,
docs/results/comparison.md, has the figures); the tuned gains are the tuning procedure's
(``ato_controller_node.gains``, docs/results/tuning.md).

Anti-windup. The position error, which winds up while the command is saturated (it is the
integral of the speed error), is the host's: its ATO envelope (``ato_controller_node.envelope``,
the same for every law) shifts the reference this law is given. The integral I is the law's own
and is integrated conditionally (Astrom & Hagglund, Advanced PID Control, ISA 2006, section 3.5
"Windup"): while the command is saturated it only moves in the direction that leaves
saturation. Bumpless transfer: on take-over the integrator is set so that the first command
equals the last one (within the integrator's limit).

Tuning: the admissible ranges of kp, kd, ki are those of a stable error polynomial
s^3 + kd s^2 + kp s + ki (Routh-Hurwitz: kp, kd, ki > 0 and kd kp > ki, ``inadmissible``), with
bandwidths the 10 Hz loop and the actuator lag leave room for (kd at most 5 1/s).
"""

from __future__ import annotations

from dataclasses import dataclass

from ato_common.types import ReferencePoint
from ato_controller_node.laws.base import (
    ControlLaw,
    FeedbackGains,
    LawOutput,
    Measurement,
    setting,
)


@dataclass(frozen=True)
class PidSettings:
    kp_position: float = setting(0.48, minimum=0.0, maximum=100.0, units='1/s^2',
                                 description='gain on the position error',
                                 admissible=(0.01, 4.0), scale='log')
    kd_speed: float = setting(1.2, minimum=0.0, maximum=100.0, units='1/s',
                              description='gain on the speed error',
                              admissible=(0.1, 5.0), scale='log')
    ki_position: float = setting(0.064, minimum=0.0, maximum=100.0, units='1/s^3',
                                 description='gain on the integral of the position error',
                                 admissible=(1e-4, 2.0), scale='log')
    integral_limit_mps2: float = setting(0.5, minimum=0.0, maximum=5.0, units='m/s^2',
                                         description='bound of the integral action ki*I')
    grade_feedforward: bool = setting(True, minimum=0, maximum=1, units='-',
                                      description='feed the known grade force forward (the '
                                      "knowledge's gradient profile; zero where it is hidden)")


class PidLaw(ControlLaw):
    name = 'pid'
    paper = None
    summary = 'PID on position/speed error with nominal-model feedforward (industrial baseline)'
    Settings = PidSettings

    def __init__(self, train, dt, settings=None):
        super().__init__(train, dt, settings)
        self.integral = 0.0
        self._pending_error = 0.0

    @classmethod
    def inadmissible(cls, settings) -> str | None:
        s = settings
        if not s.kd_speed * s.kp_position > s.ki_position:
            return (f'kd kp = {s.kd_speed * s.kp_position:g} must exceed ki = '
                    f'{s.ki_position:g} (Routh-Hurwitz of s^3 + kd s^2 + kp s + ki)')
        return None

    def feedback_gains(self) -> FeedbackGains:
        s = self.settings
        return FeedbackGains(s.kp_position, s.kd_speed, s.ki_position,
                             'the PID itself (its feedforward left out)')

    def _unbounded_parts(self, m: Measurement, r: ReferencePoint) -> tuple[float, float]:
        """(force without the integral term, N per unit of integral action)."""
        s = self.settings
        mass = self.train.nominal_mass_kg
        feedback = s.kp_position * (r.position - m.position) + s.kd_speed * (r.speed - m.speed)
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

    def step(self, measurement, reference):
        base, per_action = self._unbounded_parts(measurement, reference)
        force = base + per_action * self.settings.ki_position * self.integral
        self._pending_error = reference.position - measurement.position
        return LawOutput(force, {'integral_action_mps2': self.settings.ki_position * self.integral})

    def after_saturation(self, wanted_n, commanded_n, commanded_forces_n=(), applied_n=None):
        s = self.settings
        error = self._pending_error
        saturated_high = commanded_n < wanted_n
        saturated_low = commanded_n > wanted_n
        if (saturated_high and error > 0.0) or (saturated_low and error < 0.0):
            return  # integrating would push further into the limit
        if s.ki_position <= 0.0:
            return  # no integral action: do not store a state that a later ki would release
        self.integral += error * self.dt
        self._clamp_integral()
