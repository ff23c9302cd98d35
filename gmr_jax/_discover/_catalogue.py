"""The catalogue of candidate physics: each entry is one basis function of the gmr-model/1 format.

Names follow the `physics` vocabulary of the Discovery report (contracts): `preload` (stiffness
0), `linear_stiffness` ... `quintic_stiffness` (1..5), `coulomb_friction` (velocity_damping 0),
`viscous_damping` (1), `quadratic_drag` (2), `cubic_damping` (3), `position_dependent_damping`
(position_damping j: x^j v, with its `order`).
"""

from dataclasses import dataclass

import numpy as np

from .._fit._library import POSITION_DAMPING, STIFFNESS, VELOCITY_DAMPING
from .._model._model import POSITION_DAMPING_NAME, STIFFNESS_NAMES, VELOCITY_NAMES


#: what each physics is, in plain words (for the readable summary).
PLAIN = {
    "preload": "a constant force (preload / offset)",
    "linear_stiffness": "linear stiffness",
    "quadratic_stiffness": "an asymmetric (quadratic) stiffness",
    "cubic_stiffness": "cubic stiffening/softening",
    "quartic_stiffness": "a quartic stiffness term",
    "quintic_stiffness": "a quintic stiffness term",
    "coulomb_friction": "Coulomb (dry) friction",
    "viscous_damping": "viscous damping",
    "quadratic_drag": "quadratic (velocity-squared) drag",
    "cubic_damping": "cubic damping",
    POSITION_DAMPING_NAME: "position-dependent damping",
}

#: the unit of a coefficient, given the force unit N, the displacement unit m and s.
UNITS = {0: "N", 1: "N/m", 2: "N/m^2", 3: "N/m^3", 4: "N/m^4", 5: "N/m^5"}


@dataclass(frozen=True)
class Term:
    """One basis function of one DOF: `family` is a gmr-model/1 physics (stiffness,
    velocity_damping, position_damping), `order` its order."""

    dof: int
    family: str
    order: int

    @property
    def physics(self) -> str:
        """The contracts' `physics` name of this basis."""
        if self.family == STIFFNESS:
            return STIFFNESS_NAMES[self.order] if self.order < len(STIFFNESS_NAMES) else f"stiffness_{self.order}"
        if self.family == VELOCITY_DAMPING:
            return VELOCITY_NAMES[self.order] if self.order < len(VELOCITY_NAMES) else f"velocity_damping_{self.order}"
        return POSITION_DAMPING_NAME

    @property
    def label(self) -> str:
        """Short readable name with the order where it matters, e.g. `x^2 v`."""
        if self.family == STIFFNESS:
            return "1" if self.order == 0 else ("x" if self.order == 1 else f"x^{self.order}")
        if self.family == VELOCITY_DAMPING:
            return {0: "sgn(v)", 1: "v"}.get(self.order, f"sgn(v)|v|^{self.order}")
        return "x v" if self.order == 1 else f"x^{self.order} v"

    @property
    def unit(self) -> str:
        if self.family == STIFFNESS:
            return UNITS.get(self.order, f"N/m^{self.order}")
        if self.family == VELOCITY_DAMPING:
            return "N" if self.order == 0 else ("N s/m" if self.order == 1 else f"N s^{self.order}/m^{self.order}")
        return f"N s/m^{self.order + 1}"

    def model_term(self, coefficient: float) -> dict:
        return {"dof": self.dof, "physics": self.family, "order": self.order,
                "coefficient": float(coefficient)}


def basis(term: Term, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The basis function of `term` at (x, v) of its DOF (arrays of one DOF)."""
    if term.family == STIFFNESS:
        return x ** term.order
    if term.family == VELOCITY_DAMPING:
        return np.sign(v) * np.abs(v) ** term.order if term.order != 1 else v
    return x ** term.order * v


def default_catalogue(
    n_dof: int,
    *,
    stiffness_orders=(0, 1, 2, 3, 4, 5),
    velocity_orders=(0, 1, 2, 3),
    position_damping_orders=(1, 2),
) -> list[Term]:
    """Candidate physics for every DOF: preload and stiffness up to quintic, Coulomb, viscous,
    quadratic drag, cubic damping, and position-dependent damping x v, x^2 v."""
    out = []
    for i in range(n_dof):
        out += [Term(i, STIFFNESS, k) for k in stiffness_orders]
        out += [Term(i, VELOCITY_DAMPING, j) for j in velocity_orders]
        out += [Term(i, POSITION_DAMPING, j) for j in position_damping_orders]
    return out


def model_terms(model, dof: int) -> list[Term]:
    """The basis functions a `GlobalModel` already has (nonzero coefficients) for one DOF."""
    out = []
    for fam in (STIFFNESS, VELOCITY_DAMPING, POSITION_DAMPING):
        arr = np.asarray(getattr(model, fam))
        for k in range(arr.shape[1]):
            if arr[dof, k] != 0.0:
                # x^0 v is the viscous term: the model format keeps it under velocity_damping 1
                out.append(Term(dof, VELOCITY_DAMPING, 1) if (fam == POSITION_DAMPING and k == 0)
                           else Term(dof, fam, k))
    return list(dict.fromkeys(out))
