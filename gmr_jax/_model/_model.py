"""The global mechanical model (paper Eq. 1), in the "gmr-model/1" term vocabulary."""

import abc
import dataclasses
import math
import numbers

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._errors import GMRInputError, as_whole_number, describe
from .._fit._library import POSITION_DAMPING, STIFFNESS, VELOCITY_DAMPING, signed_power, term_name
from .._topology import AbstractTopology, Graph, Independent, as_topology


def polyval(coef: Float[Array, " orders"], x):
    """sum_k coef[k] x^k by Horner's rule."""
    out = jnp.zeros_like(x)
    for c in coef[::-1]:
        out = out * x + c
    return out


class AbstractMechanicalModel(eqx.Module):
    """A lumped model: masses plus a restoring-and-damping force per DOF (cell).

    Equation of motion (contracts): independent, m_i a_i + F_i(x_i, v_i) = force_i;
    chain (cells numbered from the base), (H a)_i + F_i(x_i, v_i) = sum_{k>=i} force_k with
    (H a)_i = sum_{k>=i} m_k a_k (paper Eq. 9 for base-first numbering). a is the absolute
    acceleration: a_i = x_0'' + ... + x_i'' + base_acc for a chain, x_i'' + base_acc otherwise.
    Graph (`Graph`): x are node displacements, the laws act on element deformations
    delta = B x, and m a = force - B^T F(delta, delta').
    """

    masses: eqx.AbstractVar[Float[Array, " dof"]]
    topology: eqx.AbstractVar[AbstractTopology]

    def force(self, x: Float[Array, " dof"], v: Float[Array, " dof"]) -> Float[Array, " elements"]:
        """Restoring plus damping force of every element at coordinates x, velocities v."""
        e, ev = self.topology.deformations(x), self.topology.deformations(v)
        return self.restoring(e) + self.damping(e, ev)

    @abc.abstractmethod
    def restoring(self, x: Float[Array, " dof"]) -> Float[Array, " dof"]:
        """Restoring force F_r of each DOF at deformations x."""

    @abc.abstractmethod
    def damping(self, x: Float[Array, " dof"], v: Float[Array, " dof"]) -> Float[Array, " dof"]:
        """Damping force F_d of each DOF."""

    @property
    def n_dof(self) -> int:
        return int(np.shape(self.masses)[0])

    @property
    def n_elements(self) -> int:
        """Number of force laws: the graph's elements, else one per DOF."""
        return self.topology.n_elements if isinstance(self.topology, Graph) else self.n_dof

    def accelerations(self, x, v, base_acc, force) -> Float[Array, " dof"]:
        """Relative accelerations x'' of every DOF, given base acceleration and forces."""
        return self.topology.accelerations(self.force(x, v), self.masses, base_acc, force)

    def absolute_accelerations(self, xdd, base_acc):
        """Absolute accelerations a of the masses from relative ones x'' (..., dof)."""
        return self.topology.absolute(xdd, base_acc)


