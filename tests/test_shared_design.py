"""Cells of one design lend their curvature (`_reconstruct/_shape_prior.py`, issue 15)."""

import json
import warnings

import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._fit._library import STIFFNESS
from gmr_jax._fit._local_fit import LocalFit
from gmr_jax._reconstruct._shape_prior import TAU_FLOOR, refit_with_prior, share_curvature


# -- the plan, on exact Taylor data ------------------------------------------------------------

def _shape(u, saddle=0.4):
    """A degree-7 double well G(u) with wells at u = 0 and 1 (no quintic reproduces it)."""
    return 10 * u * (u - saddle) * (u - 1) * (1 + 2 * u**2 + u**4)


def _taylor(fun, x0, order, h=1e-3):
    """F^(m)(x0) / m!, m = 0..order, of a polynomial callable (exact: a polynomial fit)."""
    u = x0 + h * np.linspace(-1, 1, 21)
    c = np.polynomial.polynomial.polyfit(u - x0, fun(u), 9)
    return c[: order + 1]


def _fits(lib, cells):
    """Stacked LocalFits of several DOFs: `cells` = [(scale, span, orders per well, rel_se, saddle)]."""
    idx = [lib.terms().index((STIFFNESS, k)) for k in range(lib.restoring_order + 1)]
    out = []
    for scale, span, orders, rel, saddle in cells:
        eq = np.array([0.0, span])
        coef = np.zeros((2, lib.n_terms))
        cov = np.zeros((2, lib.n_terms, lib.n_terms))
        for k, x0 in enumerate(eq):
            tay = _taylor(lambda x: scale * _shape(x / span, saddle), x0, orders[k])
            for m in range(1, orders[k] + 1):
                coef[k, idx[m]] = tay[m]
                cov[k, idx[m], idx[m]] = (rel * tay[m]) ** 2
        out.append(LocalFit(equilibrium=eq, coef=coef, covariance=cov, threshold=np.zeros(2),
                            rss=np.ones(2), n_samples=np.full(2, 1000.0)))
    return out, idx


def test_a_weak_cell_borrows_the_orders_the_others_resolve_as_dimensionless_ratios():
    lib = g.Library(4, 1)
    fits, idx = _fits(lib, [(1.0, 1.0, (4, 4), 1e-4, 0.4), (3.0, 0.5, (3, 3), 1e-4, 0.4),
                            (0.2, 2.0, (1, 2), 1e-3, 0.4)])
    plan, summary = share_curvature(fits, lib, n_sigma=3.0)
    assert summary["members"] == [0, 1, 2] and summary["tau"] < 1e-3
    weak = plan[2]
    assert sorted(weak[0]) == [2, 3, 4] and sorted(weak[1]) == [2, 3, 4]
    for k, x0 in enumerate((0.0, 1.0)):
        tay = _taylor(_shape, x0, 4)
        for m in (2, 3, 4):
            rho, sd = weak[k][m]
            assert rho == pytest.approx(tay[m] / tay[1], rel=1e-3)  # the unit-span ratio
            assert sd >= TAU_FLOOR * abs(rho) * 0.999  # never tighter than the design tolerance
    # the strongest cell borrows only what another cell resolves (orders 2, 3: cell 1 stops at 3)
    assert sorted(plan[0][0]) == [2, 3]


def test_a_cell_of_another_design_neither_lends_nor_borrows():
    lib = g.Library(4, 1)
    # cell 2's saddle at 0.6 instead of 0.4: its stiffness ratio between the wells differs
    fits, _ = _fits(lib, [(1.0, 1.0, (4, 4), 1e-4, 0.4), (3.0, 0.5, (3, 3), 1e-4, 0.4),
                          (0.2, 2.0, (1, 2), 1e-3, 0.6)])
    plan, summary = share_curvature(fits, lib, n_sigma=3.0)
    assert plan[2] is None and 2 not in summary["members"]
    assert "disagree" in summary["excluded"][2]


def test_cells_of_different_designs_share_nothing():
    lib = g.Library(4, 1)
    fits, _ = _fits(lib, [(1.0, 1.0, (4, 4), 1e-4, 0.3), (3.0, 0.5, (3, 3), 1e-4, 0.5)])
    plan, summary = share_curvature(fits, lib, n_sigma=3.0)
    assert plan == [None, None]


# -- the refit with the prior -------------------------------------------------------------------

