"""The discovery report's before/after, re-computed independently (issue 14).

Every single-DOF scenario of the concealed-physics suite is run through `discover` with its
defaults; both models (given and augmented, read back from the contract's model dicts) are then
re-simulated on the holdout with scipy (`solve_ivp`, DOP853, scipy's own cubic spline of the
input), and the output-error NRMSE recomputed with numpy. The test fails when the report's figure
differs by more than 10 % (relative), or when the report falls back to equation error without
saying why. What is shared with the tool is only the definition of the measure: the input
low-passed by `smooth_input`, the start sample `sim_start` (where an estimated v is an interior
estimate), and sgn(v) smoothed to tanh(v / eps), eps = 1e-3 x RMS(v) of the recording.
"""

from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline

import gmr_jax
from gmr_jax._discover._discover import sim_start, smooth_input
from studies.discover_scenarios import CONFOUNDED, CONTROLS, SCENARIOS
from studies.scenarios import build_full

RULE = gmr_jax.SelectionRule(n_boot=60)


def _force(terms: list[dict], x: float, v: float, eps: float) -> float:
    """F(x, v) of a one-DOF gmr-model/1 term list (contracts), sgn smoothed to tanh(v / eps)."""
    s = np.tanh(v / eps)
    out = 0.0
    for t in terms:
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


def scipy_output_nrmse(model, holdout) -> float:
    m, terms = float(np.asarray(model.masses)[0]), model.terms()
    num = den = 0.0
    for rec in holdout:
        b, f = rec.inputs()
        b, f = smooth_input(b, rec.dt), smooth_input(f, rec.dt)[:, 0]
        bs, fs = CubicSpline(rec.t, b), CubicSpline(rec.t, f)
        eps = 1e-3 * float(np.sqrt(np.mean(rec.v**2)))
        k = sim_start(rec)

        def rhs(t, y):
            x, v = y
            return [v, (fs(t) - _force(terms, x, v, eps)) / m - bs(t)]

        sol = solve_ivp(rhs, (rec.t[k], rec.t[-1]), [rec.x[k, 0], rec.v[k, 0]], method="DOP853",
                        t_eval=rec.t[k:], rtol=1e-9, atol=1e-12)
        assert sol.success, sol.message
        xm = rec.x[k:, 0]
        num += np.sum((sol.y[0] - xm) ** 2)
        den += np.sum((xm - xm.mean()) ** 2)
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


def _sdof(scs):
    return [s for s in scs if len(s.masses) == 1]


def test_report_matches_an_independent_scipy_resimulation():
    """One scenario in the default tier (shortened): Coulomb friction hidden in viscous damping."""
    sc = replace(SCENARIOS[0], duration=16.0)
    rep = check(sc)
    assert rep.before["kind"] == "output"


@pytest.mark.slow
@pytest.mark.parametrize("sc", _sdof(SCENARIOS + CONTROLS + CONFOUNDED), ids=lambda s: s.name)
def test_every_single_dof_scenario_matches_scipy(sc):
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