class GlobalModel(AbstractMechanicalModel):
    """Polynomial global model: per DOF i,
    F_i(x, v) = sum_k K_ik x^k + sum_j B_ij sgn(v)|v|^j + (sum_j C_ij x^j) v.

    **Attributes:**

    - `masses` (dof,); `topology`: `Chain()`, `Independent()` (or their names) or a `Graph`,
      whose coefficient rows are its elements (x then the element's deformation).
    - `stiffness` (dof, orders): K_ik, coefficient of x^k (`stiffness` order k).
    - `velocity_damping` (dof, orders): B_ij of sgn(v)|v|^j.
    - `position_damping` (dof, orders): C_ij of x^j v.
    - `stderr`: optional standard errors, same structure (from the coordination's covariance).
    - `covariance`: optional (dof, p, p) covariance of each DOF's coefficients, flattened as
      `coefficients(model)` orders them (stiffness, then velocity_damping, then
      position_damping, p = the three widths summed); DOFs are fitted apart, so there is no
      covariance between DOFs. Set by `reconstruct` (calibrated, see `force_band`), None when
      unknown (a hand-written model, a refined one). Drives `force_band` and `sample_models`.
    - `sign_eps`: 0 for the exact sgn(v); > 0 replaces it by tanh(v/eps) (for gradients).
    """

    masses: Float[Array, " dof"]
    stiffness: Float[Array, "dof orders"]
    velocity_damping: Float[Array, "dof orders"]
    position_damping: Float[Array, "dof orders"]
    topology: AbstractTopology = eqx.field(static=True, default=Independent(), converter=as_topology)
    sign_eps: float = eqx.field(static=True, default=0.0)
    stderr: dict | None = None
    covariance: Float[Array, "dof p p"] | None = None

    def restoring(self, x):
        return jax.vmap(polyval)(self.stiffness, x)

    def damping(self, x, v):
        out = jax.vmap(polyval)(self.position_damping, x) * v
        for j in range(self.velocity_damping.shape[1]):
            out = out + self.velocity_damping[:, j] * signed_power(v, j, self.sign_eps)
        return out

    def with_sign_eps(self, eps: float) -> "GlobalModel":
        """A copy whose sgn(v) terms are smoothed to tanh(v/eps) (for differentiation)."""
        return dataclasses.replace(self, sign_eps=float(eps))

    # -- readable form ---------------------------------------------------------------
    def terms(self, tol: float = 0.0) -> list[dict]:
        """Nonzero terms as "gmr-model/1" term dicts (with `stderr` where known)."""
        out = []
        for name, arr in (
            (STIFFNESS, self.stiffness),
            (VELOCITY_DAMPING, self.velocity_damping),
            (POSITION_DAMPING, self.position_damping),
        ):
            a = np.asarray(arr)
            se = None if self.stderr is None or self.stderr.get(name) is None else np.asarray(self.stderr[name])
            key = term_key(self.topology)
            for i in range(a.shape[0]):
                for k in range(a.shape[1]):
                    if a[i, k] != 0.0 and abs(a[i, k]) > tol:
                        t = {key: i, "physics": name, "order": k, "coefficient": float(a[i, k])}
                        if se is not None and np.isfinite(se[i, k]):
                            t["stderr"] = float(se[i, k])
                        out.append(t)
        return out

    def equations(self, precision: int = 4, x: str = "x", v: str = "v") -> list[str]:
        """One readable line per DOF: `F_0(x, v) = -2244 x + 1755 x^3 + 10 v^3`."""
        lines = []
        key = term_key(self.topology)
        for i in range(self.n_elements):
            parts = []
            for t in self.terms():
                if t[key] != i:
                    continue
                name = term_name(t["physics"], t["order"], x, v)
                c = t["coefficient"]
                cs = f"{c:.{precision}g}"
                parts.append(cs if name == "1" else f"{cs} {name}")
            body = " + ".join(parts).replace("+ -", "- ") or "0"
            lines.append(f"F_{i}({x}, {v}) = {body}")
        return lines

    def __str__(self):
        return "\n".join(self.equations())


KNOWN_PHYSICS = (STIFFNESS, VELOCITY_DAMPING, POSITION_DAMPING)


def term_key(topology) -> str:
    """The key that names a term's law: "element" on a graph, "dof" otherwise."""
    return "element" if isinstance(topology, Graph) else "dof"

TERM_KEYS = ("dof", "physics", "order", "coefficient", "stderr")
_TERM_FIX = ('a term is {"dof": i, "physics": "stiffness" | "velocity_damping" | "position_damping", '
             '"order": k, "coefficient": c} (optional "stderr": s)')


def check_masses(masses, source: str = "from_terms") -> np.ndarray:
    """The masses as a float (dof,) array, or `GMRInputError`: one finite positive number per
    DOF (a bare number is one DOF)."""
    bad = GMRInputError(f"{source}: 'masses' must be a non-empty list of numbers, one per DOF, "
                        f"got {describe(masses)}")
    if isinstance(masses, (list, tuple)) and any(isinstance(m, (bool, np.bool_)) for m in masses):
        raise bad
    try:
        m = np.asarray(masses)
    except Exception:  # noqa: BLE001 - ragged or not array-like
        raise bad from None
    if m.dtype.kind not in "iuf":
        raise bad
    m = m.astype(np.float64).reshape(-1) if m.ndim == 0 else m.astype(np.float64)
    if m.ndim != 1 or m.size == 0:
        raise GMRInputError(f"{source}: 'masses' must be a flat list, one number per DOF, got shape {m.shape}")
    if not np.all(np.isfinite(m)) or np.any(m <= 0):
        raise GMRInputError(f"{source}: masses must be finite and positive, got {m.tolist()}")
    return m


