"""pysindy interop: a `GlobalModel` (or a `LocalFit`) as a fitted `pysindy.SINDy`, and back.

The pysindy model's state is z = (x_0..x_{D-1}, v_0..v_{D-1}) and, with `inputs=True`, its
control is u = (base_acc, f0..f{D-1}); its right-hand side is z' = (v, x''), x'' the model's
relative accelerations (the equation of motion of the contracts, paper Eq. 1). The library is
one `CustomLibrary` per DOF holding that DOF's basis functions of (x_k, v_k) with the model-file
names (`x0^3`, `sgn(v0)|v0|^2`, `x0^2*v0`; the constant is `x0^0`), plus an `IdentityLibrary`
on u, joined by a `GeneralizedLibrary`. The coefficients are set on the optimizer directly:
row x_i' is v_i, row v_i' is G_F F + g_b base_acc + G_f force (`_predict.input_gains`), so a
chain's coupling through its masses appears as cross-DOF coefficients.

pysindy is optional (`pip install gmr_jax[pysindy]`); it is imported on first use.
"""

import re

import numpy as np

from .._errors import GMRInputError
from .._fit._library import POSITION_DAMPING, STIFFNESS, VELOCITY_DAMPING, Library, signed_power, term_name
from ._model import GlobalModel, from_terms
from ._predict import input_gains

_FAMILIES = (STIFFNESS, VELOCITY_DAMPING, POSITION_DAMPING)


def _pysindy():
    try:
        import pysindy
    except ImportError:
        raise GMRInputError("pysindy is not installed: `pip install pysindy` (or gmr_jax[pysindy]) to "
                            "export or import pysindy models") from None
    return pysindy


def feature_name(physics: str, order: int, x: str, v: str) -> str:
    """The model-file name of one basis function, unambiguous per DOF (`x0^0`, `x0^0*v0`)."""
    if physics == STIFFNESS and order == 0:
        return f"{x}^0"
    if physics == POSITION_DAMPING and order == 0:
        return f"{x}^0*{v}"
    return term_name(physics, order, x, v)


def _basis(physics: str, order: int):
    """The basis function as f(x, v) on numpy arrays (the exact sgn(v))."""
    if physics == STIFFNESS:
        return lambda x, v: x**order
    if physics == VELOCITY_DAMPING:
        return lambda x, v: np.asarray(signed_power(np.asarray(v), order))
    return lambda x, v: x**order * v


def _columns(model: GlobalModel) -> list[tuple[str, int]]:
    """(physics, order) exported per DOF: every column of the model's arrays, except a
    position-damping order 0 that is zero everywhere (it is the same function as v); v itself
    (velocity_damping 1) always, since x' = v needs it."""
    cols = []
    for name in _FAMILIES:
        width = np.shape(getattr(model, name))[1]
        if name == VELOCITY_DAMPING:
            width = max(width, 2)
        for k in range(width):
            if name == POSITION_DAMPING and k == 0 and not np.any(np.asarray(model.position_damping)[:, 0]):
                continue
            cols.append((name, k))
    return cols


def _coef(model: GlobalModel, name: str, i: int, k: int) -> float:
    a = np.asarray(getattr(model, name))
    return float(a[i, k]) if k < a.shape[1] else 0.0


