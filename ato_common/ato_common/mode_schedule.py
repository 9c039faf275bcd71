"""Which operating mode of a piecewise-constant plant applies (Mao et al. 2017 Section 4.1).

The one lookup shared by both sides of the line between truth and knowledge: the plant
(:class:`ato_common.plant_setup.PlantSetup`) finds the mode it simulates with it, and the
on-board software (:class:`ato_common.knowledge.TrainKnowledge`) the mode it takes as active
from its measurements. The schedule is line and timetable data, so in this suite the two agree
wherever the measured position is the true one (Mao et al.'s indicators chi_i are known).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass

#: modes start at a time (``from_s``) or at a position (``from_m``: regions of the line)
MODE_SWITCHES = ('time', 'position')


@dataclass(frozen=True)
class ModeSchedule:
    """Mode i applies from ``starts[i]`` (s or m, by ``switch``) until the next start; the first
    start is 0. Fewer than two starts: always mode 0."""

    switch: str = 'time'
    starts: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if self.switch not in MODE_SWITCHES:
            raise ValueError(f"mode switch '{self.switch}' is not valid; valid: "
                             f"{', '.join(MODE_SWITCHES)}")

    def index(self, time_s: float, position_m: float) -> int:
        """Index of the mode active at this time and position; 0 without modes. Region modes
        need a finite position: a NaN one (not measured) raises ValueError."""
        if len(self.starts) < 2:
            return 0
        key = time_s if self.switch == 'time' else position_m
        if not math.isfinite(key):
            raise ValueError(f'mode_index: the {self.switch} must be finite to find the '
                             f'mode, got {key}')
        return max(bisect_right(self.starts, key) - 1, 0)

    def known(self, time_s: float, measured_position_m: float, previous: int) -> int:
        """The mode on-board software takes as active from its measurements: :meth:`index`, or
        ``previous`` while modes switch by position and the position is not measured."""
        if self.switch != 'time' and not math.isfinite(measured_position_m):
            return previous
        return self.index(time_s, measured_position_m)