#: highest power a model term may have (a polynomial of higher degree is not a physical law
#: one can evaluate in float64 over any useful range)
MAX_ORDER = 64


def check_terms(terms, n_dof: int, source: str = "from_terms", duplicates: str = "error",
                key: str = "dof") -> list[dict]:
    """Validate "gmr-model/1" term dicts for a model of `n_dof` DOFs; return normalised copies
    (int dof and order, float coefficient and stderr). Raises `GMRInputError` naming the term,
    the key and the fix: unknown or missing keys, a non-integer dof or order, a coefficient that
    is not a finite number, a duplicated (dof, physics, order) unless `duplicates="add"`, a DOF
    without any term. `key="element"`: the terms of a graph's `n_dof` elements."""
    if key != "dof":
        with _element_words():
            return _renamed(check_terms(_renamed(terms, key, "dof", source), n_dof, source, duplicates), "dof", key,
                            source)
    if duplicates not in ("error", "add"):
        raise GMRInputError(f"{source}: duplicates must be 'error' or 'add', got {describe(duplicates)}")
    if not isinstance(terms, (list, tuple)):
        raise GMRInputError(f"{source}: 'terms' must be a list of term dicts, got {type(terms).__name__}; "
                            f"{_TERM_FIX}")
    if not terms:
        raise GMRInputError(f"{source}: the model has no terms; give each DOF at least its stiffness, "
                            f"{_TERM_FIX}")
    out, seen = [], {}
    for i, t in enumerate(terms):
        where = f"{source}: term {i}"
        if not isinstance(t, dict):
            raise GMRInputError(f"{where} is {describe(t)}, not a dict; {_TERM_FIX}")
        unknown = [k for k in t if k not in TERM_KEYS]
        if unknown:
            raise GMRInputError(f"{where} has unknown key(s) {unknown}; allowed: {', '.join(TERM_KEYS)}")
        missing = [k for k in TERM_KEYS[:4] if k not in t]
        if missing:
            raise GMRInputError(f"{where} lacks {', '.join(repr(k) for k in missing)}; {_TERM_FIX}")
        phys = t["physics"]
        if not isinstance(phys, str) or phys not in KNOWN_PHYSICS:
            hint = _report_name(phys) if isinstance(phys, str) else None
            raise GMRInputError(f"{where}: unknown physics {describe(phys)}; known: {', '.join(KNOWN_PHYSICS)}"
                                + (f" ('{phys}' is a discovery report's name: in a model write physics "
                                   f"'{hint[0]}', order {hint[1]})" if hint else ""))
        dof = as_whole_number(t["dof"], f"{where}: 'dof'", accept_float=True,
                              fix=f"DOFs are numbered 0..{n_dof - 1}")
        if not 0 <= dof < n_dof:
            raise GMRInputError(f"{where} names dof {dof}, outside 0..{n_dof - 1} (the model has {n_dof} "
                                f"mass(es)); give one mass per DOF or fix the term's dof")
        order = as_whole_number(t["order"], f"{where}: 'order'", lo=0, hi=MAX_ORDER, accept_float=True,
                                fix=f"the order is the integer power k of x^k, sgn(v)|v|^k or x^k v, "
                                f"at most {MAX_ORDER}")
        c = t["coefficient"]
        if isinstance(c, bool) or not isinstance(c, numbers.Real) or not math.isfinite(c):
            raise GMRInputError(f"{where}: 'coefficient' must be a finite number, got {describe(c)}; "
                                f"write the value of the term's coefficient (e.g. -2244.0)")
        term = {"dof": dof, "physics": phys, "order": order, "coefficient": float(c)}
        if "stderr" in t:
            s = t["stderr"]
            if isinstance(s, bool) or not isinstance(s, numbers.Real) or not math.isfinite(s) or s < 0:
                raise GMRInputError(f"{where}: 'stderr' must be a finite number >= 0, got {describe(s)}; "
                                    f"omit the key when the standard error is unknown")
            term["stderr"] = float(s)
        key = (dof, phys, order)
        if key in seen and duplicates == "error":
            raise GMRInputError(f"{source}: terms {seen[key]} and {i} are both dof {dof} {phys} order {order}; "
                                f"merge them into one term (sum their coefficients) or fix the dof/order")
        seen.setdefault(key, i)
        out.append(term)
    empty = sorted(set(range(n_dof)) - {t["dof"] for t in out})
    if empty:
        raise GMRInputError(f"{source}: DOF(s) {empty} have no term (no restoring or damping force); add at "
                            f"least a stiffness term for each, or remove their masses")
    return out


