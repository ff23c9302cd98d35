"""The local fits on estimated accelerations take the differentiation filter's gain on both sides
(`_reconstruct/_slow.filter_gain`, `band_rows`), and the wells share their damping terms by BIC
(`_reconstruct._share_velocity_damping`). Checked against scipy's Savitzky-Golay filter and
against the simulated truth (NumPy, not the tool's numbers)."""

import warnings

import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._recordings._derivatives import differentiate, savgol_taps
from gmr_jax._reconstruct._slow import filter_gain


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("window", [15, 31])
def test_filter_gain_is_what_savitzky_golay_did_to_the_derivative(order, window):
    """On a chirp (5-35 Hz, 1 kHz), the scipy Savitzky-Golay derivative equals the exact derivative
    through `filter_gain` to 1e-9 of its scale, away from the edge fits; the filter itself is off by
    up to 10 % there (window 31, x'')."""
    dt = 1e-3
    t = np.arange(6000) * dt
    phase = 2 * np.pi * (5 * t + 30 * t**2 / 12)
    omega = 2 * np.pi * (5 + 30 * t / 6)
    x = np.sin(phase)
    exact = (omega * np.cos(phase) if order == 1
             else -omega**2 * np.sin(phase) + 2 * np.pi * 5 * np.cos(phase))
    inner = slice(200, -200)
    est = differentiate(x, dt, order, window)
    through = filter_gain(exact, savgol_taps(window, 5, order, dt), order, dt)
    scale = np.max(np.abs(exact))
    assert np.max(np.abs(est - through)[inner]) < 1e-9 * scale
    assert np.max(np.abs(est - exact)[inner]) > 1e-4 * scale  # the gain is not 1: the test has teeth
    # a constant passes unchanged (G(0) = 1), along axis 0 of a 2-D array too
    cols = filter_gain(np.stack([np.ones_like(t), exact], axis=1), savgol_taps(window, 5, order, dt), order, dt)
    assert np.allclose(cols[:, 0], 1.0) and np.allclose(cols[:, 1], through)


def test_displacement_only_sweeps_keep_the_true_damping_law():
    """Bistable joint (position-independent v^3 damping), x only, 40 dB, 0.5 degree sweeps, seed 5:
    on the raw columns the filter's shortfall on the third harmonic of v^3 read as a linear v and
    x v (the model 2.02 v + 8.84 v^3 - 0.43 x v, damping 11.3 % off over the box). Through the gain,
    with the wells sharing their damping terms by BIC: v^3 alone, within 2 %."""
    s = g.systems.bistable_joint("position_independent")
    recs = [g.Recording(t=r.t, x=r.x, base_acc=r.base_acc, masses=r.masses, name=r.name)
            for r in g.systems.make_recordings(s, np.deg2rad(0.5), snr_db=40, seed=5, duration=6.0)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = g.reconstruct(recs, g.Library(5, 5)).value
    xr, vr = s.x_range[0], s.v_range[0]
    # the damping against the truth's 10 v^3 on a grid (NumPy)
    x, v = np.meshgrid(np.linspace(*xr, 21), np.linspace(*vr, 41))
    fit = np.array([[float(model.damping(np.array([a]), np.array([b]))[0]) for a, b in zip(xx, vv)] for xx, vv in zip(x, v)])
    truth = 10.0 * v**3
    assert np.linalg.norm(fit - truth) / np.linalg.norm(truth) < 0.02  # measured 0.51 %
    kinds = {(t["physics"], t["order"]) for t in model.terms() if t["coefficient"] != 0}
    assert ("velocity_damping", 1) not in kinds and not any(p == "position_damping" for p, _ in kinds), kinds
    assert g.metrics.restoring_error(model, s.truth, 0, xr) < 0.002  # measured 0.033 %


@pytest.mark.parametrize("seed", [0, 2])
def test_joint_regression_on_steady_sines_takes_the_gain(seed, monkeypatch):
    """Bistable joint, x only, the steady response to a 10 Hz base sine about each well, 45 dB
    (`studies/joint_sine_records.py`): the joint regression's target holds G[x''] (its rows are not
    low-passed on a sine, the harmonics carry the nonlinearity), so its columns pass through G too
    (`_slow.gain_segments`). Seeds 0 and 2: 0.268 and 0.291 % on raw columns, 0.020 and 0.027 %
    through G, against the truth's cubic (NumPy)."""
    import jax
    import jax.numpy as jnp

    from gmr_jax._reconstruct import _slow

    joint = g.systems.bistable_joint()
    ts = jnp.arange(5001) / 1000.0
    inp = g.BaseSine(np.deg2rad(1.0), 10.0)
    base = np.asarray(jax.vmap(lambda t: inp(t)[0])(ts))
    rng = np.random.default_rng(seed)
    recs = [g.Recording(t=np.asarray(ts), x=g.add_noise(np.asarray(g.simulate(joint.truth, inp, ts, xe).value[0]), 45.0,
                                                        rng), base_acc=base, masses=np.ones(1), name=f"sine_S{i + 1}")
            for i, xe in enumerate(joint.equilibria)]
    grid = np.linspace(-1.5, 1.5, 301) * float(np.max(joint.equilibria))
    truth = np.polynomial.polynomial.polyval(grid, [0.0, g.systems.JOINT_STIFFNESS[0], 0.0, g.systems.JOINT_STIFFNESS[1]])

    def error():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sol = g.reconstruct(recs, throw=False)
        assert sol.stats["dofs"][0].stats["coordination"] == "joint"
        fit = np.polynomial.polynomial.polyval(grid, np.asarray(sol.value.stiffness[0]))
        return np.linalg.norm(fit - truth) / np.linalg.norm(truth)

    assert error() < 1e-3  # measured 0.020 / 0.027 %
    monkeypatch.setattr(_slow, "JOINT_GAIN", False)
    assert error() > 2e-3  # raw columns: 0.268 / 0.291 %: the test has teeth
