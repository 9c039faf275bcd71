"""Declaring validated ROS parameters from one table per node (rclpy edge, like ros.py).

Each entry has a type, a default, a range or a set of valid values, a description and whether it
may change at run time. ``ParameterTable.validate`` is the node's on-set callback: a rejected
``ros2 param set`` gets the reason and the node keeps its previous configuration.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Iterable

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)

_TYPES = {bool: ParameterType.PARAMETER_BOOL, int: ParameterType.PARAMETER_INTEGER,
          float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING}


@dataclass(frozen=True)
class Param:
    name: str
    default: Any
    description: str
    minimum: float | None = None
    maximum: float | None = None
    choices: tuple[str, ...] | None = None
    read_only: bool = True

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(name=self.name, type=_TYPES[type(self.default)],
                                description=self.description, read_only=self.read_only)
        if self.minimum is not None and self.maximum is not None:
            if isinstance(self.default, float):
                d.floating_point_range = [FloatingPointRange(
                    from_value=float(self.minimum), to_value=float(self.maximum), step=0.0)]
            elif isinstance(self.default, int) and not isinstance(self.default, bool):
                d.integer_range = [IntegerRange(from_value=int(self.minimum),
                                                to_value=int(self.maximum), step=1)]
        if self.choices:
            d.additional_constraints = 'one of: ' + ', '.join(self.choices)
        return d

    def check(self, value: Any) -> str | None:
        """None if ``value`` is acceptable, else the reason."""
        expected = type(self.default)
        if expected is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if type(value) is not expected:
            return (f'{self.name} must be of type {expected.__name__}, '
                    f'got {type(value).__name__} {value!r}')
        if self.minimum is not None and value < self.minimum:
            return f'{self.name} must be >= {self.minimum:g}, got {value!r}'
        if self.maximum is not None and value > self.maximum:
            return f'{self.name} must be <= {self.maximum:g}, got {value!r}'
        if self.choices is not None and value not in self.choices:
            return f"{self.name} '{value}' is not valid; valid: {', '.join(self.choices)}"
        return None


class ParameterTable:
    def __init__(self, node, params: Iterable[Param]):
        self.node = node
        self.params = {p.name: p for p in params}
        for p in self.params.values():
            node.declare_parameter(p.name, p.default, p.descriptor())
        bad = [reason for p in self.params.values()
               if (reason := p.check(node.get_parameter(p.name).value)) is not None]
        if bad:
            from ato_common.validation import ConfigError
            raise ConfigError('; '.join(bad))
        self.extra_checks: list[Callable[[dict[str, Any]], str | None]] = []
        node.add_on_set_parameters_callback(self._on_set)

    def __getitem__(self, name: str) -> Any:
        return self.node.get_parameter(name).value

    def _on_set(self, parameters) -> SetParametersResult:
        changes = {}
        for parameter in parameters:
            spec = self.params.get(parameter.name)
            if spec is None:
                continue  # use_sim_time and other rclpy parameters
            if spec.read_only:
                return SetParametersResult(successful=False,
                                           reason=f'{spec.name} is fixed at start-up')
            reason = spec.check(parameter.value)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
            changes[parameter.name] = parameter.value
        for check in self.extra_checks:
            reason = check(changes)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)


#: Every node of the loop: its first output also waits for the readers of its /diagnostics (a
#: run monitor). DDS matches each topic separately, so a monitor matched on a node's main
#: output may still be matching on /diagnostics, and a status sent once (the profile's plan)
#: would be lost to it.
WAIT_FOR_DIAGNOSTICS_READERS = Param(
    'wait_for_diagnostics_readers', 0, 'lockstep: observers of /diagnostics besides the '
    'recorders (e.g. the run monitor of run_scenario): nothing is published before '
    '/diagnostics has these and wait_for_recorders subscribers', minimum=0, maximum=100)
