"""Property-based tests (issue 13): invariants that must hold for every input, not only for the
hand-picked cases of the other test files.

1. Coordination: the Hermite interpolant of a polynomial's Taylor data is that polynomial.
2. STLS recovers a sparse model exactly from noise-free data.
3. Models and recordings survive save/load exactly.
4. Shifting x by a constant commutes with the local fit.
5. The loaders raise nothing but `GMRInputError` on malformed files, and accept only what they
   can represent faithfully.

Reproducible in CI: the "ci" profile is derandomized (a fixed sequence of examples) and keeps no
example database. Shapes are drawn from small fixed sets so that each jitted kernel compiles a
few times per session, not once per example.
"""

import json
import math
import os
import warnings
from dataclasses import replace
from fractions import Fraction

import hypothesis
import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import gmr_jax as g

settings.register_profile(
    "ci",
    derandomize=True,
    database=None,
    deadline=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

FORMAT = "gmr-model/1"
PHYSICS = ("stiffness", "velocity_damping", "position_damping")


def _is_number(v) -> bool:
    """A JSON number: int or float, not bool."""
    return isinstance(v, (int, float)) and not isinstance(v, bool)


# ---------------------------------------------------------------------------------------------
# 1. Coordination: Hermite interpolation recovers polynomials (Eqs. 12-21)
# ---------------------------------------------------------------------------------------------

R_MAX = 4  # local orders 1..4: Taylor blocks of fixed width R_MAX + 1 (one compile per n)
_hermite = jax.jit(g.hermite_interpolate)


def _taylor_exact(coef, x0: float, r: int) -> np.ndarray:
    """Taylor coefficients F^(j)(x0)/j!, j = 0..r, of sum_k coef[k] x^k, exactly, then rounded."""
    cf = [Fraction(c) for c in coef]
    x = Fraction(x0)
    return np.array(
        [float(sum(cf[k] * math.comb(k, j) * x ** (k - j) for k in range(j, len(cf)))) for j in range(r + 1)]
    )


@st.composite
def hermite_problems(draw, counts=(2, 3, 4)):
    """2-4 distinct nodes in [-1, 1] (gaps >= 0.2, in any order), local orders 1-4, and a
    polynomial of degree <= K = (n - 1) + sum(orders) (Eq. 18)."""
    n = draw(st.sampled_from(counts))
    raw = sorted(draw(st.lists(st.floats(0.0, 1.0), min_size=n, max_size=n)))
    slack = 2.0 - 0.2 * (n - 1)
    nodes = np.array([-1.0 + u * slack + 0.2 * i for i, u in enumerate(raw)])
    nodes = np.clip(nodes, -1.0, 1.0)[np.array(draw(st.permutations(range(n))))]
    orders = np.array(draw(st.lists(st.integers(1, R_MAX), min_size=n, max_size=n)))
    k = int(n - 1 + orders.sum())
    degree = draw(st.integers(0, k))
    truth = np.zeros(k + 1)
    # |coefficients| in {0} u [1e-3, 2]: XLA on CPU flushes subnormals to zero, which would make a
    # tiny top Taylor coefficient a zero (a lower local order) inside `coordinate`
    coef = st.floats(-2.0, 2.0).map(lambda c: c if abs(c) >= 1e-3 else 0.0)
    truth[: degree + 1] = draw(st.lists(coef, min_size=degree + 1, max_size=degree + 1))
    junk = draw(st.floats(-1e3, 1e3))  # Taylor entries above a node's order are unknown: ignored
    return nodes, orders, truth, junk


def _taylor_table(nodes, orders, truth, junk):
    taylor = np.stack([_taylor_exact(truth, x, R_MAX) for x in nodes])
    known = np.arange(R_MAX + 1)[None, :] <= orders[:, None]
    return taylor, np.where(known, taylor, junk)


def _assert_same_polynomial(coef, truth, nodes, orders, taylor):
    """Equal as functions on the hull of the nodes and in every known Taylor coefficient,
    relative to the size of the data (the monomial coefficients themselves are not: recovering
    them is ill-conditioned by (1 + |centre|/half-span)^K, e.g. 3e-2 relative for K = 16 on
    nodes -1, -0.8, -0.6, -0.4, with exact data)."""
    coef = np.asarray(coef)
    k = truth.shape[0] - 1
    xs = np.linspace(nodes.min(), nodes.max(), 41)
    got = np.polynomial.polynomial.polyval(xs, coef)
    want = np.polynomial.polynomial.polyval(xs, truth)
    known = np.arange(R_MAX + 1)[None, :] <= orders[:, None]
    scale = max(np.max(np.abs(want)), np.max(np.abs(taylor[known])), 1e-300)
    assert np.max(np.abs(got - want)) <= 1e-8 * scale, np.max(np.abs(got - want)) / scale
    back = np.stack([_taylor_exact(coef[: k + 1], x, R_MAX) for x in nodes])
    err = np.max(np.abs(np.where(known, back - taylor, 0.0)))
    assert err <= 1e-8 * scale, err / scale


@settings(max_examples=60)
@given(hermite_problems())
def test_hermite_interpolant_recovers_polynomial(problem):
    """Taylor data of a random polynomial of degree <= K at 2-4 nodes with random local orders
    (entries above each order filled with junk): `hermite_interpolate` returns degree K
    (Eq. 18), zeros above it, and the polynomial itself (see `_assert_same_polynomial`)."""
    nodes, orders, truth, junk = problem
    taylor, data = _taylor_table(nodes, orders, truth, junk)
    coef, degree, cond = _hermite(jnp.asarray(nodes), jnp.asarray(data), jnp.asarray(orders))
    k = truth.shape[0] - 1
    assert int(degree) == k  # Eq. (18)
    assert np.all(np.asarray(coef)[k + 1:] == 0.0)
    assert np.isfinite(float(cond))
    _assert_same_polynomial(coef, truth, nodes, orders, taylor)


_COORD_LIB = g.Library(R_MAX, 1)


def _local_fits(nodes, coefs):
    n, p = coefs.shape
    return g.LocalFit(equilibrium=jnp.asarray(nodes), coef=jnp.asarray(coefs),
                      covariance=jnp.zeros((n, p, p)), threshold=jnp.zeros(n), rss=jnp.zeros(n),
                      n_samples=jnp.full(n, 100.0))


@settings(max_examples=15)
@given(hermite_problems(counts=(3,)))  # one compilation (the Hermite test covers n = 2..4)
def test_coordinate_recovers_restoring_polynomial(problem):
    """The same through `g.coordinate(method="hermite")`, where a node's local order is its
    highest nonzero local coefficient: entries above each order are zero (unknown). A zero
    Taylor coefficient at the top order would lower it, so such examples are skipped."""
    nodes, orders, truth, _ = problem
    taylor, _ = _taylor_table(nodes, orders, truth, 0.0)
    hypothesis.assume(np.all(np.abs(taylor[np.arange(len(nodes)), orders]) > 1e-200))
    known = np.arange(R_MAX + 1)[None, :] <= orders[:, None]
    coefs = np.zeros((len(nodes), _COORD_LIB.n_terms))
    coefs[:, _COORD_LIB.indices("stiffness")] = np.where(known, taylor, 0.0)
    sol = g.coordinate(_local_fits(nodes, coefs), _COORD_LIB, method="hermite")
    k = truth.shape[0] - 1
    assert int(sol.stats["K_r"]) == k
    np.testing.assert_array_equal(np.asarray(sol.stats["r_i"]), orders)
    coef = np.asarray(sol.value.stiffness)
    assert np.all(coef[k + 1:] == 0.0)
    _assert_same_polynomial(coef, truth, nodes, orders, taylor)
    np.testing.assert_array_equal(np.asarray(sol.value.position_damping), 0.0)
    np.testing.assert_array_equal(np.asarray(sol.value.velocity_damping), 0.0)


# ---------------------------------------------------------------------------------------------
# 2. STLS recovers sparse models from noise-free data (Eq. 8)
# ---------------------------------------------------------------------------------------------

N_ROWS = 300  # rows fixed; 100-300 active rows through sample weights (zero weight: masked out)


@st.composite
def sparse_problems(draw):
    p, normalize = draw(st.sampled_from([(5, False), (8, True), (12, True)]))  # 3 compilations
    n = draw(st.integers(100, N_ROWS))
    seed = draw(st.integers(0, 2**32 - 1))
    support = np.array(draw(st.lists(st.booleans(), min_size=p, max_size=p)))
    if not support.any():
        support[draw(st.integers(0, p - 1))] = True
    mags = np.array(draw(st.lists(st.floats(0.5, 2.0), min_size=p, max_size=p)))
    signs = np.array(draw(st.lists(st.sampled_from([-1.0, 1.0]), min_size=p, max_size=p)))
    xi = np.where(support, signs * mags, 0.0)
    alpha = draw(st.sampled_from([0.0, 0.05]))
    frac = draw(st.floats(0.3, 0.7))  # threshold as a fraction of the smallest true coefficient
    return p, n, seed, xi, normalize, alpha, frac


@settings(max_examples=40)
@given(sparse_problems())
def test_stls_recovers_sparse_model_noise_free(problem):
    """Θ: random normal columns; y = Θ ξ exactly; threshold = frac x the smallest true
    coefficient (in the normalised units when `normalize_columns`): the support is ξ's and the
    coefficients equal ξ to 1e-8 relative (the unbiased refit is exact least squares)."""
    p, n, seed, xi, normalize, alpha, frac = problem
    rng = np.random.default_rng(seed)
    theta = rng.standard_normal((N_ROWS, p))
    w = (np.arange(N_ROWS) < n).astype(float)
    y = theta @ xi
    y[n:] += 1e3  # masked rows hold samples off the model: they must not count
    norms = np.linalg.norm(theta[:n], axis=0) if normalize else np.ones(p)
    threshold = frac * np.min(np.abs(xi[xi != 0]) * norms[xi != 0])
    solver = g.STLS(jnp.asarray(threshold), jnp.asarray(alpha), 20, normalize, True)
    sol = g.stls(jnp.asarray(theta), jnp.asarray(y), solver, weights=jnp.asarray(w))
    np.testing.assert_array_equal(np.asarray(sol.stats["support"]), xi != 0)
    coef = np.asarray(sol.value)
    assert np.all(coef[xi == 0] == 0.0)
    assert np.max(np.abs(coef - xi)) <= 1e-8 * np.max(np.abs(xi))


# ---------------------------------------------------------------------------------------------
# 3. Save/load round trips
# ---------------------------------------------------------------------------------------------

finite = st.floats(allow_nan=False, allow_infinity=False)


@st.composite
def models(draw):
    d = draw(st.integers(1, 3))
    masses = draw(st.lists(st.floats(min_value=0.0, exclude_min=True, allow_infinity=False),
                           min_size=d, max_size=d))
    keys = draw(st.lists(st.tuples(st.integers(0, d - 1), st.sampled_from(PHYSICS), st.integers(0, 6)),
                         max_size=12, unique=True))
    keys += [(i, "stiffness", 1) for i in range(d) if all(k[0] != i for k in keys)]  # a term per DOF
    with_err = draw(st.booleans())
    terms = []
    for dof, phys, order in keys:
        t = {"dof": dof, "physics": phys, "order": order, "coefficient": draw(finite)}
        if with_err:
            t["stderr"] = draw(st.floats(min_value=0.0, allow_infinity=False))
        terms.append(t)
    topology = draw(st.sampled_from(["chain", "independent"]))
    return masses, terms, topology


def _canonical(terms):
    return sorted(terms, key=lambda t: (PHYSICS.index(t["physics"]), t["dof"], t["order"]))


@settings(max_examples=80)
@given(models())
def test_model_json_round_trip_exact(tmp_path_factory, spec):
    """Whatever `from_terms` builds, `save_model` writes and `load_model` reads back exactly
    (masses, coefficient arrays, topology, terms with their stderr): random masses, topology,
    terms with arbitrary finite coefficients (zero included) and optional stderr."""
    masses, terms, topology = spec
    m = g.from_terms(masses, terms, topology)
    nonzero = [t for t in m.terms() if t["coefficient"] != 0.0]
    assert _canonical([t for t in terms if t["coefficient"] != 0.0]) == nonzero
    p = tmp_path_factory.mktemp("model") / "m.json"
    g.save_model(m, p, note="extra keys are kept out of the model")
    m2 = g.load_model(p)
    assert m2.topology.name == topology
    assert np.array_equal(np.asarray(m.masses), np.asarray(m2.masses))
    for name in ("stiffness", "velocity_damping", "position_damping"):
        # equal as coefficient tables: a zero-coefficient term may leave or drop trailing zeros
        a, b = np.asarray(getattr(m, name)), np.asarray(getattr(m2, name))
        size = max(a.shape[1], b.shape[1])
        a, b = (np.pad(z, ((0, 0), (0, size - z.shape[1]))) for z in (a, b))
        assert np.array_equal(a, b), name
    assert m2.terms() == m.terms()


@st.composite
def recordings(draw, csv=False):
    n = draw(st.sampled_from([64, 65, 100]))
    d = draw(st.integers(1, 3))
    t0 = draw(st.floats(-10.0, 10.0))
    dt = draw(st.floats(1e-4, 1e-1))
    t = t0 + dt * np.arange(n)
    vals = arrays(np.float64, st.just((n, d)), elements=finite)
    def varying(a):  # a constant x (nothing to fit), v or a column (a dead sensor) is not a recording
        for k in range(d):
            if np.all(a[:, k] == a[0, k]):
                a[0, k] = 1.0 if a[1, k] != 1.0 else 0.0
        return a

    x = varying(draw(vals))
    rec = {"t": t, "x": x}
    for key in ("v", "a", "force"):
        if draw(st.booleans()):
            rec[key] = varying(draw(vals)) if key != "force" else draw(vals)
    if draw(st.booleans()):
        rec["base_acc"] = draw(arrays(np.float64, st.just((n,)), elements=finite))
    if not csv and draw(st.booleans()):
        rec["masses"] = draw(arrays(np.float64, st.just((d,)),
                                    elements=st.floats(min_value=0.0, exclude_min=True, allow_infinity=False)))
    derived = tuple(k for k in ("v", "a") if k in rec and draw(st.booleans()))
    return g.Recording(**rec, name="r", derived=derived)


def _check_recording_round_trip(rec, rec2, csv):
    for key in ("t", "x", "v", "a", "base_acc", "force", "masses"):
        a, b = getattr(rec, key), getattr(rec2, key)
        if a is None or key in rec.derived or (csv and key == "masses"):
            assert b is None, key  # derived signals (and, in CSV, masses) are not written
        else:
            assert b.shape == a.shape and np.array_equal(a, b), key
    assert rec2.derived == ()


@settings(max_examples=40)
@given(recordings())
def test_recording_npz_round_trip_exact(tmp_path_factory, rec):
    """Random uniform time base, 1-3 DOFs, any finite values, optional v/a/force/base_acc/masses
    (v/a possibly marked derived, hence not written): NPZ gives back identical arrays."""
    p = tmp_path_factory.mktemp("rec") / "r.npz"
    g.save_recording(rec, p)
    _check_recording_round_trip(rec, g.load_recording(p), csv=False)


@settings(max_examples=25)
@given(recordings(csv=True))
def test_recording_csv_round_trip_exact(tmp_path_factory, rec):
    """CSV is written with np.savetxt's "%.18e" (19 significant digits): exact for float64."""
    p = tmp_path_factory.mktemp("rec") / "r.csv"
    g.save_recording(rec, p)
    _check_recording_round_trip(rec, g.load_recording(p), csv=True)


# ---------------------------------------------------------------------------------------------
# 4. A shift of x commutes with the local fit
# ---------------------------------------------------------------------------------------------

SHIFT_LIB = g.Library(3, 2)
SHIFT_N = 200
SHIFT_SOLVER = g.STLS(jnp.asarray(0.1), jnp.asarray(0.0), 20, True, True)


@st.composite
def local_problems(draw):
    p = SHIFT_LIB.n_terms
    seed = draw(st.integers(0, 2**32 - 1))
    support = np.array(draw(st.lists(st.booleans(), min_size=p, max_size=p)))
    mags = np.array(draw(st.lists(st.floats(0.5, 2.0), min_size=p, max_size=p)))
    signs = np.array(draw(st.lists(st.sampled_from([-1.0, 1.0]), min_size=p, max_size=p)))
    xe = draw(st.floats(-2.0, 2.0))
    amp = draw(st.floats(0.3, 1.0))
    c = draw(st.floats(-100.0, 100.0))
    return seed, np.where(support, signs * mags, 0.0), xe, amp, c


@settings(max_examples=25)
@given(local_problems())
def test_shift_of_x_commutes_with_local_fit(problem):
    """A recording around equilibrium xe (noise-free: y = Θ(x - mean x, v) ξ, ξ sparse with
    |ξ_k| in [0.5, 2]), fitted by `fit_local` with a fixed threshold (no cross-validation) and
    the package's physics solver semantics (normalised columns, no ridge). Shifting x by c
    (x -> x + c, the same v and targets) gives: equilibrium + c (to rounding), the same support,
    and the same local coefficients (1e-9 relative); both equal ξ (1e-8 relative)."""
    seed, xi, xe, amp, c = problem
    rng = np.random.default_rng(seed)
    x = xe + amp * rng.standard_normal(SHIFT_N)
    v = amp * rng.standard_normal(SHIFT_N)
    t = np.arange(SHIFT_N) * 1e-3
    q = jnp.asarray(x - np.mean(x))
    force = np.asarray(SHIFT_LIB(q, jnp.asarray(v))) @ xi
    # an independent unit mass, no input force: target y = -m a = F(x, v)
    rec = g.Recording(t=t, x=x[:, None], v=v[:, None], a=-force[:, None])
    shifted = replace(rec, x=rec.x + c)
    fits = []
    for r in (rec, shifted):
        y = g.regression_targets(r, np.ones(1), "independent")[:, 0]
        fits.append(g.fit_local(jnp.asarray(r.x[:, 0]), jnp.asarray(r.v[:, 0]), jnp.asarray(y),
                                SHIFT_LIB, SHIFT_SOLVER, None).value)
    f0, f1 = fits
    scale = max(np.max(np.abs(xi)), 1.0)
    assert abs(float(f1.equilibrium) - (float(f0.equilibrium) + c)) <= 1e-12 * (1 + abs(c) + abs(xe))
    np.testing.assert_array_equal(np.asarray(f0.coef) != 0, np.asarray(f1.coef) != 0)
    assert np.max(np.abs(np.asarray(f1.coef) - np.asarray(f0.coef))) <= 1e-9 * scale
    for f in fits:
        np.testing.assert_array_equal(np.asarray(f.coef) != 0, xi != 0)
        assert np.max(np.abs(np.asarray(f.coef) - xi)) <= 1e-8 * scale


# ---------------------------------------------------------------------------------------------
# 5. Loaders: only GMRInputError on junk, and only faithful acceptance
# ---------------------------------------------------------------------------------------------

SPECIAL_VALUES = [None, True, False, 0, -1, 1.5, -0.0, 10**30, math.nan, math.inf, -math.inf, "abc",
                  "1", "", "chain", "stiffness", FORMAT, [], {}, [1.0], {"dof": 0}]
SPECIAL = st.sampled_from(SPECIAL_VALUES)
json_scalars = (
    st.none() | st.booleans() | st.integers(-3, 10) | st.floats() | st.text(max_size=4) | SPECIAL
)
json_values = st.recursive(
    json_scalars,
    lambda ch: st.lists(ch, max_size=3)
    | st.dictionaries(st.sampled_from(["format", "masses", "terms", "topology", "dof", "order",
                                       "physics", "coefficient", "stderr"]) | st.text(max_size=3),
                      ch, max_size=4),
    max_leaves=8,
)
junk = SPECIAL | json_values


@st.composite
def valid_model_dicts(draw):
    masses, terms, topology = draw(models())
    d = {"format": FORMAT, "masses": masses, "terms": terms}
    if draw(st.booleans()):
        d["topology"] = topology
    return d


@st.composite
def mutated_model_dicts(draw):
    d = draw(valid_model_dicts())
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["top", "term_field", "term", "mass", "duplicate", "whole"]))
        if kind == "top":
            key = draw(st.sampled_from(["format", "masses", "terms", "topology"]))
            if isinstance(d, dict):
                if draw(st.booleans()):
                    d[key] = draw(junk)
                else:
                    d.pop(key, None)
        elif kind == "whole":
            d = draw(junk)
        elif isinstance(d, dict) and isinstance(d.get("terms"), list) and d["terms"]:
            i = draw(st.integers(0, len(d["terms"]) - 1))
            if kind == "term_field" and isinstance(d["terms"][i], dict):
                key = draw(st.sampled_from(["dof", "physics", "order", "coefficient", "stderr"]))
                if draw(st.booleans()):
                    d["terms"][i][key] = draw(junk)
                else:
                    d["terms"][i].pop(key, None)
            elif kind == "term":
                d["terms"][i] = draw(junk)
            elif kind == "duplicate":
                d["terms"].append(json.loads(json.dumps(d["terms"][i])))
        if kind == "mass" and isinstance(d, dict) and isinstance(d.get("masses"), list) and d["masses"]:
            d["masses"][draw(st.integers(0, len(d["masses"]) - 1))] = draw(junk)
    return d


