"""The discovery report's before/after, re-computed independently (issue 14).

Every scenario of the concealed-physics suite (single DOFs and chains) is run through `discover`
with its defaults; both models (given and augmented, read back from the contract's model dicts) are then
re-simulated on the holdout with scipy (`solve_ivp`, DOP853, scipy's own cubic spline of the
input), and the output-error NRMSE recomputed with numpy. The test fails when the report's figure
differs by more than 10 % (relative), or when the report falls back to equation error without
saying why. What is shared with the tool is only the definition of the measure: the input
low-passed by `smooth_input`, the start sample `sim_start` (where an estimated v is an interior
estimate), sgn(v) smoothed to tanh(v / eps), eps = 1e-3 x RMS(v) of the recording, and for x
integrated from v or a (contracts) the equilibrium placed by each model (`_offset.place`) and
the drift removal applied to both sides (`_offset.comparable`). The equations of motion
(independent and chain) are written out here from the contracts.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline

import gmr_jax
from gmr_jax._simulate._free_run import sim_start
from gmr_jax._simulate._inputs import smooth_input
from gmr_jax._simulate._offset import comparable, place
from studies.discover_scenarios import CONFOUNDED, CONTROLS, SCENARIOS
from studies.scenarios import build_full

RULE = gmr_jax.SelectionRule(n_boot=60)


def _force(terms: list[dict], dof: int, x: float, v: float, eps: float) -> float:
    """F_dof(x, v) of a gmr-model/1 term list (contracts), sgn smoothed to tanh(v / eps)."""
    s = np.tanh(v / eps)
    out = 0.0
    for t in terms:
        if t["dof"] != dof:
            continue
        c, j = t["coefficient"], t["order"]
        if t["physics"] == "stiffness":
            out += c * x**j
        elif t["physics"] == "velocity_damping":
            out += c * (s if j == 0 else s * abs(v) ** j)
        elif t["physics"] == "position_damping":
            out += c * x**j * v
        else:
            raise AssertionError(f"unexpected physics {t['physics']}")
    return out


def _xdd(topology: str, m, terms, x, v, b, f, eps):
    """x'' of every DOF from the contracts' equations of motion, written out here: independent
    m_i a_i + F_i = f_i; chain (H a)_i + F_i = sum_{k>=i} f_k, i.e. m_k a_k = f_k - F_k + F_{k+1};
    a absolute (independent: x_i'' + b; chain: x_0'' + ... + x_i'' + b)."""
    d = len(m)
    F = [_force(terms, i, x[i], v[i], eps) for i in range(d)] + [0.0]
    if topology == "independent":
        return [(f[i] - F[i]) / m[i] - b for i in range(d)]
    a = [(f[k] - F[k] + F[k + 1]) / m[k] for k in range(d)]
    return [a[0] - b] + [a[i] - a[i - 1] for i in range(1, d)]


def scipy_output_nrmse(model, holdout) -> float:
    m, terms, topo = np.asarray(model.masses, float), model.terms(), model.topology.name
    d = m.size
    num = den = 0.0
    for rec in place(model, holdout)[0]:  # the contracts' unobserved equilibrium: the model's own
        b, f = rec.inputs()
        b, f = smooth_input(b, rec.dt), smooth_input(f, rec.dt)
        bs, fs = CubicSpline(rec.t, b), CubicSpline(rec.t, f, axis=0)
        eps = 1e-3 * float(np.sqrt(np.mean(rec.v**2)))
        k = sim_start(rec)

        def rhs(t, y):
            return np.concatenate([y[d:], _xdd(topo, m, terms, y[:d], y[d:], float(bs(t)), fs(t), eps)])

        sol = solve_ivp(rhs, (rec.t[k], rec.t[-1]), np.concatenate([rec.x[k], rec.v[k]]), method="DOP853",
                        t_eval=rec.t[k:], rtol=1e-9, atol=1e-12)
        assert sol.success, sol.message
        xs, xm = sol.y[:d].T, rec.x[k:]
        if "x" in rec.derived:  # x integrated from v or a: both sides as the integration left it
            xs, xm = comparable(rec, xs), comparable(rec, xm)
        num += np.sum((xs - xm) ** 2)
        den += np.sum((xm - xm.mean(0)) ** 2)
    return float(np.sqrt(num / den))


def check(sc):
    b = build_full(sc)
    rep = gmr_jax.discover(b.model, b.est, b.hold, rule=RULE).value
    hold = rep.series["holdout"]
    for label, e in (("before", rep.before), ("after", rep.after)):
        if e["kind"] != "output":
            assert e.get("why_not_output"), f"{sc.name}: {label} fell back to equation error silently"
            continue
    if rep.before["kind"] == "output":
        for label, m, e in (("before", rep.given, rep.before), ("after", rep.model, rep.after)):
            ours = scipy_output_nrmse(m, hold)
            assert e["nrmse"] == pytest.approx(ours, rel=0.10), (sc.name, label, e["nrmse"], ours)
    return rep


@pytest.mark.slow
@pytest.mark.parametrize("sc", SCENARIOS + CONTROLS + CONFOUNDED, ids=lambda s: s.name)
def test_every_scenario_matches_scipy(sc):
    check(sc)


def test_equation_error_says_why(rng):
    """A model with no restoring force (a closed-loop plant's mechanics) cannot be simulated
    under its recorded force: the report says so rather than falling back silently."""
    t = np.arange(4000) * 1e-3
    v = np.sin(2 * np.pi * 0.7 * t) * np.where(np.sin(2 * np.pi * 0.2 * t) > 0, 1.0, 0.6)
    x = np.cumsum(v) * 1e-3
    a = np.gradient(v, 1e-3)
    f = 2.0 * a + 30.0 * v + 5.0 * np.sign(v) + 0.05 * rng.normal(size=t.size)
    rec = gmr_jax.Recording(t=t, x=x[:, None], v=v[:, None], a=a[:, None], force=f[:, None], name="drive")
    model = gmr_jax.from_terms([2.0], [{"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 45.0}])
    rep = gmr_jax.discover(model, [rec], rule=RULE).value
    assert rep.before["kind"] == "equation"
    assert "no restoring" in rep.before["why_not_output"] and "closed loop" in rep.before["why_not_output"]
    assert "error measure: equation (force) error" in rep.summary()
    rep2 = gmr_jax.discover(model, [rec], rule=RULE, error="equation").value
    assert "asked for" in rep2.before["why_not_output"]
