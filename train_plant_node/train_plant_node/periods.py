"""Many control periods of the plant in one compiled call.

:func:`train_plant_node.batch.run_commands` defines the result: for each row of commands,
``apply_command`` then ``advance`` by one period, then ``truth``. Per period that path costs
several microseconds of Python around a compiled physics step of one or two (the actuator
limits, the ATP's check, the state snapshot), so a plant driven from Python cannot run much
faster than 10,000x real time at 10 Hz. These kernels do the same work per period in compiled
code: the actuator limits (``Actuators.targets``), the integration (the models' step kernels),
the ATP's anticipated check (``OnboardATP.over_speed`` with ``SampledLimit`` look-ups, on the
odometry of an exact odometer with its declared interval, ``Odometry.exact``) and the truth (the
models' ``outputs``), in the same floating-point operations in the same order, so that both
paths give the same numbers to the last bit (the tests check this). The simulation uses them
only where that holds (``batch.compiled_periods``).
"""

from __future__ import annotations

import numpy as np

from train_plant_node.atp import ACCELERATION_CAP_MPS2
from train_plant_node.jit import kernel
from train_plant_node.models.multi_car import (
    CAR_ACTUATOR,
    MultiCarModel,
    outputs_kernel,
    substep_kernel,
)
from train_plant_node.models.point_mass import PointMassModel, acceleration_kernel, step_kernel


@kernel
def exact_sum(values, count, partials):
    """``math.fsum(values[:count])``: the correctly rounded sum (Shewchuk's algorithm with
    CPython's final half-even correction), so that the compiled and the Python paths agree to
    the last bit. ``partials`` is scratch space of at least ``count`` floats."""
    used = 0
    for k in range(count):
        x = values[k]
        i = 0
        for j in range(used):
            y = partials[j]
            if abs(x) < abs(y):
                x, y = y, x
            hi = x + y
            lo = y - (hi - x)
            if lo != 0.0:
                partials[i] = lo
                i += 1
            x = hi
        partials[i] = x
        used = i + 1
    if used == 0:
        return 0.0
    n = used - 1
    hi = partials[n]
    lo = 0.0
    while n > 0:
        x = hi
        n -= 1
        y = partials[n]
        hi = x + y
        lo = y - (hi - x)
        if lo != 0.0:
            break
    if n > 0 and ((lo < 0.0 and partials[n - 1] < 0.0) or (lo > 0.0 and partials[n - 1] > 0.0)):
        y = lo * 2.0
        x = hi + y
        if y == x - hi:
            hi = x
    return hi


@kernel
def limit_at(leg, offsets, positions, speeds, position):
    """``RunSupervision.sampled_curve`` on one curve's tables packed by
    ``RunSupervision.packed_curve``: the leg's ``SampledLimit``."""
    first, end = offsets[leg], offsets[leg + 1]
    i = np.searchsorted(positions[first:end], position, side='right')
    if i == 0:
        return speeds[first]
    if i == end - first:
        return speeds[end - 1] if position == positions[end - 1] else 0.0
    x0, x1 = positions[first + i - 1], positions[first + i]
    v0, v1 = speeds[first + i - 1], speeds[first + i]
    return v0 + (v1 - v0) * (position - x0) / (x1 - x0)


@kernel
def actuator_targets(out, commanded, speed, intervention, max_force_n, max_power_w,
                     emergency_brake_n):
    """``Actuators.targets`` with the watchdog quiet (every period has a command): each
    unit's share of the traction characteristic and of the emergency brake; under an
    intervention traction is cut (the kernels stop at its first period, where the emergency
    brake has not built up yet)."""
    count = commanded.size
    share = 1.0 / count
    lowest = -emergency_brake_n * share
    if intervention:
        for i in range(count):
            out[i] = 0.0
        return
    v = abs(speed)
    highest = (max_force_n if v <= 0.0 else min(max_force_n, max_power_w / v)) * share
    for i in range(count):
        f = commanded[i]
        out[i] = lowest if f < lowest else highest if f > highest else f


@kernel
def exact_odometry(atp, position, speed, fix, passed):
    """``Odometry.exact`` with a declared accuracy: the balise groups passed, the half-width of
    the confidence interval and the speed's upper end. Returns (half-width, upper speed, the
    last group passed or the start, how many groups passed)."""
    location, odometry, speed_m, speed_share, groups = atp[10], atp[11], atp[12], atp[13], atp[14]
    i = np.searchsorted(groups, position, side='right')
    if i > passed:
        passed = i
        fix = groups[i - 1]
    half = location + odometry * abs(position - fix)
    accuracy = speed_m + speed_share * abs(speed) if speed != 0.0 else 0.0
    return half, speed + accuracy, fix, passed


@kernel
def supervise(atp, position, speed, previous_speed, period_s, intervention, half, upper):
    """``OnboardATP.cycle`` on an exact odometry (front ``position`` +/- ``half``, speed
    ``speed`` up to ``upper``) from a period without an intervention (the kernels stop at the
    first period of one): ``OnboardATP.over_speed`` in the same operations. Returns
    (intervention after this period, 1 if one began)."""
    leg, offsets, positions, speeds, highest, starts, ceilings = \
        atp[0], atp[4], atp[5], atp[6], atp[7], atp[8], atp[9]
    if intervention:
        return intervention, 0
    measured = (speed - previous_speed) / period_s
    a = max(highest, min(measured, ACCELERATION_CAP_MPS2))
    ahead = (position + half) + upper * period_s + 0.5 * a * period_s * period_s
    limit = limit_at(leg, offsets, positions, speeds, ahead)
    first = np.searchsorted(starts, position - half, side='right') - 1
    last = np.searchsorted(starts, ahead, side='right') - 1
    if last > first:
        for i in range(max(first, 0), last + 1):
            limit = min(limit, ceilings[i])
    if upper + a * period_s > limit:
        return True, 1
    return False, 0