class _element_words:
    """Re-raise a `GMRInputError` about DOFs in the words of a graph's elements."""

    def __enter__(self):
        return self

    def __exit__(self, kind, err, tb):
        if isinstance(err, GMRInputError):
            msg = str(err)
            for a, b in (("give one mass per DOF or fix the term's dof", "fix the term's element"),
                         ("mass(es)", "element(s)"), ("DOF(s)", "element(s)"), ("DOFs", "elements"),
                         ("DOF", "element"), ("dof", "element"), ("remove their masses", "remove the elements")):
                msg = msg.replace(a, b)
            raise GMRInputError(msg) from None
        return False


def _renamed(terms, old: str, new: str, source: str = "from_terms"):
    """Term dicts with the key `old` renamed `new` (a term that has `new` already is refused)."""
    if not isinstance(terms, (list, tuple)):
        return terms
    out = []
    for i, t in enumerate(terms):
        if isinstance(t, dict) and new in t:
            raise GMRInputError(f"{source}: term {i} has the key {new!r}; terms of a "
                                f"{'graph' if old == 'element' else 'chain or independent'} model name their law "
                                f"with {old!r}")
        out.append({(new if k == old else k): v for k, v in t.items()} if isinstance(t, dict) else t)
    return out


def coefficient_index(model: GlobalModel) -> list[tuple[str, int]]:
    """(physics, order) of each position of a DOF's flattened coefficient vector (the layout of
    `GlobalModel.covariance`): stiffness 0.., then velocity_damping 0.., then position_damping 0..."""
    return [(name, k) for name in KNOWN_PHYSICS for k in range(np.shape(getattr(model, name))[-1])]


def coefficients(model: GlobalModel) -> Float[Array, "*batch dof p"]:
    """Each DOF's coefficients flattened in the layout of `GlobalModel.covariance`."""
    return jnp.concatenate([model.stiffness, model.velocity_damping, model.position_damping], axis=-1)


_COV_FIX = ('the covariance is a list of {"dof": i, "terms": [[physics, order], ...], "matrix": [[...], ...]} '
            'entries, one per DOF at most, the matrix square, symmetric, finite, with a non-negative diagonal, '
            'one row per listed term; omit the key when the covariance is unknown')


#: the `physics` names of a discovery report's terms (contracts), per stiffness and velocity order
STIFFNESS_NAMES = ("preload", "linear_stiffness", "quadratic_stiffness", "cubic_stiffness",
                   "quartic_stiffness", "quintic_stiffness")
VELOCITY_NAMES = ("coulomb_friction", "viscous_damping", "quadratic_drag", "cubic_damping")
POSITION_DAMPING_NAME = "position_dependent_damping"


def _report_name(phys: str):
    """The model term (physics, order) of a discovery report's physics name (the catalogue's vocabulary,
    contracts), None if it is not one."""
    names = ({n: (STIFFNESS, k) for k, n in enumerate(STIFFNESS_NAMES)}
             | {n: (VELOCITY_DAMPING, k) for k, n in enumerate(VELOCITY_NAMES)}
             | {POSITION_DAMPING_NAME: (POSITION_DAMPING, "the finding's 'order'")})
    return names.get(phys)


