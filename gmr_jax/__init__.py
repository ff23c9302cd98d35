"""gmr_jax: global model reconstruction of multi-stable structures from local small vibrations.

The API a notebook uses is this module: recordings -> local fits -> coordination -> global
model -> simulate / basins / refine / actuate / discover. Browsable namespaces:
`gmr_jax.systems` (built-in systems that make data), `gmr_jax.metrics` (accuracy against a
truth), `gmr_jax.data` (the EMPS recordings), `gmr_jax.plots` (figures).

Importing gmr_jax enables JAX float64 (`jax_enable_x64`): the numerics need it; and JAX's
persistent compilation cache in `~/.cache/gmr_jax/xla` (`$GMR_CACHE_DIR`; `use_compilation_cache`).
"""

import importlib.metadata as _metadata

from . import _config as _config  # noqa: F401  (enables x64 first)

# results and errors
from ._config import (
    relieve_map_pressure as relieve_map_pressure,
    use_compilation_cache as use_compilation_cache,
    use_cpu_cores as use_cpu_cores,
)
from ._errors import GMRInputError as GMRInputError
from ._reconstruct._sanity import GMRDataWarning as GMRDataWarning, unit_checks as unit_checks
from ._solution import GMRComputationError as GMRComputationError, RESULTS as RESULTS, Solution as Solution
from ._topology import (
    AbstractTopology as AbstractTopology,
    Chain as Chain,
    Graph as Graph,
    Independent as Independent,
)

# recordings
from ._recordings._derivatives import differentiate as differentiate
from ._recordings._noise import add_noise as add_noise
from ._recordings._recording import (
    Recording as Recording,
    load_recording as load_recording,
    save_recording as save_recording,
)

# local fits (Eqs. 2-8)
from ._fit._library import Library as Library
from ._fit._local_fit import AutoThreshold as AutoThreshold, LocalFit as LocalFit, fit_local as fit_local
from ._fit._stls import STLS as STLS, stls as stls
from ._fit._threshold import select_threshold as select_threshold

# coordination (Eqs. 12-21)
from ._coordination._coordinate import GlobalCoefficients as GlobalCoefficients, coordinate as coordinate
from ._coordination._gls import hermite_gls as hermite_gls
from ._coordination._hermite import hermite_interpolate as hermite_interpolate
from ._model._admissible import inadmissible as inadmissible

# the global model (Eq. 1)
from ._model._io import (
    load_graph as load_graph,
    load_model as load_model,
    save_graph as save_graph,
    save_model as save_model,
)
from ._model._model import (
    AbstractMechanicalModel as AbstractMechanicalModel,
    GlobalModel as GlobalModel,
    from_terms as from_terms,
    to_graph as to_graph,
)
from ._model._predict import forces as forces, predict as predict
from ._model._uncertainty import ForceBand as ForceBand, force_band as force_band, sample_models as sample_models
from ._model._pysindy import from_pysindy as from_pysindy, to_pysindy as to_pysindy

# reconstruction (Algorithm 1) and the GMC-SINDy baseline
from ._reconstruct._reconstruct import gmc_sindy as gmc_sindy, reconstruct as reconstruct
from ._recordings._recording import regression_targets as regression_targets
from ._reconstruct._estimator import (
    ReconstructSettings as ReconstructSettings,
    reconstruct_arrays as reconstruct_arrays,
)

# simulation
from ._simulate._frequency import resonance_peaks as resonance_peaks, transmissibility as transmissibility
from ._simulate._inputs import (
    AbstractInput as AbstractInput,
    BaseChirp as BaseChirp,
    BaseSine as BaseSine,
    HalfSineBase as HalfSineBase,
    HalfSineNodes as HalfSineNodes,
    HalfSineTip as HalfSineTip,
    NoInput as NoInput,
    Sampled as Sampled,
)
from ._simulate._integrate import Integrator as Integrator
from ._simulate._free_run import FreeRun as FreeRun, free_run as free_run
from ._simulate._front import TransitionFront as TransitionFront, transition_front as transition_front
from ._simulate._simulate import simulate as simulate

# basins of deployment (Fig. 11)
from ._basins._sweep import BasinMap as BasinMap, SweepSettings as SweepSettings, basin_map as basin_map
from ._basins._wells import configuration as configuration, stable_wells as stable_wells
from ._basins._probability import BasinProbability as BasinProbability, basin_probability as basin_probability

# refinement on trajectories
from ._refine._refine import RefineSettings as RefineSettings, refine as refine
from ._refine._shooting import OutputError as OutputError, output_error as output_error

# actuation design
from ._actuate._actuate import Actuation as Actuation, ActuateSettings as ActuateSettings, actuate as actuate

# discovery of missing physics
from ._discover._catalogue import Term as Term, default_catalogue as default_catalogue
from ._discover._discover import DiscoveryReport as DiscoveryReport, discover as discover
from ._discover._select import SelectionRule as SelectionRule

# browsable namespaces, imported on first use (`gmr.plots` loads matplotlib, `gmr.systems` and
# `gmr.data` parts of scipy: ~1 s that `gmr fit` on a 2-core machine need not pay at start-up)
_NAMESPACES = ("data", "metrics", "plots", "systems")


def __getattr__(name: str):
    if name in _NAMESPACES:
        import importlib

        module = importlib.import_module(f".{name}", __name__)
        globals()[name] = module
        return module
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_NAMESPACES))


try:
    __version__ = _metadata.version("gmr_jax")
except _metadata.PackageNotFoundError:  # a source tree that was not installed
    __version__ = "0+unknown"

# compiled programs kept on disk between processes (`use_compilation_cache`: the folder, or off)
_config.compilation_cache_on_import()
