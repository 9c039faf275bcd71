"""Many control periods of a :class:`~train_plant_node.simulation.TrainSimulation` at once:
``run_commands`` holds each row of a table of commands for one period, compiled where it can be
(``periods.py``), period by period through the simulation's interface elsewhere, with the same
result to the last bit. For open-loop runs: commands from a file, identification, Monte Carlo.

The compiled path applies where ``advance`` would take its one-step path with nothing switching:
instant actuators, constant surroundings (no modes, no abrupt change), no failure active, one
integration step per period, no safety function acting, no dwell, and the ATP's odometer exact
and working (the odometry's estimate is the truth, its interval the declared accuracy since the
last balise group, as the kernels take it). Everything else (a scheduled time, a failure, a
period in which a car of the multi-car model crosses a line boundary, an intervention, a stop)
runs period by period.
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ato_common.braking_curves import RunSupervision
from ato_common.types import NS_PER_S, TrainState
from train_plant_node.actuators import EVENT_TOLERANCE_S, CommandRejected


@dataclass(frozen=True)
class Trajectory:
    """The truth after each control period of :func:`run_commands`: row k is what ``truth()``
    returns after the k-th period (columns: the cars, lead car first)."""

    car_names: tuple[str, ...]
    stamps_ns: np.ndarray          # (periods,) int64
    positions: np.ndarray          # (periods, cars), m
    speeds: np.ndarray             # m/s
    accelerations: np.ndarray      # m/s^2
    forces: np.ndarray             # applied longitudinal force per car, N
    atp_intervention: np.ndarray   # (periods,) bool: the ATP's emergency brake after the period

    def __len__(self) -> int:
        return len(self.stamps_ns)

    def state(self, k: int) -> TrainState:
        return TrainState(int(self.stamps_ns[k]), self.car_names,
                          tuple(self.positions[k].tolist()), tuple(self.speeds[k].tolist()),
                          tuple(self.accelerations[k].tolist()), tuple(self.forces[k].tolist()))


def checked_commands(commands, names: tuple[str, ...], period_ns) -> tuple[np.ndarray, int]:
    """The commands as a (periods, actuators) array of finite forces and the period as an int;
    CommandRejected naming the row (or ValueError for the period) otherwise."""
    try:
        forces = np.array(commands, dtype=float, ndmin=2)
    except (TypeError, ValueError) as error:
        raise CommandRejected(f'commands must be a table of forces: {error}') from None
    if forces.ndim != 2 or forces.shape[1] != len(names):
        raise CommandRejected(f'commands of shape {forces.shape}: need one row per period '
                              f'of {len(names)} forces {list(names)}')
    finite = np.isfinite(forces).all(axis=1)
    if not finite.all():
        row = int(np.argmin(finite))
        raise CommandRejected(f'row {row}: non-finite force in {forces[row].tolist()}')
    if isinstance(period_ns, bool) or not isinstance(period_ns, (int, np.integer)) \
            or period_ns <= 0:
        raise ValueError(f'period_ns must be a positive integer, got {period_ns!r}')
    return forces, int(period_ns)


def run_commands(sim, commands, period_ns: int) -> Trajectory:
    """Hold each row of ``commands`` for one control period of ``sim``: the same as
    ``apply_command(row)``, ``advance(period_ns)`` and ``truth()`` for each row, to the last
    bit (module docstring). The sensors are not sampled on the way (``measured()`` afterwards
    reads the final state).

    Every row is checked before the first period: a wrong shape or a non-finite force raises
    CommandRejected naming the row, and the simulation is left as it was."""
    forces, period_ns = checked_commands(commands, sim.actuator_names, period_ns)
    periods, cars = len(forces), len(sim.model.car_names)
    stamps = sim.stamp_ns + period_ns * np.arange(1, periods + 1, dtype=np.int64)
    quantities = [np.empty((periods, cars)) for _ in range(4)]
    interventions = np.empty(periods, dtype=bool)
    rows = None  # the commands as lists of floats, once some periods run one by one
    k = 0
    while k < periods:
        batch = compiled_periods(sim, periods - k, period_ns)
        if batch:
            done = run_compiled(sim, forces[k:k + batch], period_ns,
                                [q[k:k + batch] for q in quantities], interventions[k:k + batch])
            k += done
            if done:
                continue
        end = k  # then at least one period by the interface
        outputs, held = [], []
        rows = rows or forces.tolist()
        while end < periods and (end == k or not compiled_periods(sim, 1, period_ns)):
            sim.apply_command(rows[end])  # checked above
            sim.advance(period_ns)
            truth = sim.truth()
            outputs.append((truth.positions, truth.speeds, truth.accelerations, truth.forces))
            held.append(sim.atp_intervention)
            end += 1
        for q, values in zip(quantities, zip(*outputs)):
            q[k:end] = values
        interventions[k:end] = held
        k = end
    positions, speeds, accelerations, forces_out = quantities
    return Trajectory(sim.model.car_names, stamps, positions, speeds, accelerations, forces_out,
                      interventions)


def compiled_periods(sim, wanted: int, period_ns: int) -> int:
    """How many of the next ``wanted`` periods ``periods.py``'s kernels may run: those in
    which ``advance`` would take its one-step path with nothing switching, and that end
    before the next scheduled time, so that no failure acts at any of them."""
    # Imported here: it loads every model's module, which a node of one model need not.
    from train_plant_node.periods import period_kernel
    if not (sim._one_step_possible and sim._constant_env and sim._exact_odometry
            and period_kernel(sim.model) is not None
            and period_ns / NS_PER_S <= sim.model.max_substep_s):
        return 0
    if sim.actuators.failures and sim.actuators.active(sim.time_s) or \
            sim.sensors.odometer_failed(sim.time_s):
        return 0
    if sim.emergency_brake or sim.missed_periods or sim.atp.holding_brake:
        return 0  # braking, or dwelling at a stop: period by period
    standing = getattr(sim.model, 'standing', None)
    if standing is not None and standing(sim.state):
        return 0  # a train at rest: the model's ``step`` holds it (the kernels do not)
    events = sim.events
    i = bisect_right(events, sim.time_s + EVENT_TOLERANCE_S)
    if i == len(events):
        return wanted
    before = events[i] - EVENT_TOLERANCE_S
    count = max(0, int((before - sim.time_s) * NS_PER_S / period_ns))
    while count > 0 and (sim.stamp_ns + count * period_ns) / NS_PER_S >= before:
        count -= 1
    while count < wanted and (sim.stamp_ns + (count + 1) * period_ns) / NS_PER_S < before:
        count += 1
    return min(count, wanted)


@lru_cache(maxsize=8)
def packed_supervision(run: RunSupervision) -> tuple:
    """The ATP's tables of a run for the kernels: every leg's sampled EBI, and the ceiling of
    the EBI section by section (the same for every leg: the line's MRSP)."""
    starts, ceilings = run.legs[0].ceiling('ebi')
    return (*run.packed_curve('ebi'), np.array(starts, dtype=float),
            np.array(ceilings, dtype=float))


@lru_cache(maxsize=8)
def groups_array(groups: tuple[float, ...]) -> np.ndarray:
    """A run's balise groups ahead of its start as the kernels take them."""
    return np.array(groups, dtype=float)


def run_compiled(sim, forces: np.ndarray, period_ns: int, out: list[np.ndarray],
                 interventions: np.ndarray) -> int:
    """Up to ``len(forces)`` periods in ``periods``' kernel; returns how many ran."""
    from train_plant_node.periods import period_kernel
    atp = sim.atp
    offsets, positions, speeds, starts, ceilings = packed_supervision(sim.supervision)
    low, high = sim.supervision.stop_zone(atp.leg)
    odometry = sim.odometry
    accuracy = ((0.0, 0.0, 0.0, 0.0) if odometry.exact_accuracy else
                (odometry.location_accuracy_m, odometry.odometry_accuracy,
                 odometry.speed_accuracy_mps, odometry.speed_accuracy_share))
    tables = (np.int64(atp.leg), low, high, sim.supervision.STANDSTILL_MPS, offsets, positions,
              speeds, atp.acceleration_mps2, starts, ceilings, *accuracy,
              groups_array(odometry.groups_ahead_m))
    traction = sim.scenario.train.traction
    state = np.array(sim.state, dtype=float)
    done, intervention, began, previous = period_kernel(sim.model)(
        state, sim.stamp_ns, period_ns, forces,
        (traction.max_traction_force_n, traction.max_traction_power_w,
         traction.max_emergency_brake_force_n), tables, atp.previous_speed_mps,
        atp.emergency_brake, odometry.fix_m, np.int64(odometry.passed), *out, interventions,
        sim.model.kernel_inputs(sim.surroundings(), period_ns / NS_PER_S))
    if done:
        sim.state = state
        sim.stamp_ns += period_ns * done
        odometry.exact(float(state[0]), sim.model.lead_speed(state))
        atp.previous_speed_mps = previous
        if began:
            atp.begin(odometry)
        atp.emergency_brake = bool(intervention)
        atp.track_stop(sim.time_s, odometry)
        sim.apply_command(forces[done - 1].tolist())
    return done
