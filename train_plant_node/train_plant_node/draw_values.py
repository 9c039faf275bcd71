"""The plant's ``draw_values`` parameter: the drawn values of one draw of a campaign's uncertainty
(``ato_common.uncertainty``), which the plant's truth is perturbed by (pure: no rclpy).

The text is a JSON object of parameter -> value, e.g. ``{"mass_factor": 1.08, "wind_mps":
-2.5}``: each name one of ``ato_common.uncertainty.PLANT_PARAMETERS``, each value a finite
number within that parameter's valid range. A parameter left out keeps its nominal value (the
controller's), so ``{}`` and ``''`` are the nominal plant. A knowledge parameter
(``gradient_known``) is refused here: it changes what the controller is told, never the plant,
and is given to the controller (its ``gradient_known`` parameter). The plant then runs
``perturbed(scenario, values)`` as the offline loop does (``ato_simulation.loop.run_offline``);
the controller keeps the nominal scenario's knowledge.
"""

from __future__ import annotations

import json
import math
from typing import Any, Mapping

from ato_common.uncertainty import KNOWLEDGE_PARAMETERS, PARAMETERS, PLANT_PARAMETERS
from ato_common.validation import ConfigError, as_number, unknown_field_message

#: the parameter's name, in the messages
NAME = 'draw_values'


def _refuse_constant(text: str) -> None:
    raise ValueError(f'{text} is not a number JSON allows')


def parse_draw_values(text: str) -> dict[str, float] | None:
    """The drawn values ``text`` gives, every plant parameter's (the ones left out at their
    nominal values), or None for '' (the nominal plant); ConfigError naming what is wrong: text
    that is not a JSON object, an unknown or a knowledge parameter, a value that is not a
    finite number in the parameter's range."""
    if not text.strip():
        return None
    try:
        data = json.loads(text, parse_constant=_refuse_constant)
    except ValueError as error:  # json.JSONDecodeError is a ValueError
        raise ConfigError(f'{NAME}: not JSON ({error}); give an object of uncertain '
                          'parameters, e.g. {"mass_factor": 1.08}') from None
    if not isinstance(data, dict):
        raise ConfigError(f'{NAME}: must be a JSON object of uncertain parameters, e.g. '
                          f'{{"mass_factor": 1.08}}, got {type(data).__name__} {text.strip()!r}')
    return checked_values(data)


def checked_values(data: Mapping[str, Any]) -> dict[str, float]:
    """Every plant parameter's value: ``data``'s, checked, the others nominal."""
    knowledge = [k for k in data if k in KNOWLEDGE_PARAMETERS]
    if knowledge:
        raise ConfigError(f'{NAME}.{knowledge[0]}: acts on what the controller knows, not on '
                          'the plant; give it to the controller (its gradient_known parameter)')
    unknown = [k for k in data if k not in PARAMETERS]
    if unknown:
        raise ConfigError(f'{NAME}: ' + unknown_field_message(unknown, PLANT_PARAMETERS))
    values = {name: PARAMETERS[name].nominal for name in PLANT_PARAMETERS}
    for name, value in data.items():
        values[name] = _value(name, value)
    return values


def _value(name: str, value: Any) -> float:
    p = PARAMETERS[name]
    number = as_number(value) if not isinstance(value, str) else None
    if number is None or not (math.isfinite(number) and p.minimum <= number <= p.maximum):
        raise ConfigError(f'{NAME}.{name}: must be a finite number in [{p.minimum:g}, '
                          f'{p.maximum:g}] {p.unit}, got {value!r}')
    return number


def draw_values_text(values: Mapping[str, float]) -> str:
    """The ``draw_values`` text of a draw's values (``ato_common.uncertainty.draw``): its plant
    parameters only, in a stable order, every float exactly (JSON keeps the shortest repr that
    reads back to the same double); the knowledge parameters are left out (the controller's)."""
    return json.dumps({name: float(values[name]) for name in PLANT_PARAMETERS if name in values},
                      sort_keys=True)