def to_pysindy(model, *, library: Library | None = None, mass: float = 1.0, inputs: bool = True,
               state: str = "x"):
    """Export a model as a fitted `pysindy.SINDy` with the same terms and coefficients.

    **Arguments:**

    - `model`: a `GlobalModel`, or a `LocalFit` (then `library` is the `Library` it was fitted
      with and `mass` its mass; it is exported in its own coordinate q = x - equilibrium, state
      names `q0`, `v0`).
    - `inputs`: include the inputs (base_acc, f0..) as pysindy controls `u` (default); without,
      the exported system is the free (unforced) one.
    - `state`: name of the displacement variables (`x` -> `x0`, `x1`, ...).

    **Returns:** a fitted `pysindy.SINDy`: `predict(z, u)` gives z' = (v, x'') for
    z = (x_0..x_{D-1}, v_0..v_{D-1}) (n, 2D) and u = (base_acc, f0..f{D-1}) (n, 1 + D).
    """
    from .._fit._local_fit import LocalFit

    if isinstance(model, LocalFit):
        if library is None:
            raise GMRInputError("to_pysindy: a LocalFit needs the Library it was fitted with: "
                                "to_pysindy(fit, library=Library(r, d), mass=m)")
        terms = [{"dof": 0, "physics": p, "order": k, "coefficient": float(c)}
                 for (p, k), c in zip(library.terms(), np.asarray(model.coef))]
        model = from_terms([mass], terms or [{"dof": 0, "physics": STIFFNESS, "order": 1, "coefficient": 0.0}])
        state = "q" if state == "x" else state
    if not isinstance(model, GlobalModel):
        raise GMRInputError(f"to_pysindy: needs a GlobalModel or a LocalFit, got {type(model).__name__}")
    ps = _pysindy()
    d = model.n_dof
    cols = _columns(model)
    libs, names = [], []
    xn, vn = [f"{state}{i}" for i in range(d)], [f"v{i}" for i in range(d)]
    for i in range(d):
        fns = [_basis(p, k) for p, k in cols]
        fnames = [(lambda a, b, p=p, k=k: feature_name(p, k, a, b)) for p, k in cols]
        libs.append(ps.CustomLibrary(fns, fnames, interaction_only=True, include_bias=False))
        names += [feature_name(p, k, xn[i], vn[i]) for p, k in cols]
    per = len(cols)
    G_F, g_b, G_f = input_gains(model)
    # F_k's coefficients on DOF k's features; x'' = G_F F (+ inputs)
    Fcoef = np.zeros((d, d * per))
    for k in range(d):
        for j, (p, o) in enumerate(cols):
            Fcoef[k, k * per + j] = _coef(model, p, k, o)
    xdot = np.zeros((d, d * per))
    for i in range(d):
        xdot[i, i * per + cols.index((VELOCITY_DAMPING, 1))] = 1.0
    coef = np.vstack([xdot, G_F @ Fcoef])
    per_lib = [[i, d + i] for i in range(d)]
    feature_names = xn + vn
    if inputs:
        libs.append(ps.IdentityLibrary())
        per_lib.append(list(range(2 * d, 3 * d + 1)))
        unames = ["base_acc"] + [f"f{i}" for i in range(d)]
        feature_names += unames
        coef = np.hstack([coef, np.vstack([np.zeros((d, d + 1)), np.column_stack([g_b, G_f])])])
    lib = ps.GeneralizedLibrary(libs, inputs_per_library=per_lib)
    sindy = ps.SINDy(optimizer=ps.STLSQ(threshold=0.0), feature_library=lib)
    rng = np.random.default_rng(0)  # a throwaway fit builds pysindy's pipeline; coef_ is then set
    n = 4 * coef.shape[1] + 8
    z = rng.standard_normal((n, 2 * d))
    u = rng.standard_normal((n, d + 1)) if inputs else None
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sindy.fit(z, t=1.0, x_dot=np.zeros_like(z), u=u, feature_names=feature_names)
    got = sindy.get_feature_names()
    want = names + (unames if inputs else [])
    if got != want:  # pragma: no cover - a pysindy whose naming differs
        raise GMRInputError(f"to_pysindy: this pysindy names the features {got[:6]}..., expected {want[:6]}...")
    sindy.optimizer.coef_ = coef
    if hasattr(sindy.optimizer, "intercept_"):
        sindy.optimizer.intercept_ = 0.0
    return sindy


_POW = r"(?:\^(\d+))?"


def parse_feature(name: str, state: str = "x"):
    """(dof, physics, order) of a feature name, or None. Accepts this module's names and
    pysindy's PolynomialLibrary ones (`x0^2 v0`, `x0 v0`, `v0^3`); `1` gives (None, stiffness, 0)."""
    s = name.strip()
    if s == "1":
        return None, STIFFNESS, 0
    X, V = rf"{state}(\d+)", r"v(\d+)"
    m = re.fullmatch(X + _POW, s)
    if m:
        return int(m[1]), STIFFNESS, int(m[2] or 1)
    m = re.fullmatch(V + _POW, s)
    if m:
        order = int(m[2] or 1)
        return (int(m[1]), VELOCITY_DAMPING, order) if order % 2 == 1 else None
    m = re.fullmatch(rf"sgn\({V}\)", s)
    if m:
        return int(m[1]), VELOCITY_DAMPING, 0
    m = re.fullmatch(rf"sgn\({V}\)\|v(\d+)\|\^(\d+)", s)
    if m and m[1] == m[2]:
        return int(m[1]), VELOCITY_DAMPING, int(m[3])
    m = re.fullmatch(X + _POW + r"[ *]" + V, s)
    if m and m[1] == m[3]:
        return int(m[1]), POSITION_DAMPING, int(m[2] or 1)
    m = re.fullmatch(V + r"[ *]" + X + _POW, s)
    if m and m[1] == m[2]:
        return int(m[1]), POSITION_DAMPING, int(m[3] or 1)
    return None


