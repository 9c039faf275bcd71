"""Compile every plant kernel into numba's on-disk cache: ``python -m train_plant_node.warmup``.

``scripts/setup.sh`` runs it after a build, so that no node start or test process pays the
compilation (tens of seconds). It lives apart from :mod:`train_plant_node.jit`, the decorator
module every kernel imports, because it drives the whole simulation.
"""

from __future__ import annotations

import dataclasses

from ato_common.scenario import load_scenario
from ato_common.trains import train_preset
from train_plant_node.simulation import TrainSimulation


def compile_kernels() -> None:
    """Run both plant models through their period interface and ``run_commands``."""
    scenario = load_scenario('short_line')
    for model, train in (('point_mass', scenario.train),
                         ('multi_car', train_preset('crh2_4car_mao'))):
        sim = TrainSimulation(dataclasses.replace(scenario, train=train), model)
        sim.run_commands([[0.0] * len(sim.actuator_names)] * 2, 100_000_000)  # periods.py


if __name__ == '__main__':
    compile_kernels()
