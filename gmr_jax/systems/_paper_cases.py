"""The paper's single-DOF cases: the bistable bionic joint (Sec. 2.3) and the asymmetric
tri-stable NES (Sec. 3.1, Eq. 23, Table 1)."""

import numpy as np

from .._model._model import from_terms
from ._system import System

#: Bistable joint per unit inertia (Tables B1/B2): F_r = -2244 θ + 1755 θ³.
JOINT_STIFFNESS = (-2244.0, 1755.0)


def bistable_joint(damping: str = "position_independent") -> System:
    """Bistable bionic joint, per unit inertia, angle θ in rad.

    `damping`: "position_independent" (10 θ'³) or "position_dependent" (50 θ² θ')."""
    k1, k3 = JOINT_STIFFNESS
    terms = [
        {"dof": 0, "physics": "stiffness", "order": 1, "coefficient": k1},
        {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": k3},
    ]
    if damping == "position_independent":
        terms.append({"dof": 0, "physics": "velocity_damping", "order": 3, "coefficient": 10.0})
    elif damping == "position_dependent":
        terms.append({"dof": 0, "physics": "position_damping", "order": 2, "coefficient": 50.0})
    else:
        raise ValueError(f"damping must be position_independent or position_dependent, got {damping!r}")
    xe = np.sqrt(-k1 / k3)
    return System(
        name=f"joint_{'pi' if damping == 'position_independent' else 'pd'}",
        truth=from_terms([1.0], terms),
        equilibria=np.array([[-xe], [xe]]),
        sweep=(1.0, 25.0),
        duration=8.0,
        fs=1000.0,
        x_range=np.array([[-1.5 * xe, 1.5 * xe]]),
        v_range=np.array([[-10.0, 10.0]]),
        orders={"gmr": (5, 5), "gmc": (7, 7)},
        description=f"bistable bionic joint, {damping.replace('_', '-')} damping",
        units=("θ [rad]", "θ' [rad/s]", "F [1/s²]"),
    )


#: Tri-stable NES, Table 1 (SI units): m, c, alpha_0..alpha_7.
NES_MASS = 0.035
NES_DAMPING = 0.8
NES_ALPHA = (-0.9, 168.6, 575.1, -2.0e5, -5.0e4, 6.5e7, 7.6e5, -4.7e9)


def tristable_nes() -> System:
    """Asymmetric tri-stable nonlinear energy sink, Eq. (23), base acceleration input."""
    terms = [{"dof": 0, "physics": "stiffness", "order": k, "coefficient": a} for k, a in enumerate(NES_ALPHA)]
    terms.append({"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": NES_DAMPING})
    roots = np.polynomial.Polynomial(NES_ALPHA).roots()
    dpoly = np.polynomial.Polynomial(NES_ALPHA).deriv()
    real = np.sort(roots[np.abs(roots.imag) < 1e-12].real)
    stable = real[dpoly(real) > 0]
    span = stable.max() - stable.min()
    return System(
        name="nes",
        truth=from_terms([NES_MASS], terms),
        equilibria=stable[:, None],
        sweep=(2.0, 25.0),
        duration=8.0,
        fs=1000.0,
        x_range=np.array([[stable.min() - 0.05 * span, stable.max() + 0.05 * span]]),
        v_range=np.array([[-0.5, 0.5]]),
        orders={"gmr": (3, 3), "gmc": (7, 7)},
        description="asymmetric tri-stable NES (Eq. 23, Table 1)",
        units=("x [m]", "x' [m/s]", "F [N]"),
    )
