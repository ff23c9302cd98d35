"""Accuracy of a model against a truth (paper Sec. 2.3, Eq. 22) and features of its restoring
force: equilibria, energy barriers, resonance peaks of a transmissibility curve."""

from .._simulate._frequency import resonance_frequencies as resonance_frequencies
from ._metrics import BandCoverage as BandCoverage
from ._metrics import band_coverage as band_coverage
from ._metrics import damping_error as damping_error
from ._metrics import damping_error_map as damping_error_map
from ._metrics import energy_barriers as energy_barriers
from ._metrics import equilibria as equilibria
from ._metrics import restoring_error as restoring_error
