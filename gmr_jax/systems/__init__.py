"""Built-in systems that make data: the paper's single-DOF cases, Kresling truss chains and
non-polynomial single-DOF bistables (a shallow arch, a magnetic oscillator), lattices of
bistable elements on a graph (a ladder, a grid, a grounded ladder that carries transition waves).

Each factory returns a `System` (truth model, stable equilibria, how it is excited, the
phase-plane box where errors are measured); `make_recordings` simulates base-sweep recordings
around each equilibrium.
"""

from ._kresling import (
    KRESLING3_AMPLITUDE as KRESLING3_AMPLITUDE,
    KRESLING5_AMPLITUDE as KRESLING5_AMPLITUDE,
    KRESLING5_DEPLOYMENT_AMPLITUDE as KRESLING5_DEPLOYMENT_AMPLITUDE,
    KRESLING5_DEPLOYMENT_DAMPING as KRESLING5_DEPLOYMENT_DAMPING,
    KreslingCell as KreslingCell,
    KreslingChain as KreslingChain,
    cell_equilibria as cell_equilibria,
    kresling3 as kresling3,
    kresling5 as kresling5,
    kresling_chain as kresling_chain,
)
from ._lattice import Lattice as Lattice, grid as grid, grounded_ladder as grounded_ladder, ladder as ladder
from ._nonpolynomial import (
    MagneticOscillator as MagneticOscillator,
    ShallowArch as ShallowArch,
    magnetic_bistable as magnetic_bistable,
    shallow_arch as shallow_arch,
)
from ._paper_cases import (
    JOINT_STIFFNESS as JOINT_STIFFNESS,
    NES_ALPHA as NES_ALPHA,
    NES_DAMPING as NES_DAMPING,
    NES_MASS as NES_MASS,
    bistable_joint as bistable_joint,
    tristable_nes as tristable_nes,
)
from ._system import System as System, make_recordings as make_recordings
