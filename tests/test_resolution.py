"""The per-well resolution report and its excitation advice (issue 15)."""

import json
import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._cli._main import main
from gmr_jax._reconstruct._resolution import BOUND_FRACTION, SAFETY, hermite_influence


def test_influence_is_the_rms_of_the_cardinal_hermite_polynomials():
    """H_ik: Taylor coefficient 1 of order k at node i, 0 for every other condition; checked
    against the public Hermite interpolant."""
    nodes = np.array([-1.09, 0.884])
    lo, hi = -1.6, 1.4
    inf = hermite_influence(nodes, 2, lo, hi)
    xs = np.linspace(lo, hi, 201)
    for i in range(2):
        for k in range(3):
            taylor = np.zeros((2, 3))
            taylor[i, k] = 1.0
            coef, deg, _ = g.hermite_interpolate(jnp.asarray(nodes), jnp.asarray(taylor), jnp.array([2, 2]))
            h = np.polynomial.polynomial.polyval(xs, np.asarray(coef)[: int(deg) + 1])
            assert inf[i, k] == pytest.approx(float(np.sqrt(np.mean(h**2))), rel=1e-8)
    # the value polynomials sum to 1 (interpolating a constant) and each is O(1)
    assert 0.3 < inf[0, 0] < 1.0 and inf[0, 2] < inf[0, 1] < inf[0, 0]


def _joint(amplitude, snr_db, seed=0):
    s = g.systems.bistable_joint()
    recs = g.systems.make_recordings(s, amplitude, snr_db=snr_db, seed=seed, duration=5.0)  # test_sanity.DURATION: shared compiled fits
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sol = g.reconstruct(recs)
    return sol, [str(w.message) for w in caught if issubclass(w.category, g.GMRDataWarning)]


@pytest.fixture(scope="module")
def nominal():
    return _joint(0.05, 60.0)


@pytest.fixture(scope="module")
def weak():
    return _joint(2e-4, 30.0)


def test_nominal_joint_resolves_every_needed_term_silently(nominal):
    sol, caught = nominal
    rep = sol.stats["resolution"]
    assert isinstance(rep, g.ResolutionReport)
    assert len(rep.wells) == 2 and rep.missing() == [] and rep.advice() == []
    assert not any("do not resolve" in w for w in caught)
    for w in rep.wells:
        assert [t.order for t in w.terms] == [0, 1, 2, 3]
        assert all(t.resolved for t in w.terms if t.needed)
        assert w.terms[2].significant  # F'' of a cubic: 6e3 at the wells, many standard errors
    text = str(rep)
    assert text.startswith("| DOF | well x |") and text.count("\n| 0 |") == 2
    json.dumps(rep.to_dict())  # plain JSON for the model file


def test_weak_excitation_is_warned_with_advice_that_follows_the_scaling(weak):
    """At 30 dB and ~0.05 % of the interwell distance the curvature is not resolved: a
    GMRDataWarning names the well, the term and the amplitude that would resolve it; that
    amplitude is the current one times rho^(1/(k-1)), rho = bound / threshold."""
    sol, caught = weak
    rep = sol.stats["resolution"]
    miss = rep.missing()
    assert miss, str(rep)
    w, t = miss[0]
    assert t.needed and not t.resolved and t.order >= 2
    assert t.impact > BOUND_FRACTION
    assert t.rho == pytest.approx(SAFETY * t.impact / BOUND_FRACTION, rel=1e-9)
    assert t.advised_ratio == pytest.approx(w.ratio * t.rho ** (1 / (t.order - 1)), rel=1e-9)
    assert any("do not resolve" in m and t.name in m and "% of the interwell distance" in m for m in caught), caught
    assert any("do not resolve" in m for m in sol.stats["warnings"])
    assert "**NO**" in rep.table()


@pytest.mark.slow
def test_advised_amplitude_resolves_the_term():
    """The advice checked by simulation on a non-polynomial truth (the shallow arch, 30 dB, x v a,
    base sweep at 0.2 % of the interwell distance): F'' is unresolved and warned; re-recorded
    with the base amplitude scaled to the advised response amplitude (the arch responds
    linearly at these amplitudes), same seed and noise level, it is resolved and not warned.
    (The bistable joint is no test of the scaling: its cubic damping changes the response
    spectrum with amplitude.)"""
    s = g.systems.shallow_arch()
    base = 0.003 * 0.2 / 1.61  # 0.003 gives 1.61 % at the more excited well

    def fit(amp):
        recs = g.systems.make_recordings(s, amp, snr_db=30.0, seed=0)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            sol = g.reconstruct(recs)
        return sol.stats["resolution"], [str(w.message) for w in caught]

    rep, caught = fit(base)
    assert any(t.order == 2 for _, t in rep.missing()), str(rep)
    assert any("do not resolve F''" in m for m in caught)
    factor = max(t.advised_ratio / w.ratio for w, t in rep.missing())
    again, caught = fit(base * factor)
    assert again.missing() == [], str(again)
    assert not any("do not resolve" in m for m in caught)


def test_show_prints_the_stored_resolution(tmp_path, capsys, nominal):
    sol, _ = nominal
    p = tmp_path / "m.json"
    g.save_model(sol.value, p, method="GMR", resolution=sol.stats["resolution"].to_dict())
    assert main(["show", str(p), "--detail"]) == 0
    out = capsys.readouterr().out
    assert "What each well's data resolved" in out and "F'' ok" in out
    assert "  resolution: " not in out  # shown as its own section, not as an unknown key


@pytest.mark.slow
def test_reduced_stress_set():
    """A reduced `studies/stress_cases.py` (the shallow arch, x v a, 30 dB, float32 time stamps, 0.45 %
    of the interwell distance): defaults give no spurious well, no diverging free or forced run, a
    restoring error within 2x of the curvature oracle's; the unresolved curvature is warned."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "studies"))
    import stress_cases as sc

    case = sc.Case("arch_xva_f32", "arch", "xva", True)
    row = sc.evaluate(case, sc.base_amplitude(case.make_system(), case.ratio), 0)
    assert all(0.002 <= r <= 0.005 for r in row["ratios"]), row["ratios"]
    assert row["pass"]["wells"] and row["pass"]["divergence"], row
    assert row["pass"]["error"], row["dofs"]
    assert row["warned"] and row["resolution"].missing()
