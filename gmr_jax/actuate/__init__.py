"""Actuation design: the cheapest tip load that deploys a chain into a target configuration."""

from ._actuate import (
    Actuation as Actuation,
    ActuateRESULTS as ActuateRESULTS,
    ActuateSettings as ActuateSettings,
    actuate as actuate,
    terminal_margin_half_sine as terminal_margin_half_sine,
)
from ._surrogate import parse_target as parse_target
