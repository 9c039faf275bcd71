"""Small typed records exchanged between the cores; the ROS messages are converted to and from
these in :mod:`ato_ros`. All quantities in SI; time stamps in integer nanoseconds so that
lockstep time is exact."""

from __future__ import annotations

from dataclasses import dataclass

NS_PER_S = 1_000_000_000


def seconds(stamp_ns: int) -> float:
    return stamp_ns / NS_PER_S


def nanoseconds(time_s: float) -> int:
    return int(round(time_s * NS_PER_S))


@dataclass(frozen=True)
class TrainState:
    """Position (m along the line), speed (m/s), acceleration (m/s^2) and applied longitudinal
    force (N, traction positive, braking negative) of every car, lead car first."""

    stamp_ns: int
    car_names: tuple[str, ...]
    positions: tuple[float, ...]
    speeds: tuple[float, ...]
    accelerations: tuple[float, ...]
    forces: tuple[float, ...]


@dataclass(frozen=True)
class ReferencePoint:
    """The target at ``time_s``: x*, v*, a* and the jerk a*' (some laws need v*'', e.g.
    Mao et al. eq 51; the reference is piecewise-constant jerk, so it is exact)."""

    time_s: float
    position: float
    speed: float
    acceleration: float
    jerk: float = 0.0


@dataclass(frozen=True)
class Reference:
    """The target at ``stamp_ns`` (``points[0]``) followed by a short preview."""

    stamp_ns: int
    points: tuple[ReferencePoint, ...]

    @property
    def now(self) -> ReferencePoint:
        return self.points[0]


@dataclass(frozen=True)
class Command:
    """Force per actuated unit (N; traction positive, braking negative) and the law behind it."""

    stamp_ns: int
    actuator_names: tuple[str, ...]
    forces: tuple[float, ...]
    law: str
