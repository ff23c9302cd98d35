"""gmr_jax: global model reconstruction of multi-stable structures from local small vibrations.

Importing gmr_jax enables JAX float64 (`jax_enable_x64`): the numerics need it.
"""

from . import _config as _config  # noqa: F401  (enables x64 first)
from ._config import use_cpu_cores as use_cpu_cores
from ._errors import GMRInputError as GMRInputError
from ._reconstruct import (
    DEFAULT_SOLVER as DEFAULT_SOLVER,
    Reconstruction as Reconstruction,
    gmc_sindy as gmc_sindy,
    reconstruct as reconstruct,
    regression_targets as regression_targets,
)
from ._solution import RESULTS as RESULTS, Solution as Solution
from .coordination._coordinate import GlobalCoefficients as GlobalCoefficients, coordinate as coordinate
from .coordination._hermite import hermite_interpolate as hermite_interpolate
from .coordination._gls import hermite_gls as hermite_gls
from .local._library import Library as Library
from .local._local_fit import AutoThreshold as AutoThreshold, LocalFit as LocalFit, fit_local as fit_local
from .local._stls import STLS as STLS, stls as stls
from .local._threshold import select_threshold as select_threshold
from .model._io import load_model as load_model, save_model as save_model
from .model._model import (
    AbstractMechanicalModel as AbstractMechanicalModel,
    GlobalModel as GlobalModel,
    from_terms as from_terms,
)
from .recordings._derivatives import differentiate as differentiate
from .recordings._noise import add_noise as add_noise
from .recordings._recording import (
    Recording as Recording,
    load_recording as load_recording,
    save_recording as save_recording,
)
from .simulate._inputs import (
    AbstractInput as AbstractInput,
    BaseChirp as BaseChirp,
    BaseSine as BaseSine,
    HalfSineBase as HalfSineBase,
    HalfSineTip as HalfSineTip,
    NoInput as NoInput,
    Sampled as Sampled,
)
from .simulate._simulate import Integrator as Integrator, simulate as simulate
from .basins._sweep import BasinMap as BasinMap, SweepSettings as SweepSettings, basin_map as basin_map
from .basins._wells import stable_wells as stable_wells
from .metrics._metrics import (
    damping_error as damping_error,
    damping_error_map as damping_error_map,
    energy_barriers as energy_barriers,
    restoring_error as restoring_error,
)
from .actuate._actuate import (
    Actuation as Actuation,
    ActuateRESULTS as ActuateRESULTS,
    ActuateSettings as ActuateSettings,
    actuate as actuate,
)
from .simulate._frequency import (
    resonance_frequencies as resonance_frequencies,
    resonance_peaks as resonance_peaks,
    transmissibility as transmissibility,
)
from .systems._kresling import (
    KreslingCell as KreslingCell,
    KreslingChain as KreslingChain,
    cell_equilibria as cell_equilibria,
    kresling3 as kresling3,
    kresling5 as kresling5,
    kresling_chain as kresling_chain,
)
from .systems._paper_cases import bistable_joint as bistable_joint, tristable_nes as tristable_nes
from .systems._system import System as System, make_recordings as make_recordings
from .discover._discover import DiscoveryReport as DiscoveryReport, discover as discover
from .discover._catalogue import Term as Term, default_catalogue as default_catalogue
from .discover._select import SelectionRule as SelectionRule
from .refine._refine import RefineSettings as RefineSettings, refine as refine
from .refine._shooting import output_error as output_error

__version__ = "0.1.0"
