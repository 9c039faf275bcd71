"""Which law can drive which scenario, on which plant, at which control rate: what a comparison,
a campaign and the launchers decide before a run starts, so that a law that cannot drive its
plant is refused with the reason instead of running.
"""

from __future__ import annotations

import math

from ato_common.knowledge import knowledge_of
from ato_common.scenario import Scenario
from ato_controller_node.laws import LAWS


def plant_model_for(scenario: Scenario) -> str:
    """The plant model a scenario needs: the multi-car model for a train of cars, else the
    single mass."""
    return 'multi_car' if scenario.train.cars else 'point_mass'


def failed_measurement(law: str, scenario: Scenario, model: str) -> str:
    """Why the scenario's plant fails a measurement the law requires ('' if it does not)."""
    lead = scenario.train.cars[0].name if model == 'multi_car' else 'train'
    for quantity in LAWS[law].requires:
        sensor = getattr(scenario.plant.sensors, quantity.removeprefix('car_').rstrip('s'))
        if math.isinf(sensor.failed_from_s) or math.isfinite(sensor.failed_until_s):
            continue  # never fails, or only for a while (the run then shows the held steps)
        if quantity.startswith('car_') or not sensor.failed_cars or lead in sensor.failed_cars:
            return (f'{law} needs the measured {quantity.replace("_", " ")}, which the plant\'s '
                    f'sensor fails from {sensor.failed_from_s:g} s')
    return ''


#: control rates tried, in order, for a law that refuses the scenario's rate
FASTER_RATES_HZ = (200.0, 1000.0, 10000.0)


def measured_cars(scenario: Scenario, model: str) -> int:
    """The cars whose measurements a plant of ``model`` publishes for ``scenario``."""
    return len(scenario.train.cars) if model == 'multi_car' else 1


def applicable_rate(law: str, scenario: Scenario, model: str | None = None,
                    rate_hz: float | None = None) -> tuple[float | None, str]:
    """(control rate, '') at which ``law`` runs on ``scenario``: the scenario's, else the first
    of FASTER_RATES_HZ its sampled-time design accepts; (None, reason) if it does not apply.
    ``model``: the plant model the law is given (default the scenario's, ``plant_model_for``);
    ``rate_hz``: a rate asked for, the only one tried."""
    knowledge = knowledge_of(scenario)
    model = model or plant_model_for(scenario)
    cars = measured_cars(scenario, model)
    rate = rate_hz or scenario.run.controller_rate_hz
    failed = failed_measurement(law, scenario, model)
    if failed:
        return None, failed
    reason = LAWS[law](knowledge, 1.0 / rate).fits(knowledge, cars)
    if not reason or rate_hz:
        return (None, reason) if reason else (rate, '')
    for faster in FASTER_RATES_HZ:
        if faster > rate and not LAWS[law](knowledge, 1.0 / faster).fits(knowledge, cars):
            return faster, ''
    return None, reason