def _well_data(n=3000, amp=0.02, noise=1e-3, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 500.0
    q = sum(amp / 3 * np.sin(2 * np.pi * f * t + rng.uniform(0, 6.3)) for f in (1.3, 3.1, 7.7))
    v = np.gradient(q, t)
    y = 2.0 * q + 1.5 * q**2 + 4.0 * q**3 + 0.3 * v + noise * rng.standard_normal(n)
    return q, v, y


def test_refit_with_prior_is_the_gaussian_posterior_and_has_the_right_limits():
    lib = g.Library(3, 1)  # 1, x, x^2, x^3, sgn v, v, x v
    q, v, y = _well_data()
    theta = np.asarray(lib(q, v))
    own = np.array([True, True, True, False, False, True, False])  # the fit stops at q^2
    c_own = np.zeros(lib.n_terms)
    c_own[own] = np.linalg.lstsq(theta[:, own], y, rcond=None)[0]
    rss = float(np.sum((y - theta @ c_own) ** 2))
    w = np.ones_like(q)
    span, rho, sd = 0.5, 4.0 * 0.5**2 / 2.0, 0.05  # prior a3 = rho a1 / L^2 = 4.0 (the truth)
    coef, cov = refit_with_prior(q, v, y, w, lib, c_own, rss, q.size, span, {3: (rho, sd)})
    # independent: the normal equations of the Gaussian posterior, solved directly
    cols = np.array([0, 1, 2, 3, 5])
    a = theta[:, cols]
    s2 = rss / (q.size - own.sum())
    prior = np.zeros(cols.size)
    prior[3], prior[1] = 1.0, -rho / span**2
    s_p = sd * abs(c_own[1]) / span**2
    lhs = a.T @ a / s2 + np.outer(prior, prior) / s_p**2
    expect = np.linalg.solve(lhs, a.T @ y / s2)
    np.testing.assert_allclose(coef[cols], expect, rtol=1e-6)
    np.testing.assert_allclose(cov[np.ix_(cols, cols)], np.linalg.inv(lhs), rtol=1e-5)
    assert coef[4] == 0 and coef[6] == 0
    # limits: a vague prior is the least-squares fit with q^3, a sharp one pins a3 to rho a1 / L^2
    vague, _ = refit_with_prior(q, v, y, w, lib, c_own, rss, q.size, span, {3: (rho, 1e8)})
    np.testing.assert_allclose(vague[cols], np.linalg.lstsq(a, y, rcond=None)[0], rtol=1e-6)
    sharp, _ = refit_with_prior(q, v, y, w, lib, c_own, rss, q.size, span, {3: (rho, 1e-9)})
    assert sharp[3] == pytest.approx(rho * sharp[1] / span**2, rel=1e-6)


# -- end to end: two DOFs of one design, one barely excited ---------------------------------------

def _recordings(saddles=(0.4, 0.4), amps=(0.08, 0.004), spans=(1.0, 0.5), scales=(1.0, 3.0), seed=0):
    """Two independent DOFs (force inputs), each F_j(x) = s_j G_j(x / L_j), recorded in both wells."""
    rng = np.random.default_rng(seed)
    t = np.arange(6000) / 500.0
    m = np.array([1.0, 1.0])
    recs = []
    for well in (0, 1):
        xs, vs, as_, fs = [], [], [], []
        for j in range(2):
            phase = rng.uniform(0, 6.3, 4)
            fr = np.array([0.9, 2.3, 4.1, 6.6])
            q = amps[j] * spans[j] / 4 * sum(np.sin(2 * np.pi * f * t + p) for f, p in zip(fr, phase))
            v = amps[j] * spans[j] / 4 * sum(2 * np.pi * f * np.cos(2 * np.pi * f * t + p) for f, p in zip(fr, phase))
            acc = -amps[j] * spans[j] / 4 * sum((2 * np.pi * f) ** 2 * np.sin(2 * np.pi * f * t + p)
                                                 for f, p in zip(fr, phase))
            x = well * spans[j] + q
            force = m[j] * acc + scales[j] * _shape(x / spans[j], saddles[j]) + 0.2 * v
            xs.append(x), vs.append(v), as_.append(acc)
            fs.append(force + 1e-5 * scales[j] * rng.standard_normal(t.size))
        recs.append(g.Recording(t=t, x=np.stack(xs, 1), v=np.stack(vs, 1), a=np.stack(as_, 1),
                                force=np.stack(fs, 1), masses=m, name=f"well{well}"))
    return recs


def _error(model, j, saddle, span, scale):
    """Relative L2 error of DOF j's restoring force over [-0.1 L, 1.1 L], by NumPy."""
    x = np.linspace(-0.1 * span, 1.1 * span, 401)
    fit = np.polynomial.polynomial.polyval(x, np.asarray(model.stiffness[j]))
    true = scale * _shape(x / span, saddle)
    return float(np.sqrt(np.mean((fit - true) ** 2) / np.mean(true**2)))


def _fit(recs, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return g.reconstruct(recs, g.Library(5, 3), topology="independent", **kw)


def test_one_design_the_barely_excited_dof_reaches_the_well_excited_ones_accuracy():
    recs = _recordings()
    alone = _fit(recs, shared_design=False)
    shared = _fit(recs)
    e_alone = _error(alone.value, 1, 0.4, 0.5, 3.0)
    e_shared = _error(shared.value, 1, 0.4, 0.5, 3.0)
    info = shared.stats["dofs"][1].stats["shared_design"]
    assert info["used"] and all(3 in b for b in info["borrowed"]), info
    assert e_alone > 0.05 and e_shared < 0.25 * e_alone, (e_alone, e_shared)
    # the well-excited DOF is not made worse by what it borrowed
    assert _error(shared.value, 0, 0.4, 1.0, 1.0) <= 1.2 * _error(alone.value, 0, 0.4, 1.0, 1.0) + 1e-4
    # the report keeps the local fits from the data alone (the resolution report reads them)
    np.testing.assert_array_equal(shared.stats["dofs"][1].local_coef, alone.stats["dofs"][1].local_coef)


def test_two_designs_the_fit_is_the_per_dof_one():
    recs = _recordings(saddles=(0.4, 0.6))
    alone = _fit(recs, shared_design=False)
    shared = _fit(recs)
    info = shared.stats["dofs"][1].stats["shared_design"]
    assert not info["used"] and "why" in info
    np.testing.assert_array_equal(np.asarray(shared.value.stiffness), np.asarray(alone.value.stiffness))


def test_command_line_records_and_shows_what_was_lent_and_can_switch_it_off(tmp_path, capsys):
    from gmr_jax._cli._main import main

    paths = []
    for r in _recordings():
        paths.append(str(tmp_path / f"{r.name}.npz"))
        g.save_recording(r, paths[-1])
    common = ["fit", *paths, "-r", "5", "-d", "3", "--topology", "independent", "--no-figure"]
    assert main(common + ["--out", str(tmp_path / "on.json")]) == 0
    assert main(common + ["--out", str(tmp_path / "off.json"), "--no-shared-design"]) == 0
    on, off = (json.loads((tmp_path / f"{k}.json").read_text()) for k in ("on", "off"))
    assert off.get("shared_design") is None
    design = on["shared_design"]
    assert len(design) == 2 and design[1]["used"] and all(3 in b for b in design[1]["borrowed"])
    # the borrowing DOF's global degree is recorded: the file's own polynomial has it
    degree = max(t["order"] for t in on["terms"] if t["physics"] == "stiffness" and t["dof"] == 1 and t["coefficient"])
    assert design[1]["degree"] == degree and degree % 2 == 1 and isinstance(design[1]["degree_notes"], list)
    # the file's model is the API's (the command line adds nothing of its own)
    api = _fit(_recordings())
    k_file = {(t["dof"], t["order"]): t["coefficient"] for t in on["terms"] if t["physics"] == "stiffness"}
    for (dof, order), c in k_file.items():
        assert c == pytest.approx(float(api.value.stiffness[dof, order]), rel=1e-9, abs=1e-12)
    capsys.readouterr()
    assert main(["show", str(tmp_path / "on.json"), "--detail"]) == 0
    out = capsys.readouterr().out
    assert "Cells of one design" in out and "DOF 1: borrowed well 0: q^" in out
    assert f"; global degree {degree}" in out
    # the coordination route of each DOF and the auto route's notes are in the file and printed
    routes = on["coordination"]
    assert [r["route"] for r in routes] == [api.stats["dofs"][i].stats["coordination"] for i in range(2)]
    assert all(isinstance(r["notes"], list) for r in routes)
    assert "Coordination (the route per DOF and why):" in out and f"DOF 1: {routes[1]['route']}" in out