def _integral(v) -> bool:
    return _is_number(v) and math.isfinite(v) and float(v).is_integer()


def _unfaithful_model(d, m) -> list[str]:
    """Why accepting `d` as model `m` was wrong (empty: acceptable). Lenient: extra keys, a
    missing `topology` or `terms` (defaults), integral floats for `dof`/`order`, a bare number
    as the masses of one DOF are fine. Rejecting any of these is fine too."""
    why = []
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        return ["not a gmr-model/1 dict"]
    topo = d.get("topology", "independent")
    if topo not in ("chain", "independent") or m.topology.name != topo:
        why.append(f"topology {topo!r} loaded as {m.topology.name!r}")
    masses = d.get("masses")
    masses = [masses] if _is_number(masses) else masses  # a bare number for one DOF: lenient
    if not isinstance(masses, list) or not masses or not all(_is_number(x) for x in masses):
        why.append(f"masses {masses!r} is not a non-empty list of numbers")
    elif [float(x) for x in masses] != np.asarray(m.masses).tolist():
        why.append("masses changed")
    terms = d.get("terms", [])
    if not isinstance(terms, list):
        return why + [f"terms {terms!r} is not a list"]
    want, err = {}, {}
    for t in terms:
        if not isinstance(t, dict):
            why.append(f"term {t!r} is not an object")
            continue
        dof, order, phys, c = t.get("dof"), t.get("order"), t.get("physics"), t.get("coefficient")
        if not (_integral(dof) and _integral(order) and phys in PHYSICS and _is_number(c)
                and math.isfinite(c)):
            why.append(f"term {t!r} has a missing or invalid field")
            continue
        if "stderr" in t and not _is_number(t["stderr"]):
            why.append(f"term {t!r} has a non-numeric stderr")
        key = (int(dof), phys, int(order))
        if key in want:
            why.append(f"duplicated term {key}")
        want[key] = float(c)
        if _is_number(t.get("stderr")) and math.isfinite(t["stderr"]):
            err[key] = float(t["stderr"])
    got = {(t["dof"], t["physics"], t["order"]): t["coefficient"] for t in m.terms()}
    if got != {k: c for k, c in want.items() if c != 0.0}:
        why.append(f"terms changed: {want} loaded as {got}")
    for t in m.terms():
        key = (t["dof"], t["physics"], t["order"])
        if key in err and t.get("stderr") != err[key]:
            why.append(f"stderr of {key} changed")
    for name in ("masses", "stiffness", "velocity_damping", "position_damping"):
        if not np.all(np.isfinite(np.asarray(getattr(m, name)))):
            why.append(f"{name} not finite")
    return why