@kernel
def at_stop(atp, position, speed, half):
    """``OnboardATP.track_stop``'s zone for the leg, with the confidence interval: the kernels
    stop there (the dwell is counted period by period)."""
    low, high, standstill = atp[1], atp[2], atp[3]
    return abs(speed) <= standstill and position + half >= low and position - half <= high


# The kernels below share one signature: the state (updated in place), the time, the commands
# (one row per period), the traction limits (force N, power W, emergency brake N), the ATP's
# packed tables (``batch.packed_supervision``) and its odometry's declared accuracy and balise
# groups ahead (``batch.run_compiled``), the speed the ATP saw at its last cycle, its
# intervention state, the odometry's last balise group (or start) and how many it passed, the
# truth per period (positions, speeds, accelerations, forces: one
# column per car; the ATP's state), and the model's own inputs (``kernel_inputs`` of the
# model). They return how many periods they ran (fewer than asked where the interface would
# have split a step), the intervention state, how many began and the ATP's last speed.

@kernel
def run_point_mass_periods(state, stamp_ns, period_ns, commands, traction, atp, previous,
                           intervention, fix, passed, out_positions, out_speeds,
                           out_accelerations, out_forces, out_intervention, model):
    p, table, work, max_substep_s = model
    max_force_n, max_power_w, emergency_brake_n = traction
    count = commands.shape[1]
    forces = np.empty(count)
    scratch = np.empty(count + 1)
    duration_s = period_ns / 1_000_000_000
    position, speed = state[0], state[1]
    began = 0
    for k in range(commands.shape[0]):
        row = commands[k]
        actuator_targets(forces, row, speed, intervention, max_force_n, max_power_w,
                         emergency_brake_n)
        time_s = stamp_ns / 1_000_000_000
        position, speed = step_kernel(p, table, work, position, speed, time_s, duration_s,
                                      max_substep_s, exact_sum(forces, count, scratch))
        stamp_ns += period_ns
        half, upper, fix, passed = exact_odometry(atp, position, speed, fix, passed)
        intervention, new = supervise(atp, position, speed, previous, duration_s, intervention,
                                      half, upper)
        previous = speed
        began += new
        # The truth holds the forces for the new state: the ATP's decision, the same command.
        actuator_targets(forces, row, speed, intervention, max_force_n, max_power_w,
                         emergency_brake_n)
        force = exact_sum(forces, count, scratch)
        out_positions[k, 0] = position
        out_speeds[k, 0] = speed
        out_accelerations[k, 0] = acceleration_kernel(p, table, position, speed, force,
                                                      stamp_ns / 1_000_000_000)
        out_forces[k, 0] = force
        out_intervention[k] = intervention
        if intervention or at_stop(atp, position, speed, half):
            state[0], state[1] = position, speed
            return k + 1, intervention, began, previous
    state[0], state[1] = position, speed
    return commands.shape[0], intervention, began, previous


@kernel
def run_multi_car_periods(state, stamp_ns, period_ns, commands, traction, atp, previous,
                          intervention, fix, passed, out_positions, out_speeds,
                          out_accelerations, out_forces, out_intervention, model):
    """``MultiCarModel.step`` when it takes one ETDRK4 step: it stops before a period in which
    a car reaches another line segment (the interface splits that step at the boundary)."""
    props, table, cars, p, linear = model
    max_force_n, max_power_w, emergency_brake_n = traction
    n = state.size // 2
    count = commands.shape[1]
    forces = np.empty(count)
    moved = np.empty(2 * n)
    outputs = np.empty(3 * n)
    duration_s = period_ns / 1_000_000_000
    began = 0
    for k in range(commands.shape[0]):
        row = commands[k]
        actuator_targets(forces, row, state[n], intervention, max_force_n, max_power_w,
                         emergency_brake_n)
        time_s = stamp_ns / 1_000_000_000
        end = time_s + duration_s
        if not end - time_s > duration_s * (1.0 - 1e-9):
            return k, intervention, began, previous  # the interface would step end - time_s
        if substep_kernel(state, moved, time_s, duration_s, props, forces, table, cars, p):
            return k, intervention, began, previous
        if end - (time_s + duration_s) > 1e-12 * max(1.0, abs(end)):
            return k, intervention, began, previous  # the interface would add a sliver
        state[:] = moved
        stamp_ns += period_ns
        half, upper, fix, passed = exact_odometry(atp, state[0], state[n], fix, passed)
        intervention, new = supervise(atp, state[0], state[n], previous, duration_s,
                                      intervention, half, upper)
        previous = state[n]
        began += new
        actuator_targets(forces, row, state[n], intervention, max_force_n, max_power_w,
                         emergency_brake_n)
        outputs_kernel(state, outputs, stamp_ns / 1_000_000_000, linear, forces, table, cars, p)
        for q in range(n):
            out_positions[k, q] = outputs[q]
            out_speeds[k, q] = outputs[n + q]
            out_accelerations[k, q] = outputs[2 * n + q]
            actuator = int(cars[CAR_ACTUATOR, q])
            out_forces[k, q] = forces[actuator] if actuator >= 0 else 0.0
        out_intervention[k] = intervention
        if intervention or at_stop(atp, state[0], state[n], half):
            return k + 1, intervention, began, previous
    return commands.shape[0], intervention, began, previous


def period_kernel(model):
    """The compiled periods of a plant model, or None."""
    if isinstance(model, PointMassModel):
        return run_point_mass_periods
    if isinstance(model, MultiCarModel):
        return run_multi_car_periods
    return None
