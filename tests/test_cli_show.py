"""`gmr show` and `gmr --version`."""

import json

import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._cli._main import main


@pytest.fixture
def model_file(tmp_path):
    k1, k3 = -2.0, 8.0  # wells at +-0.5, saddle at 0, barrier k1^2 / (4 k3) = 0.125
    terms = [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": k1, "stderr": 0.01},
             {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": k3, "stderr": 0.02},
             {"dof": 0, "physics": "stiffness", "order": 2, "coefficient": 1e-4, "stderr": 0.3},
             {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.05}]
    d = {"format": "gmr-model/1", "topology": "independent", "masses": [0.5], "terms": terms,
         "method": "GMR", "library": {"r": 5, "d": 5}, "data_range": [[-0.6, 0.6]],
         "training": {"rec_a": {"r2": [0.999], "nrmse": [0.01]}},
         "warnings": ["rec_b: the sweep barely leaves its noise floor"], "refinement": {"iterations": 3}}
    p = tmp_path / "m.json"
    p.write_text(json.dumps(d))
    return p


def test_show_equations_wells_barriers_metadata(model_file, capsys):
    assert main(["show", str(model_file)]) == 0
    out = capsys.readouterr().out
    assert "F_0(x, v) =" in out and "1 DOF, topology independent" in out
    # standard errors, and the one that does not pin its coefficient down is starred
    row = next(line for line in out.splitlines() if line.strip().startswith("x^2 "))
    assert "0.3" in row and row.rstrip().endswith("*")
    assert "std. error" in out
    wells = [line for line in out.splitlines() if "x = " in line]
    assert len(wells) == 3 and "stable" in wells[0] and "saddle" in wells[1] and "stable" in wells[2]
    assert "-0.5" in wells[0] and "stable wells per DOF: [2]" in out
    assert "0.125 from the left well" in out
    assert "rec_a" in out and "rec_b: the sweep barely" in out
    assert "data range of x: DOF 0 [-0.6, 0.6]" in out
    # the file's other keys: with --detail
    assert "refinement" not in out and "--detail" in out
    assert main(["show", str(model_file), "--detail"]) == 0
    assert "refinement" in capsys.readouterr().out


def test_show_barriers_match_numeric_integral(tmp_path):
    from gmr_jax._cli._show import barriers, equilibria

    k = np.array([[0.01, -3.0, 0.2, 10.0, 0.0, 1.0]])
    eqs = equilibria(k)
    b = barriers(k, eqs)[0][0]
    xs = np.linspace(b["left"], b["saddle"], 20001)
    f = np.polynomial.polynomial.polyval(xs, k[0])
    np.testing.assert_allclose(b["from_left"], np.trapezoid(f, xs), rtol=1e-6)


def test_show_without_stderr_or_metadata(tmp_path, capsys):
    g.save_model(g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": 3.0}]),
                 tmp_path / "m.json")
    assert main(["show", str(tmp_path / "m.json")]) == 0
    out = capsys.readouterr().out
    assert "no standard errors stored" in out and "none (no DOF has two stable wells" in out
    assert "Warnings stored with the model: none" in out


def test_show_bad_file_exit_2(tmp_path, capsys):
    assert main(["show", str(tmp_path / "missing.json")]) == 2
    err = capsys.readouterr().err
    assert "no such model file" in err and len(err.strip().splitlines()) == 1


def test_version(capsys):
    import gmr_launch

    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    assert capsys.readouterr().out.strip() == f"gmr_jax {g.__version__}"
    assert gmr_launch.main(["--version"]) == 0  # the console script answers without importing gmr_jax
    assert capsys.readouterr().out.strip() == f"gmr_jax {g.__version__}"


def test_show_gives_the_barriers_an_interval_from_the_covariance(tmp_path, capsys):
    """With a covariance in the file, each barrier and saddle gets the 95 % range over models drawn from it,
    checked against the linear propagation of the same covariance (barrier k1^2 / (4 k3) of F = k1 x + k3 x^3,
    the saddle at 0); without one, `gmr show` says the numbers carry no interval."""
    from gmr_jax._cli._show import barrier_intervals, barriers, equilibria

    k1, k3, s1, s3 = -2.0, 8.0, 0.02, 0.1
    cov = [{"dof": 0, "terms": [["stiffness", 1], ["stiffness", 3]], "matrix": [[s1**2, 0.0], [0.0, s3**2]]}]
    model = g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": k1},
                                 {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": k3}], covariance=cov)
    bars = barriers(model.stiffness, equilibria(model.stiffness))
    s = barrier_intervals(model, bars, n=4000)[0][0]
    sd = np.hypot(2 * k1 / (4 * k3) * s1, k1**2 / (4 * k3**2) * s3)  # d(k1^2/4k3)
    np.testing.assert_allclose(s["from_left"], 0.125 + 1.96 * sd * np.array([-1, 1]), rtol=0.03)
    assert s["kept"] == 1.0 and abs(s["saddle"][0]) < 1e-12 and abs(s["saddle"][1]) < 1e-12
    g.save_model(model, tmp_path / "m.json")
    assert main(["show", str(tmp_path / "m.json")]) == 0
    assert "95 % of the models drawn from the file's covariance: saddle" in capsys.readouterr().out
    g.save_model(g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": k1},
                                      {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": k3}]),
                 tmp_path / "n.json")
    assert main(["show", str(tmp_path / "n.json")]) == 0
    assert "no covariance in this file: no interval" in capsys.readouterr().out