def _load_model_text(path, text):
    path.write_text(text)
    try:
        return g.load_model(path)
    except g.GMRInputError:
        return None


@settings(max_examples=250)
@given(st.one_of(mutated_model_dicts(), json_values, valid_model_dicts()))
def test_load_model_junk_only_gmr_input_error(tmp_path_factory, d):
    p = tmp_path_factory.mktemp("junk") / "m.json"
    m = _load_model_text(p, json.dumps(d))  # anything but GMRInputError propagates: a failure
    if m is not None:
        why = _unfaithful_model(d, m)
        assert not why, f"accepted an invalid model: {why}"


FIELDS = ("format", "topology", "masses", "terms", "mass", "term", "dof", "physics", "order",
          "coefficient", "stderr")


def test_load_model_one_bad_field(tmp_path):
    """Exhaustive companion of the random junk: a valid 2-DOF model with exactly one field (a
    top-level key, the first mass, the first term or one of its keys) replaced by each special
    value (1.5, NaN, inf, 10**30, None, "abc", ...). Every offending case is listed at once."""
    base = {"format": FORMAT, "topology": "chain", "masses": [1.0, 2.0], "terms": [
        {"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -2.0, "stderr": 0.1},
        {"dof": 1, "physics": "stiffness", "order": 3, "coefficient": 5.0},
    ]}
    bad = []
    for field in FIELDS:
        for value in SPECIAL_VALUES:
            d = json.loads(json.dumps(base))
            if field in ("format", "topology", "masses", "terms"):
                d[field] = value
            elif field == "mass":
                d["masses"][0] = value
            elif field == "term":
                d["terms"][0] = value
            else:
                d["terms"][0][field] = value
            try:
                m = _load_model_text(tmp_path / "m.json", json.dumps(d))
            except Exception as e:  # noqa: BLE001 - collected, reported below
                bad.append(f"{field}={value!r}: {type(e).__name__}: {e}")
                continue
            why = [] if m is None else _unfaithful_model(d, m)
            if why:
                bad.append(f"{field}={value!r}: accepted: {why}")
    assert not bad, "\n".join(bad)


@settings(max_examples=60)
@given(st.text(max_size=60) | st.binary(max_size=60).map(lambda b: b.decode("latin-1")))
def test_load_model_junk_text(tmp_path_factory, text):
    p = tmp_path_factory.mktemp("junk") / "m.json"
    _load_model_text(p, text)


# -- recordings -------------------------------------------------------------------------------

REC_KEYS = ("t", "x", "v", "a", "base_acc", "force", "masses")
DTYPES = ["float64", "float32", "int64", "bool", "complex128", "<U3", "object", "datetime64[s]"]


@st.composite
def junk_npz(draw):
    """A recording's arrays (some valid, some with a wrong shape, dtype, NaN/inf or time base)."""
    n = draw(st.sampled_from([0, 1, 2, 63, 64, 80]))
    d = draw(st.integers(1, 3))
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    valid = {
        "t": np.arange(n) * 1e-3,
        "x": rng.standard_normal((n, d)),
        "v": rng.standard_normal((n, d)),
        "a": rng.standard_normal((n, d)),
        "base_acc": rng.standard_normal(n),
        "force": rng.standard_normal((n, d)),
        "masses": rng.uniform(0.5, 2.0, d),
    }
    out = {}
    for key in REC_KEYS + ("extra",):
        action = draw(st.sampled_from(["valid", "valid", "absent", "mutate"] if key in ("t", "x")
                                      else ["absent", "absent", "valid", "mutate"]))
        if action == "absent" or (key == "extra" and action == "valid"):
            continue
        arr = valid.get(key, np.zeros(n))
        if action == "mutate":
            what = draw(st.sampled_from(["shape", "dtype", "nonfinite", "time", "constant", "scalar"]))
            if what == "shape":
                dims = draw(st.lists(st.sampled_from([0, 1, 2, n, max(n - 1, 0), d, d + 1]),
                                     min_size=0, max_size=3))
                arr = rng.standard_normal(tuple(dims))
            elif what == "dtype":
                dt = draw(st.sampled_from(DTYPES))
                if dt == "object":
                    arr = arr.astype(object)
                elif dt == "datetime64[s]":
                    arr = (arr * 1e3).astype("int64").astype(dt)
                elif dt == "<U3":  # numbers as text, or words
                    text = draw(st.sampled_from(["%.1f", "abc"]))
                    arr = np.char.mod(text, arr).astype(dt) if arr.size else arr.astype(dt)
                elif dt == "complex128":
                    arr = arr + 1j * draw(st.sampled_from([0.0, 1.0]))
                else:
                    arr = arr.astype(dt)
            elif what == "nonfinite" and arr.size:
                arr = arr.copy()
                arr.flat[draw(st.integers(0, arr.size - 1))] = draw(st.sampled_from([np.nan, np.inf, -np.inf]))
            elif what == "time" and key == "t" and n > 2:  # repeated, jittered or decreasing
                arr = arr.copy()
                i = draw(st.integers(1, n - 2))
                arr[i] = draw(st.sampled_from([arr[i - 1], arr[i] + 3e-4, arr[i + 1] + 1.0]))
            elif what == "constant":
                arr = np.full(np.shape(arr), draw(st.sampled_from([0.0, 1.0, -3.5])))
            elif what == "scalar":
                arr = np.asarray(draw(st.sampled_from([0.0, 1.5, np.nan])))
        out[key] = arr
    return out


def _unfaithful_recording(stored: dict, rec) -> list[str]:
    """Why accepting these arrays as `rec` was wrong. Lenient: a 1-D `x`/`v`/`a`/`force` is one
    DOF, a (N, 1) base_acc is (N,)."""
    why = []
    t = rec.t
    if t.ndim != 1 or t.shape[0] < 64 or not np.all(np.isfinite(t)):
        why.append(f"t has shape {t.shape} or non-finite values")
    elif not (np.all(np.diff(t) > 0) and np.ptp(np.diff(t)) <= 1e-6 * np.mean(np.diff(t)) + 1e-12):
        why.append("t not uniform increasing")
    n, dd = t.shape[0], rec.x.shape[-1]
    for key in REC_KEYS:
        a = getattr(rec, key)
        if key not in stored:
            if a is not None and key not in rec.derived:  # x (and v) integrated from v or a: contracts
                why.append(f"{key} appeared")
            continue
        s = stored[key]
        if s.dtype.kind not in "biuf":
            why.append(f"{key} of dtype {s.dtype} accepted")
            continue
        if a is None or not np.array_equal(np.asarray(s, float).reshape(-1), a.reshape(-1)):
            why.append(f"{key} changed")
            continue
        if not np.all(np.isfinite(a)):
            why.append(f"{key} not finite")
        want = {"t": (n,), "base_acc": (n,), "masses": (dd,)}.get(key, (n, dd))
        if a.shape != want:
            why.append(f"{key} has shape {a.shape}, expected {want}")
    if "masses" in stored and rec.masses is not None and np.any(rec.masses <= 0):
        why.append("non-positive masses")
    return why


def _load_or_none(path):
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # numpy's ComplexWarning / empty-input warnings
            return g.load_recording(path)
    except g.GMRInputError:
        return None


@settings(max_examples=200)
@given(junk_npz())
def test_load_recording_npz_junk_only_gmr_input_error(tmp_path_factory, stored):
    p = tmp_path_factory.mktemp("junk") / "r.npz"
    np.savez(p, **stored)
    rec = _load_or_none(p)
    if rec is not None:
        why = _unfaithful_recording(stored, rec)
        assert not why, f"accepted an invalid recording: {why}"


CSV_NAMES = ["t", "x0", "x1", "v0", "a0", "f0", "f1", "base_acc", "x", "y", "", " t", "x00"]
CSV_CELLS = ["1", "-2.5e-3", "nan", "inf", "", "abc", "1,2", "0x10", " 3 ", "1e999"]


@st.composite
def junk_csv(draw):
    if draw(st.integers(0, 3)) == 0:  # free text
        return draw(st.text(max_size=80) | st.binary(max_size=80).map(lambda b: b.decode("latin-1")))
    names = draw(st.sampled_from([["t", "x0"], ["t", "x0", "x1"], []]))
    names = names + draw(st.lists(st.sampled_from(CSV_NAMES), min_size=0 if names else 1, max_size=3))
    names = [names[i] for i in draw(st.permutations(range(len(names))))]
    n = draw(st.sampled_from([0, 1, 63, 64, 70]))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    data = rng.standard_normal((n, len(names)))
    if "t" in names:
        data[:, names.index("t")] = np.arange(n) * 1e-3
    rows = [",".join(repr(float(v)) for v in row) for row in data]
    for _ in range(draw(st.integers(0, 3))):
        if not rows:
            break
        i = draw(st.integers(0, len(rows) - 1))
        cells = rows[i].split(",")
        op = draw(st.sampled_from(["cell", "drop", "add", "blank"]))
        if op == "cell":
            cells[draw(st.integers(0, len(cells) - 1))] = draw(st.sampled_from(CSV_CELLS))
        elif op == "drop" and len(cells) > 1:
            cells.pop()
        elif op == "add":
            cells.append(draw(st.sampled_from(CSV_CELLS)))
        else:
            cells = []
        rows[i] = ",".join(cells)
    return "\n".join([",".join(names)] + rows) + draw(st.sampled_from(["", "\n", "\n\n"]))


def _csv_table(text):
    """The header names and the numeric table of a clean CSV text (every row as many cells as
    the header, every cell a float), else None: the reference the loader is checked against."""
    lines = text.splitlines()
    if not lines:
        return None
    names = [h.strip() for h in lines[0].split(",")]
    rows = [r.split(",") for r in lines[1:] if r.strip()]
    try:
        table = np.array([[float(c) for c in r] for r in rows if len(r) == len(names)])
    except ValueError:
        return None
    if any(len(r) != len(names) for r in rows):
        return None
    return names, table.reshape(len(rows), len(names))


def _unfaithful_csv(text, rec) -> list[str]:
    """Lenient: unknown columns may be ignored. Not: a duplicated or gapped column name (which
    column is x0?), or loaded signals that differ from the columns named for them."""
    why = [w for w in _unfaithful_recording({"t": rec.t}, rec) if w.startswith("t ")]
    ref = _csv_table(text)
    if ref is None:
        return why + ["accepted a CSV that is not a clean numeric table"]
    names, table = ref
    col = {}
    for i, h in enumerate(names):
        key = h
        for pre in ("x", "v", "a", "f"):
            if h.startswith(pre) and h[1:].isdigit():
                key = (pre, int(h[1:]))
        if key in col and (key in ("t", "base_acc") or isinstance(key, tuple)):
            why.append(f"column {h!r} duplicated")
        col[key] = table[:, i]
    for pre, key in (("x", "x"), ("v", "v"), ("a", "a"), ("f", "force")):
        idx = sorted(k[1] for k in col if isinstance(k, tuple) and k[0] == pre)
        got = getattr(rec, key)
        if idx != list(range(len(idx))):
            why.append(f"columns {pre}{idx} have gaps")
        elif not idx:
            if got is not None:
                why.append(f"{key} appeared")
        elif got is None or not np.array_equal(got, np.stack([col[(pre, i)] for i in idx], axis=1)):
            why.append(f"{key} differs from columns {pre}0..")
    for key in ("t", "base_acc"):
        got = getattr(rec, key)
        if (key in col) != (got is not None) or (got is not None and not np.array_equal(got, col[key])):
            why.append(f"{key} differs from its column")
    for key in ("x", "v", "a", "force", "base_acc"):
        a = getattr(rec, key)
        if a is not None and (a.shape[0] != rec.t.shape[0] or not np.all(np.isfinite(a))):
            why.append(f"{key} invalid")
    return why


@settings(max_examples=150)
@given(junk_csv())
def test_load_recording_csv_junk_only_gmr_input_error(tmp_path_factory, text):
    p = tmp_path_factory.mktemp("junk") / "r.csv"
    p.write_text(text, encoding="utf-8")
    rec = _load_or_none(p)
    if rec is not None:
        why = _unfaithful_csv(text, rec)
        assert not why, f"accepted an invalid recording: {why}"


@st.composite
def plain_recordings(draw):
    """Valid recordings with awkward signals: constant, zero, a single step, tiny, huge."""
    n = draw(st.sampled_from([64, 100]))
    d = draw(st.integers(1, 2))
    t = np.arange(n) * 1e-3
    cols = []
    for _ in range(d):
        kind = draw(st.sampled_from(["sine", "constant", "zero", "step", "tiny", "huge"]))
        level = draw(st.floats(-2.0, 2.0))
        s = {"sine": np.sin(2 * np.pi * 20 * t), "constant": np.zeros(n), "zero": np.zeros(n),
             "step": (t > t[n // 2]).astype(float), "tiny": 1e-300 * np.sin(2 * np.pi * 20 * t),
             "huge": 1e150 * np.sin(2 * np.pi * 20 * t)}[kind]
        cols.append(s + (0.0 if kind == "zero" else level))
    return {"t": t, "x": np.stack(cols, axis=1)}


@settings(max_examples=20)
@given(plain_recordings(), st.sampled_from(["chain", "independent"]))
def test_loaded_recording_completes_without_crash(tmp_path_factory, stored, topology):
    """A recording the loader accepts must be usable: filling v and a (Savitzky-Golay,
    automatic window) raises nothing but GMRInputError. (The loader may refuse some of these,
    e.g. a constant displacement column.)"""
    p = tmp_path_factory.mktemp("rec") / "r.npz"
    np.savez(p, **stored)
    rec = _load_or_none(p)
    if rec is None:
        return
    try:
        rec.complete(topology)
    except g.GMRInputError:
        pass
