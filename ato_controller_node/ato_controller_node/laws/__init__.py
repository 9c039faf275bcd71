"""Registry of control laws: the ``controller`` parameter names one of these."""

from __future__ import annotations

from ato_controller_node.laws.base import ControlLaw
from ato_controller_node.laws.liu_li import LiuLiLaw
from ato_controller_node.laws.luo_xu import LuoXuLaw, LuoXuProjectionLaw
from ato_controller_node.laws.mao_2017 import Mao2017Law
from ato_controller_node.laws.mao_multibody import MaoAdaptiveLaw, MaoNominalLaw
from ato_controller_node.laws.mao_rigid import MaoRigidLaw
from ato_controller_node.laws.pid import PidLaw
from ato_controller_node.laws.tan import (
    SecondLevelAdaptiveLaw,
    SecondLevelFixedLaw,
    SwitchingMultipleModelLaw,
    WeightedMultipleModelLaw,
)

LAWS: dict[str, type[ControlLaw]] = {law.name: law for law in (
    PidLaw, LuoXuLaw, LuoXuProjectionLaw, Mao2017Law, MaoNominalLaw, MaoAdaptiveLaw, MaoRigidLaw,
    LiuLiLaw,
    SecondLevelFixedLaw, SecondLevelAdaptiveLaw, SwitchingMultipleModelLaw,
    WeightedMultipleModelLaw)}


def law_class(name: str) -> type[ControlLaw]:
    try:
        return LAWS[name]
    except KeyError:
        raise KeyError(f"unknown controller '{name}'; valid: {', '.join(sorted(LAWS))}") from None
