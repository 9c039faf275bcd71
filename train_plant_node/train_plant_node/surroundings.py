"""What the plant models see of the scenario's ``plant:`` section during one integration step.

The simulation splits its steps at every scheduled time (mode switches by time, abrupt changes,
failures, jumps of a random disturbance), so within a step the mode, an abrupt change and the
actuator forces are constant; the slowly varying resistance and the disturbance d(t) are
continuous functions of time that the integrators evaluate at their stage times (a random
disturbance is piecewise constant: the models hold its value in the middle of the step).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ato_common.plant_setup import Disturbance, Mode, PlantSetup, ResistanceVariation, Sinusoid
from ato_common.trains import TrainParameters
from train_plant_node.jit import kernel

# The surroundings as the models' compiled kernels read them: a float array of ENV_SIZE values,
# at an offset inside a model's parameter array (see ``write_parameters`` and ``env_factors``).
HAS_OVERRIDE, OVERRIDE_SINE, RESISTANCE_FACTOR = 0, 1, 2
SINUSOIDS = 3              # (amplitude, omega, phase) of the factors of a, b, c, the line force
DISTURBANCE_KIND = 15      # DISTURBANCE_HELD, _FAST or _SLOW
DISTURBANCE = 16           # amplitude, omega, phase
DISTURBANCE_VALUE = 19     # the held value (a random disturbance: set per step, see below)
ENV_SIZE = 20
DISTURBANCE_HELD, DISTURBANCE_FAST, DISTURBANCE_SLOW = 0.0, 1.0, 2.0


@dataclass(frozen=True)
class Surroundings:
    mode: Mode                    # mass, Davis resistance, extra grade and curve term
    mode_key: int                 # which mode (models cache per-mode matrices under it)
    grade_override_sine: float | None = None   # an abrupt change replaces the line's grade
    resistance_factor: float = 1.0
    variation: ResistanceVariation | None = None
    disturbance: Disturbance | None = None     # None: d = 0

    @property
    def held_disturbance(self) -> bool:
        """d(t) is piecewise constant (random): the simulation splits steps where it jumps."""
        return self.disturbance is not None and self.disturbance.kind == 'random'

    def write_parameters(self, out: np.ndarray, offset: int) -> None:
        """Write the kernels' view of these surroundings into ``out[offset:offset+ENV_SIZE]``;
        a random disturbance's value is the caller's to write, per step."""
        values = np.zeros(ENV_SIZE)
        if self.grade_override_sine is not None:
            values[HAS_OVERRIDE], values[OVERRIDE_SINE] = 1.0, self.grade_override_sine
        values[RESISTANCE_FACTOR] = self.resistance_factor
        variation = self.variation
        if variation is not None:
            for k, sinusoid in enumerate((variation.a, variation.b, variation.c, variation.line)):
                if sinusoid is not None:
                    values[SINUSOIDS + 3 * k:SINUSOIDS + 3 * k + 3] = _sinusoid(sinusoid)
        d = self.disturbance
        if d is not None and d.kind in ('fast', 'slow'):
            values[DISTURBANCE_KIND] = DISTURBANCE_FAST if d.kind == 'fast' else DISTURBANCE_SLOW
            values[DISTURBANCE:DISTURBANCE + 3] = (d.amplitude_n, d.omega_rad_per_s, d.phase_rad)
        out[offset:offset + ENV_SIZE] = values

    def factors(self, time_s: float) -> tuple[float, float, float, float, float]:
        """(factor of a, of b, of c, of the line force, disturbance in N) at a time."""
        values = np.zeros(ENV_SIZE)
        self.write_parameters(values, 0)
        if self.disturbance is not None and self.held_disturbance:
            values[DISTURBANCE_VALUE] = self.disturbance.force(time_s)
        return env_factors(values, 0, time_s)


def _sinusoid(s: Sinusoid) -> tuple[float, float, float]:
    return s.amplitude, s.omega_rad_per_s, s.phase_rad


@kernel
def _factor(p, i, time_s):
    """1 + amplitude sin(omega t + phase) (ato_common.plant_setup.Sinusoid.factor)."""
    if p[i] == 0.0:
        return 1.0
    return 1.0 + p[i] * math.sin(p[i + 1] * time_s + p[i + 2])


@kernel
def env_factors(p, offset, time_s):
    """(factor of a, of b, of c, of the line force, disturbance in N) at a time, from the
    parameters written by ``Surroundings.write_parameters`` at ``offset`` of ``p``: Luo & Xu
    eq (34) (the factors, as ResistanceVariation.factors), Liu & Li eq (9) (d(t), as
    Disturbance.force), Tan et al. Section 4.3 (the abrupt change's resistance factor)."""
    r = p[offset + RESISTANCE_FACTOR]
    fa = _factor(p, offset + SINUSOIDS, time_s) * r
    fb = _factor(p, offset + SINUSOIDS + 3, time_s) * r
    fc = _factor(p, offset + SINUSOIDS + 6, time_s) * r
    fl = _factor(p, offset + SINUSOIDS + 9, time_s)
    kind = p[offset + DISTURBANCE_KIND]
    d = offset + DISTURBANCE
    if kind == DISTURBANCE_FAST:
        dist = p[d] * math.sin(p[d + 1] * time_s + p[d + 2])
    elif kind == DISTURBANCE_SLOW:
        dist = -0.5 * p[d] * (1.0 + math.sin(p[d + 1] * time_s + p[d + 2]))
    else:
        dist = p[offset + DISTURBANCE_VALUE]
    return fa, fb, fc, fl, dist


def nominal_mode(train: TrainParameters) -> Mode:
    return Mode('nominal', 0.0, train.mass_kg, train.davis)


def surroundings_at(setup: PlantSetup, train: TrainParameters, time_s: float,
                    position_m: float) -> Surroundings:
    """The surroundings that hold from ``time_s`` until the next scheduled time."""
    if setup.modes:
        index = setup.mode_index(time_s, position_m)
        mode = setup.modes[index]
    else:
        index, mode = 0, nominal_mode(train)
    change = setup.abrupt_change(time_s)
    return Surroundings(
        mode=mode, mode_key=index,
        grade_override_sine=change.grade_sine if change is not None else None,
        resistance_factor=change.resistance_factor if change is not None else 1.0,
        variation=setup.resistance_variation,
        disturbance=setup.disturbance if setup.disturbance.kind != 'none' else None)