def check_covariance(entries, n_dof: int, source: str = "from_terms", key: str = "dof") -> list[dict]:
    """Validate the "covariance" extension of "gmr-model/1" (see `from_terms`); returns
    normalised entries (int dof, (physics, order) tuples, float64 matrix). Raises
    `GMRInputError` naming the entry, the key and the fix (`key="element"`: a graph's entries)."""
    if key != "dof":
        with _element_words():
            return _renamed(check_covariance(_renamed(entries, key, "dof", source), n_dof, source), "dof", key,
                            source)
    if not isinstance(entries, (list, tuple)):
        raise GMRInputError(f"{source}: 'covariance' must be a list, got {describe(entries)}; {_COV_FIX}")
    out, seen = [], set()
    for i, e in enumerate(entries):
        where = f"{source}: covariance entry {i}"
        if not isinstance(e, dict) or set(e) != {"dof", "terms", "matrix"}:
            raise GMRInputError(f"{where} must be a dict with exactly the keys 'dof', 'terms', 'matrix', got "
                                f"{describe(e)}; {_COV_FIX}")
        dof = as_whole_number(e["dof"], f"{where}: 'dof'", accept_float=True, fix=f"DOFs are numbered 0..{n_dof - 1}")
        if not 0 <= dof < n_dof or dof in seen:
            raise GMRInputError(f"{where}: dof {dof} is outside 0..{n_dof - 1} or appears twice; {_COV_FIX}")
        seen.add(dof)
        keys = []
        if not isinstance(e["terms"], (list, tuple)):
            raise GMRInputError(f"{where}: 'terms' must be a list of [physics, order] pairs; {_COV_FIX}")
        for t in e["terms"]:
            if (not isinstance(t, (list, tuple)) or len(t) != 2 or not isinstance(t[0], str)
                    or t[0] not in KNOWN_PHYSICS):
                raise GMRInputError(f"{where}: term {describe(t)} is not a [physics, order] pair with physics one "
                                    f"of {', '.join(KNOWN_PHYSICS)}")
            keys.append((t[0], as_whole_number(t[1], f"{where}: order of {t[0]}", lo=0, hi=MAX_ORDER,
                                               accept_float=True)))
        if len(set(keys)) != len(keys):
            raise GMRInputError(f"{where}: a term is listed twice in 'terms'; {_COV_FIX}")
        try:
            mat = np.asarray(e["matrix"], dtype=np.float64)
        except (TypeError, ValueError):
            raise GMRInputError(f"{where}: 'matrix' is not a numeric square matrix; {_COV_FIX}") from None
        n = len(keys)
        if mat.shape != (n, n) and not (n == 0 and mat.size == 0):
            raise GMRInputError(f"{where}: 'matrix' has shape {mat.shape} for {n} terms; {_COV_FIX}")
        mat = mat.reshape(n, n)
        if not np.all(np.isfinite(mat)) or np.any(np.diag(mat) < 0):
            raise GMRInputError(f"{where}: 'matrix' has a non-finite entry or a negative variance; {_COV_FIX}")
        if not np.allclose(mat, mat.T, rtol=1e-9, atol=0.0):
            raise GMRInputError(f"{where}: 'matrix' is not symmetric; {_COV_FIX}")
        out.append({"dof": dof, "terms": keys, "matrix": 0.5 * (mat + mat.T)})
    return out


def covariance_entries(model: GlobalModel) -> list[dict] | None:
    """The model's covariance as "covariance" extension entries (JSON-ready; only the
    coefficients with a nonzero variance), or None."""
    if model.covariance is None:
        return None
    cov = np.asarray(model.covariance)
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))  # exactly symmetric on file (the reader checks it)
    index = coefficient_index(model)
    out = []
    for i in range(cov.shape[0]):
        keep = np.nonzero(np.diag(cov[i]) > 0)[0]
        if keep.size:
            out.append({term_key(model.topology): i, "terms": [[index[k][0], index[k][1]] for k in keep],
                        "matrix": [[float(c) for c in row] for row in cov[i][np.ix_(keep, keep)]]})
    return out


