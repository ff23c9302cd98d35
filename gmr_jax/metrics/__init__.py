"""Accuracy of a model against a truth (paper Sec. 2.3, Eq. 22) and features of its restoring
force: equilibria, energy barriers, resonance peaks of a transmissibility curve."""

from .._simulate._frequency import resonance_frequencies as resonance_frequencies
from ._metrics import (
    damping_error as damping_error,
    damping_error_map as damping_error_map,
    energy_barriers as energy_barriers,
    equilibria as equilibria,
    restoring_error as restoring_error,
)
