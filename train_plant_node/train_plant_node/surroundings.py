"""What the plant models see of the scenario's ``plant:`` section during one integration step.

The simulation splits its steps at every scheduled time (mode switches by time, abrupt changes,
failures, jumps of a random disturbance), so within a step the mode, an abrupt change and the
actuator forces are constant; the slowly varying resistance and the disturbance d(t) are
continuous functions of time that the integrators evaluate at their stage times.
"""

from __future__ import annotations

from dataclasses import dataclass

from ato_common.plant_setup import Disturbance, Mode, PlantSetup, ResistanceVariation
from ato_common.trains import TrainParameters


@dataclass(frozen=True)
class Surroundings:
    mode: Mode                    # mass, Davis resistance, extra grade and curve term
    mode_key: int                 # which mode (models cache per-mode matrices under it)
    grade_override_sine: float | None = None   # an abrupt change replaces the line's grade
    resistance_factor: float = 1.0
    variation: ResistanceVariation | None = None
    disturbance: Disturbance | None = None     # None: d = 0

    @property
    def time_varying(self) -> bool:
        return self.variation is not None or self.disturbance is not None

    def factors(self, time_s: float) -> tuple[float, float, float, float, float]:
        """(factor of a, of b, of c, of the line force, disturbance in N) at a time."""
        fa, fb, fc, fl = (self.variation.factors(time_s) if self.variation is not None
                          else (1.0, 1.0, 1.0, 1.0))
        r = self.resistance_factor
        d = self.disturbance.force(time_s) if self.disturbance is not None else 0.0
        return fa * r, fb * r, fc * r, fl, d


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