def from_terms(
    masses, terms: list[dict], topology: str = "independent", *, min_orders: dict | None = None,
    duplicates: str = "error", covariance: list[dict] | None = None,
) -> GlobalModel:
    """Build a `GlobalModel` from "gmr-model/1" term dicts.

    **Arguments:**

    - `masses`: one positive mass per DOF.
    - `terms`: `{"dof": i, "physics": p, "order": k, "coefficient": c}` (optional `"stderr"`),
      `p` one of "stiffness", "velocity_damping", "position_damping"; every DOF needs a term.
    - `topology`: "independent" | "chain" (or a topology object); a `Graph` takes one mass per
      node and terms `{"element": e, ...}`, one law per element.
    - `min_orders`: smallest number of columns per physics (`{"stiffness": 4}`).
    - `duplicates`: "error" (default): two terms with the same (dof, physics, order) are
      refused; "add": their coefficients add (used to apply corrections to a model).
    - `covariance`: optional covariance of the coefficients, the "covariance" extension of the
      model file: a list of `{"dof": i, "terms": [[physics, order], ...], "matrix": [[...]]}`
      (per DOF, the covariance of the listed coefficients; coefficients not listed have zero
      variance and covariance). Becomes `GlobalModel.covariance`; None (default): unknown.

    Raises `GMRInputError` naming the bad term and key (see `check_terms`).

    Examples:
        A two-cell chain, each cell bistable, with viscous damping:

        >>> import gmr_jax as gmr
        >>> terms = [{"dof": i, "physics": p, "order": k, "coefficient": c}
        ...          for i in (0, 1)
        ...          for p, k, c in [("stiffness", 1, -1.0), ("stiffness", 3, 1.0), ("velocity_damping", 1, 0.05)]]
        >>> model = gmr.from_terms([0.1, 0.1], terms, topology="chain")
        >>> print(model)
        F_0(x, v) = -1 x + 1 x^3 + 0.05 v
        F_1(x, v) = -1 x + 1 x^3 + 0.05 v
        >>> model.n_dof, model.topology
        (2, Chain())
    """
    masses = check_masses(masses)
    topology = as_topology(topology)
    key = term_key(topology)
    if isinstance(topology, Graph) and topology.nodes != masses.shape[0]:
        raise GMRInputError(f"from_terms: {masses.shape[0]} masses for a graph of {topology.nodes} nodes; give one "
                            f"mass per node")
    d = topology.n_elements if isinstance(topology, Graph) else masses.shape[0]
    terms = [{("dof" if k == key else k): v for k, v in t.items()}
             for t in check_terms(terms, d, duplicates=duplicates, key=key)]
    min_orders = {} if min_orders is None else min_orders
    if not isinstance(min_orders, dict) or any(k not in KNOWN_PHYSICS for k in min_orders):
        raise GMRInputError(f"from_terms: min_orders must be a dict keyed by {KNOWN_PHYSICS}, got "
                            f"{describe(min_orders)}")
    for k, v in min_orders.items():
        as_whole_number(v, f"from_terms: min_orders[{k!r}]", lo=1)
    cov_entries = None if covariance is None else [
        {("dof" if k == key else k): v for k, v in e.items()} for e in check_covariance(covariance, d, key=key)]
    arrays, errs = {}, {}
    for name in KNOWN_PHYSICS:
        orders = [t["order"] for t in terms if t["physics"] == name]
        orders += [o for e in (cov_entries or []) for ph, o in e["terms"] if ph == name]
        size = max([o + 1 for o in orders] + [min_orders.get(name, 1)])
        arrays[name] = np.zeros((d, size))
        errs[name] = np.full((d, size), np.nan)
    for t in terms:
        arrays[t["physics"]][t["dof"], t["order"]] += t["coefficient"]
        if "stderr" in t:
            errs[t["physics"]][t["dof"], t["order"]] = t["stderr"]
    has_err = any("stderr" in t for t in terms)
    cov = None
    if cov_entries is not None:
        offsets = np.cumsum([0] + [arrays[name].shape[1] for name in KNOWN_PHYSICS])
        start = dict(zip(KNOWN_PHYSICS, offsets[:-1]))
        cov = np.zeros((d, offsets[-1], offsets[-1]))
        for e in cov_entries:
            idx = np.array([start[ph] + o for ph, o in e["terms"]], int)
            cov[e["dof"]][np.ix_(idx, idx)] = e["matrix"]
        cov = jnp.asarray(cov)
    return GlobalModel(
        masses=jnp.asarray(masses),
        stiffness=jnp.asarray(arrays[STIFFNESS]),
        velocity_damping=jnp.asarray(arrays[VELOCITY_DAMPING]),
        position_damping=jnp.asarray(arrays[POSITION_DAMPING]),
        topology=topology,
        stderr={k: jnp.asarray(v) for k, v in errs.items()} if has_err else None,
        covariance=cov,
    )


def to_graph(model: AbstractMechanicalModel) -> AbstractMechanicalModel:
    """The same model on its `Graph`: a chain as elements [[-1, 0], [0, 1], ...], independent DOFs
    as [[-1, i]]; the force laws are unchanged, the coordinates become the node displacements
    (`model.topology.displacements(x)`)."""
    from .._topology import as_graph

    if not isinstance(model, AbstractMechanicalModel):
        raise GMRInputError(f"to_graph: needs a mechanical model, got {type(model).__name__}")
    return dataclasses.replace(model, topology=as_graph(model.topology, model.n_dof))