def from_pysindy(sindy, masses, topology: str = "independent", *, state: str = "x",
                 tol: float = 1e-8) -> GlobalModel:
    """Import a fitted `pysindy.SINDy` on z = (x_0..x_{D-1}, v_0..v_{D-1}) as a `GlobalModel`.

    **Arguments:**

    - `sindy`: a fitted SINDy whose features are basis functions of the model format, one DOF
      each, named as `to_pysindy` names them or as pysindy's `PolynomialLibrary` does (`x0^3`,
      `x0 v0`, `v0^3`, `1`); inputs `base_acc`, `f0..` may be present.
    - `masses`, `topology`: the mechanics (pysindy has no masses): F = G_F^{-1} (x'' - inputs).
    - `state`: name of the displacement variables; `tol`: relative tolerance of the checks.

    Raises `GMRInputError` naming a term that does not map: a feature outside the vocabulary
    (`v0^2`, `x0*x1`), a DOF's feature that the masses put in another DOF's force, input
    coefficients that disagree with `masses`/`topology`, or x' rows other than x_i' = v_i.
    """
    d = len(np.atleast_1d(masses))
    probe = from_terms(masses, [{"dof": i, "physics": STIFFNESS, "order": 1, "coefficient": 0.0}
                                for i in range(d)], topology)
    names = list(sindy.get_feature_names())
    coef = np.asarray(sindy.optimizer.coef_, float)
    if coef.shape != (2 * d, len(names)):
        raise GMRInputError(f"from_pysindy: the model has {coef.shape[0]} equations for {len(names)} features; "
                            f"a {d}-DOF model needs {2 * d} (x' and v' per DOF, state {state}0.., v0..)")
    scale = np.max(np.abs(coef)) or 1.0
    G_F, g_b, G_f = input_gains(probe)
    inputs = {"base_acc": g_b, **{f"f{k}": G_f[:, k] for k in range(d)}}
    Finv = np.linalg.inv(G_F)
    terms = []
    for j, name in enumerate(names):
        cx, cv = coef[:d, j], coef[d:, j]
        want_x = np.zeros(d)
        if name in inputs:
            if not np.allclose(cv, inputs[name], rtol=1e-6, atol=tol * scale):
                raise GMRInputError(f"from_pysindy: the coefficients of input '{name}' ({cv.tolist()}) do not match "
                                    f"the masses {np.atleast_1d(masses).tolist()} ({topology}): expected "
                                    f"{inputs[name].tolist()}")
            if np.any(np.abs(cx) > tol * scale):
                raise GMRInputError(f"from_pysindy: input '{name}' appears in an x' equation; x' must be v")
            continue
        parsed = parse_feature(name, state)
        if parsed is None:
            if np.all(coef[:, j] == 0):
                continue
            raise GMRInputError(f"from_pysindy: the term '{name}' does not map to the model format (stiffness x^k, "
                                f"velocity_damping sgn(v)|v|^j, position_damping x^j v of one DOF)")
        k, phys, order = parsed
        if phys == VELOCITY_DAMPING and order == 1:
            want_x[k] = 1.0
        if not np.allclose(cx, want_x, rtol=0, atol=tol * max(scale, 1.0)):
            raise GMRInputError(f"from_pysindy: the x' equations must read x_i' = v_i; the term '{name}' has "
                                f"coefficients {cx.tolist()} there")
        F = Finv @ cv  # each DOF's force coefficients on this feature
        if k is None:  # a constant: each DOF's preload
            for i in range(d):
                if F[i] != 0:
                    terms.append({"dof": i, "physics": STIFFNESS, "order": 0, "coefficient": float(F[i])})
            continue
        if k >= d:
            raise GMRInputError(f"from_pysindy: the term '{name}' refers to DOF {k}; the masses give {d} DOF(s)")
        other = np.delete(F, k)
        if np.any(np.abs(other) > tol * max(np.max(np.abs(Finv)) * scale, 1.0)):
            raise GMRInputError(f"from_pysindy: the term '{name}' of DOF {k} enters the force of another DOF "
                                f"(a coupling the model format has no physics for)")
        if F[k] != 0:
            terms.append({"dof": k, "physics": phys, "order": order, "coefficient": float(F[k])})
    present = {t["dof"] for t in terms}
    terms += [{"dof": i, "physics": STIFFNESS, "order": 1, "coefficient": 0.0} for i in range(d) if i not in present]
    return from_terms(masses, terms, topology, duplicates="add")
