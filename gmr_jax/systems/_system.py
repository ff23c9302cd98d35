"""Benchmark systems: a truth model, its stable equilibria, and how it is excited."""

from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._model._model import AbstractMechanicalModel
from .._recordings._noise import add_noise
from .._recordings._recording import Recording
from .._simulate._inputs import BaseChirp
from .._simulate._integrate import Integrator
from .._simulate._simulate import simulate


@dataclass(frozen=True)
class System:
    """A built-in single- or multi-DOF benchmark.

    `equilibria` (n, dof): the stable states data are recorded around; `sweep`: base chirp
    (f0, f1) in Hz over `duration` s; `x_range`, `v_range`: the phase-plane box where restoring
    and damping errors are measured (per DOF for chains); `orders`: library orders
    {"gmr": (r, d), "gmc": (r, d)} used by the paper for this case.

    `designs`: one label per DOF (per element on a `Graph`), the same label for cells of one
    design (`reconstruct(..., designs=system.designs)`); None where every cell is its own.
    Systems on a `Graph` (lattices): `equilibria` are node displacements, `x_range`, `v_range`
    are per element (deformation and its rate), and `drive="force"`: `make_recordings` drives every node with its own multisine force in the
    band `sweep`, not the base."""

    name: str
    truth: AbstractMechanicalModel
    equilibria: np.ndarray
    sweep: tuple[float, float]
    duration: float
    fs: float
    x_range: np.ndarray
    v_range: np.ndarray
    orders: dict = field(default_factory=dict)
    description: str = ""
    units: tuple = ("x", "v", "F")
    designs: np.ndarray | None = None
    drive: str = "base"


@eqx.filter_jit
def _sweep_responses(model, exc, ts, x0s):
    d = model.n_dof
    sols = jax.vmap(lambda x0: simulate(model, exc, ts, x0, integrator=Integrator(), throw=False))(x0s)
    xs, vs = sols.value
    base = jax.vmap(lambda t: exc(t)[0])(ts)

    def absolute_acc(x, v):
        xdd = jax.vmap(lambda x, v, b: model.accelerations(x, v, b, jnp.zeros(d)))(x, v, base)
        return model.absolute_accelerations(xdd, base)

    return xs, vs, jax.vmap(absolute_acc)(xs, vs), base


def make_recordings(
    system: System,
    amplitude: float,
    *,
    snr_db: float | None = 60.0,
    seed: int = 0,
    duration: float | None = None,
) -> list[Recording]:
    """Base-sweep recordings around each equilibrium of `system` (paper Figs. 4e, 7d, 8e).

    Starts at rest at each equilibrium; sweeps the base displacement with amplitude
    `amplitude` from `sweep[0]` to `sweep[1]` Hz; records x, v and the absolute acceleration a
    of every mass, and the base acceleration, at `fs` Hz, each with white noise at `snr_db`
    (None: noise-free). All equilibria are simulated in one vmapped solve.

    A force-driven lattice (`drive="force"`): every node gets its own random-phase multisine
    force over the band `sweep` (flat spectrum), scaled per configuration so that the linearised
    response's largest RMS element deformation is `amplitude` (x units); the recordings carry
    the node forces `force` (N, D) instead of `base_acc`."""
    if system.drive == "force":
        from ._lattice import force_recordings

        return force_recordings(system, amplitude, snr_db=snr_db, seed=seed, duration=duration)
    duration = duration or system.duration
    model = system.truth
    d = model.n_dof
    ts = jnp.arange(int(round(duration * system.fs)) + 1) / system.fs
    exc = BaseChirp(jnp.asarray(amplitude, float), system.sweep[0], system.sweep[1], duration, n_dof=d)
    x0s = jnp.asarray(system.equilibria, float).reshape(-1, d)
    xs, vs, a, base = (np.asarray(z) for z in _sweep_responses(model, exc, ts, x0s))
    if not np.all(np.isfinite(xs)):
        raise RuntimeError(f"{system.name}: the truth simulation failed at amplitude {amplitude}")
    rng = np.random.default_rng(seed)
    recs = []
    for i in range(x0s.shape[0]):
        sig = {"x": xs[i], "v": vs[i], "a": a[i], "base_acc": base}
        if snr_db is not None:
            sig = {k: add_noise(s, snr_db, rng) for k, s in sig.items()}
        recs.append(Recording(t=np.asarray(ts), masses=np.asarray(model.masses),
                              name=f"{system.name}_S{i + 1}", **sig))
    return recs
