"""`plots.fit_figure` (the figure `gmr fit` writes): panels, data ranges, residual NRMSE, band."""

import numpy as np
import pytest

import gmr_jax as gmr
from gmr_jax._cli._fit import figure_path
from gmr_jax._errors import GMRInputError


def _chain_and_records():
    terms = [{"dof": i, "physics": "stiffness", "order": k, "coefficient": c}
             for i in range(2) for k, c in ((1, -4.0), (3, 4.0))]
    terms += [{"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": 0.2} for i in range(2)]
    model = gmr.from_terms([1.0, 1.0], terms, "chain")
    rng = np.random.default_rng(0)
    recs = []
    t = np.arange(2000) * 1e-3
    for k, x0 in enumerate((-1.0, 1.0)):
        x = x0 + 0.05 * np.column_stack([np.sin(9 * t), np.cos(7 * t)])
        v = 0.05 * np.column_stack([9 * np.cos(9 * t), -7 * np.sin(7 * t)])
        base = 0.1 * np.sin(3 * t)
        xdd = np.asarray(gmr.predict(model, x, v, base, np.zeros_like(x)))
        a = np.asarray(model.absolute_accelerations(xdd, base)) + 1e-3 * rng.normal(size=x.shape)
        recs.append(gmr.Recording(t=t, x=x, v=v, a=a, base_acc=base, masses=np.ones(2), name=f"S{k + 1}"))
    return model, recs


def test_fit_figure_panels_and_residuals(tmp_path):
    model, recs = _chain_and_records()
    calls = []

    def band(X):
        calls.append(X.shape)
        f = np.asarray(model.restoring(X.T)).T
        return f - 1.0, f + 1.0

    fig = gmr.plots.fit_figure(model, recs, tmp_path / "f.png", band=band, title="chain")
    assert (tmp_path / "f.png").stat().st_size > 10_000
    assert gmr.plots.fit_figure(model, recs, band="auto") is not None  # from_terms: no covariance, no band
    axes = fig.axes
    # three panels per DOF, and the band's half-width on its own axis beside each restoring panel
    assert len(axes) == 6 + 2 and calls and calls[0][1] == 2
    assert all("half-width" in ax.get_ylabel() for ax in axes[6:])
    # data ranges shaded per recording on each restoring panel, equilibria marked
    for i in range(2):
        ax_r = axes[3 * i]
        spans = [p for p in ax_r.patches]
        assert len(spans) >= 2
        labels = [t.get_text() for t in ax_r.get_legend().get_texts()]
        assert any(lab.startswith("95 % band (half-width <= 1") for lab in labels) and "S1: data range" in labels
        # residual legend carries the NRMSE of the force (noise-only residual: small)
        res_labels = [t.get_text() for t in axes[3 * i + 2].get_legend().get_texts()]
        nrmse = [float(s.rsplit(" ", 1)[1]) for s in res_labels]
        assert len(nrmse) == 2 and all(0 < n < 0.05 for n in nrmse)


def test_fit_figure_path_rule(tmp_path):
    assert figure_path("out/model.json", None).as_posix() == "out/model_fit.png"
    assert figure_path("m.json", "x/f.png").as_posix() == "x/f.png"
    with pytest.raises(GMRInputError, match="--figure must name a .png"):
        figure_path("m.json", "f.svg")


def test_figure_band_equals_force_band():
    import jax

    from gmr_jax.plots._fit import _model_band

    terms = [{"dof": 0, "physics": "stiffness", "order": k, "coefficient": c} for k, c in ((1, -4.0), (3, 4.0))]
    terms.append({"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.2})
    base = gmr.from_terms([1.0], terms)
    p = base.stiffness.shape[1] + base.velocity_damping.shape[1] + base.position_damping.shape[1]
    a = np.random.default_rng(1).normal(size=(p, p))
    model = gmr.GlobalModel(masses=base.masses, stiffness=base.stiffness, velocity_damping=base.velocity_damping,
                            position_damping=base.position_damping, covariance=(a @ a.T)[None] * 1e-2)
    x = np.linspace(-1.5, 1.5, 7)[:, None]
    lo, hi = _model_band(model)(x)
    ref = jax.vmap(lambda xx: gmr.force_band(model, xx))(x)
    np.testing.assert_allclose(lo, ref.lower, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(hi, ref.upper, rtol=1e-10, atol=1e-12)


def test_figure_damping_band_equals_force_band():
    """The damping panel's band (`_damping_band`, NumPy) is `force_band(part="damping")` at speeds away from 0
    (where the model's smoothed sign is the sign), position-dependent terms included."""
    import jax

    from gmr_jax.plots._fit import _damping_band

    terms = [{"dof": 0, "physics": "stiffness", "order": k, "coefficient": c} for k, c in ((1, -4.0), (3, 4.0))]
    terms += [{"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.2},
              {"dof": 0, "physics": "velocity_damping", "order": 2, "coefficient": 0.05},
              {"dof": 0, "physics": "position_damping", "order": 2, "coefficient": 0.3}]
    base = gmr.from_terms([1.0], terms)
    p = base.stiffness.shape[1] + base.velocity_damping.shape[1] + base.position_damping.shape[1]
    a = np.random.default_rng(2).normal(size=(p, p))
    model = gmr.GlobalModel(masses=base.masses, stiffness=base.stiffness, velocity_damping=base.velocity_damping,
                            position_damping=base.position_damping, covariance=(a @ a.T)[None] * 1e-2)
    x = np.repeat(np.linspace(-1.5, 1.5, 4), 4)[:, None]
    v = np.tile([-2.0, -0.5, 0.5, 2.0], 4)[:, None]
    lo, hi = _damping_band(model)(x, v)
    ref = jax.vmap(lambda xx, vv: gmr.force_band(model, xx, vv, part="damping"))(x, v)
    np.testing.assert_allclose(lo, ref.lower, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(hi, ref.upper, rtol=1e-8, atol=1e-10)
    assert np.all(hi - lo > 0)
