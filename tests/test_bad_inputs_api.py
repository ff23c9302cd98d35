"""Issue 13: every bad input a user can hand the public API raises `GMRInputError` at call time,
with a one-line message that names the offending key/column/sample/argument and the fix.

One table, one test: `CASES` rows are (id, a zero-argument callable that makes the bad call, a
regex the message must match). `table()` returns (id, message) for every row, for a report
(it runs outside pytest: temporary files are made inside the callables).
"""

import json
import os
import tempfile

import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g

N = 200  # samples of the recordings below (>= the 64 a fit needs)


# -- helpers -------------------------------------------------------------------------------------
def _term(**kw):
    t = {"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -1.0}
    t.update(kw)
    return t


def _model(terms=None, masses=(1.0,), **kw):
    d = {"format": "gmr-model/1", "topology": "independent", "masses": list(masses),
         "terms": [_term()] if terms is None else terms}
    d.update(kw)
    return d


def _drop(d, key):
    d = dict(d)
    del d[key]
    return d


def _load_model_dict(**kw):
    return lambda: g.load_model(_model(**kw))


def _load_model_file(name, content):
    """load_model on a file holding `content` (str, bytes, a dict as JSON, or a callable that
    writes the path) in a fresh temporary directory."""

    def call():
        with tempfile.TemporaryDirectory() as d:
            p = os.path.join(d, name)
            if callable(content):
                content(p)
            elif isinstance(content, bytes):
                with open(p, "wb") as fh:
                    fh.write(content)
            else:
                with open(p, "w") as fh:
                    fh.write(content if isinstance(content, str) else json.dumps(content))
            g.load_model(p)

    return call


def _signals(**kw):
    t = np.arange(N) * 1e-3
    out = {"t": t, "x": np.sin(2 * np.pi * 5 * t)[:, None]}
    out.update(kw)
    return {k: v for k, v in out.items() if v is not None}


def _load_npz(**kw):
    def call():
        with tempfile.TemporaryDirectory() as d:
            p = os.path.join(d, "rec.npz")
            np.savez(p, **_signals(**kw))
            g.load_recording(p)

    return call


def _csv_text(header="t,x0", mutate=None):
    t = np.arange(N) * 1e-3
    rows = [f"{float(a)!r},{float(b)!r}" for a, b in zip(t, np.sin(2 * np.pi * 5 * t))]
    if mutate:
        mutate(rows)
    return "\n".join([header] + rows) + "\n"


def _load_file(name, content):
    def call():
        with tempfile.TemporaryDirectory() as d:
            p = os.path.join(d, name)
            if callable(content):
                content(p)
            else:
                with open(p, "wb" if isinstance(content, bytes) else "w") as fh:
                    fh.write(content)
            g.load_recording(p)

    return call


def _in_tmp(fn):
    """fn(tmpdir) inside a fresh temporary directory."""

    def call():
        with tempfile.TemporaryDirectory() as d:
            fn(d)

    return call


def _save_npy(path):
    with open(path, "wb") as fh:  # np.save on a file object keeps the .npz name
        np.save(fh, np.zeros(3))


def _set_row(i, text):
    def mutate(rows):
        rows[i] = text

    return mutate


def _simulate(**kw):
    m = g.from_terms([1.0, 1.0], [_term(dof=0), _term(dof=1)])
    args = {"model": m, "inputs": g.NoInput(), "ts": jnp.linspace(0.0, 1.0, 11), "x0": jnp.zeros(2)}
    args.update(kw)
    return lambda: g.simulate(args["model"], args["inputs"], args["ts"], args["x0"], **args.get("extra", {}))


# -- the table -----------------------------------------------------------------------------------
CASES = [
    # model dicts (load_model(dict) reads an in-memory "gmr-model/1" model)
    ("model_wrong_format", lambda: g.load_model({"format": "gmr-model/0", "masses": [1.0], "terms": []}),
     r"not a gmr-model/1 model .*'format'"),
    ("model_terms_not_list", _load_model_dict(terms="x^3"), r"'terms' must be a list of term dicts"),
    ("model_terms_missing", lambda: g.load_model(_drop(_model(), "terms")), r"no 'terms' key; add"),
    ("model_no_terms", _load_model_dict(terms=[]), r"no terms; give each DOF at least its stiffness"),
    ("model_term_not_dict", _load_model_dict(terms=[[0, "stiffness", 1, -1.0]]), r"term 0 is .*not a dict"),
    ("model_term_unknown_key", _load_model_dict(terms=[_term(coef=2.0)]),
     r"term 0 has unknown key\(s\) \['coef'\]; allowed: dof, physics"),
    ("model_term_missing_key", _load_model_dict(terms=[_drop(_term(), "coefficient")]),
     r"term 0 lacks 'coefficient'"),
    ("model_coefficient_text", _load_model_dict(terms=[_term(coefficient="abc")]),
     r"term 0: 'coefficient' must be a finite number, got 'abc'"),
    ("model_coefficient_null", _load_model_dict(terms=[_term(coefficient=None)]),
     r"'coefficient' must be a finite number, got None"),
    ("model_coefficient_bool", _load_model_dict(terms=[_term(coefficient=True)]),
     r"'coefficient' must be a finite number, got True"),
    ("model_coefficient_nan", _load_model_file("m.json", '{"format": "gmr-model/1", "masses": [1.0], "terms": '
                                                          '[{"dof": 0, "physics": "stiffness", "order": 1, '
                                                          '"coefficient": NaN}]}'),
     r"'coefficient' must be a finite number, got nan"),
    ("model_order_fraction", _load_model_dict(terms=[_term(order=1.5)]),
     r"term 0: 'order' must be a whole number, got 1.5; the order is the integer power"),
    ("model_order_negative", _load_model_dict(terms=[_term(order=-1)]), r"'order' must be >= 0, got -1"),
    ("model_order_bool", _load_model_dict(terms=[_term(order=True)]), r"'order' must be a whole number, got True"),
    ("model_dof_fraction", _load_model_dict(terms=[_term(dof=1.5)]), r"'dof' must be a whole number, got 1.5"),
    ("model_dof_text", _load_model_dict(terms=[_term(dof="a")]), r"'dof' must be a whole number, got 'a'"),
    ("model_dof_out_of_range", _load_model_dict(terms=[_term(dof=3)]),
     r"term 0 names dof 3, outside 0..0 .*give one mass per DOF"),
    ("model_physics_unknown", _load_model_dict(terms=[_term(physics="magic")]),
     r"unknown physics 'magic'; known: stiffness, velocity_damping, position_damping"),
    ("model_duplicate_term", _load_model_dict(terms=[_term(), _term(order=3), _term(coefficient=2.0)]),
     r"terms 0 and 2 are both dof 0 stiffness order 1; merge them"),
    ("model_dof_without_term", _load_model_dict(masses=(1.0, 1.0)),
     r"DOF\(s\) \[1\] have no term .*add at least a stiffness term"),
    ("model_stderr_nan", _load_model_file("m.json", '{"format": "gmr-model/1", "masses": [1.0], "terms": '
                                                     '[{"dof": 0, "physics": "stiffness", "order": 1, '
                                                     '"coefficient": 1.0, "stderr": NaN}]}'),
     r"'stderr' must be a finite number >= 0, got nan; omit the key"),
    ("model_stderr_negative", _load_model_dict(terms=[_term(stderr=-0.1)]), r"'stderr' must be a finite number >= 0"),
    ("model_masses_missing", lambda: g.load_model(_drop(_model(), "masses")), r"no 'masses' key"),
    ("model_masses_text", _load_model_dict(masses=("1.0",)), r"'masses' must be a non-empty list of numbers"),
    ("model_masses_bool", _load_model_dict(masses=(True,)), r"'masses' must be a non-empty list of numbers"),
    ("model_masses_negative", _load_model_dict(masses=(-1.0,)), r"masses must be finite and positive"),
    ("model_masses_nested", _load_model_dict(masses=([1.0, 2.0],)), r"'masses' must be a flat list"),
    ("model_topology_unknown", _load_model_dict(topology="ring"), r"'topology' must be one of \('chain', 'independent'\)"),
    # model files and what is given as one
    ("model_file_missing", lambda: g.load_model("/nonexistent/m.json"), r"no such model file"),
    ("model_file_directory", _in_tmp(lambda d: g.load_model(d)), r"is a directory, not a model file"),
    ("model_file_empty", _load_model_file("m.json", ""), r"the model file is empty"),
    ("model_file_npz", _load_model_file("rec.npz", lambda p: np.savez(p, **_signals())),
     r"not a JSON text file but a zip/NPZ archive \(a recording\?\); give the gmr-model/1 .json"),
    ("model_file_binary", _load_model_file("m.json", b"\x00\xff\xfe" * 10), r"not a JSON text file but binary data"),
    ("model_file_invalid_json", _load_model_file("m.json", "{"), r"not valid JSON"),
    ("model_file_duplicate_key", _load_model_file("m.json", '{"format": "gmr-model/1", "masses": [1.0], "masses": '
                                                             '[2.0], "terms": []}'),
     r"key 'masses' appears twice"),
    ("model_not_a_path", lambda: g.load_model(123), r"load_model needs the path of a gmr-model/1 .json file or a"),
    # from_terms
    ("from_terms_physics", lambda: g.from_terms([1.0], [_term(physics="magic")]), r"from_terms: term 0: unknown physics"),
    ("from_terms_order_negative", lambda: g.from_terms([1.0], [_term(order=-2)]), r"from_terms: term 0: 'order' must be >= 0"),
    ("from_terms_masses_too_few", lambda: g.from_terms([1.0], [_term(), _term(dof=1)]),
     r"term 1 names dof 1, outside 0..0 \(the model has 1 mass\(es\)\)"),
    ("from_terms_masses_zero", lambda: g.from_terms([0.0], [_term()]), r"masses must be finite and positive"),
    ("from_terms_topology", lambda: g.from_terms([1.0], [_term()], "ring"), r"topology must be one of"),
    ("from_terms_terms_dict", lambda: g.from_terms([1.0], _term()), r"'terms' must be a list of term dicts, got dict"),
    # recordings
    ("recording_not_a_path", lambda: g.load_recording(123), r"load_recording needs the path of an .npz or .csv file, got int"),
    ("recording_list", lambda: g.load_recording(["a.npz"]), r"got list; for arrays in memory build gmr_jax.Recording"),
    ("recording_missing", lambda: g.load_recording("/nonexistent/r.npz"), r"no such file"),
    ("recording_directory", _in_tmp(lambda d: g.load_recording(d)), r"is a directory"),
    ("recording_empty_file", _load_file("r.npz", b""), r"the file is empty"),
    ("recording_npz_object_array", _load_npz(x=np.array([{"a": 1}] * N, dtype=object)),
     r"'x' is an object array \(pickled Python objects\)"),
    ("recording_npz_no_t", _load_npz(t=None, time=np.arange(N) * 1e-3),
     r"NPZ needs arrays 't' and 'x'.*found \['time', 'x'\]"),
    ("recording_npz_unknown_key", _load_npz(base=np.zeros(N)),
     r"unknown array\(s\) \['base'\]; found \['base', 't', 'x'\]"),
    ("recording_npy", _load_file("r.npz", _save_npy),
     r"holds a single array \(.npy\), not named arrays"),
    ("recording_garbage", _load_file("r.npz", b"not a zip"), r"cannot read as NPZ"),
    ("recording_constant", _load_npz(x=np.full((N, 1), 0.3)),
     r"x of column 0 is constant .*nothing to fit; check that sensor's column or drop that DOF"),
    ("recording_integer", _load_npz(x=(1000 * np.sin(np.arange(N) / 5.0)).astype(int)[:, None]),
     r"'x' holds integer values \(int64\), not floats; convert it with .astype\(float\)"),
    ("recording_boolean", _load_npz(x=(np.arange(N) % 2 == 0)[:, None]), r"'x' holds boolean values"),
    ("recording_nan", _load_npz(x=np.where(np.arange(N)[:, None] == 7, np.nan, 1.0 + np.arange(N)[:, None])),
     r"'x' has 1 NaN/inf value\(s\), first at sample 7"),
    ("recording_too_short", _load_npz(t=np.arange(10) * 1e-3, x=np.arange(10.0)), r"only 10 samples"),
    ("recording_csv_no_t", _load_file("r.csv", _csv_text(header="stamp,x0")),
     r"unknown column\(s\) \['stamp'\]; found columns \['stamp', 'x0'\], expected t, x0.*map them: --columns"),
    ("recording_csv_no_x", _load_file("r.csv", _csv_text(header="t,f0")), r"no column of DOF 0 \(x0, v0 or a0\)"),
    ("recording_csv_no_header", _load_file("r.csv", _csv_text(header="0.0,0.0")),
     r"the first line holds numbers \(0.0,0.0\), not column names: a header row is needed"),
    ("recording_csv_duplicate_column", _load_file("r.csv", _csv_text(header="t,x0").replace("t,x0", "t,x0,x0", 1)),
     r"column\(s\) \['x0'\] appear more than once in the header"),
    ("recording_csv_text_cell", _load_file("r.csv", _csv_text(mutate=_set_row(5, "0.005,abc"))),
     r"line 7 \(sample 5\), column 'x0': 'abc' is not a number"),
    ("recording_csv_ragged", _load_file("r.csv", _csv_text(mutate=_set_row(3, "0.003"))),
     r"line 5 \(sample 3\) has 1 cells, the header has 2 columns"),
    ("recording_csv_header_only", _load_file("r.csv", "t,x0\n"), r"no data rows"),
    ("recording_csv_gap", _load_file("r.csv", "t,x0,x2\n" + "".join(f"{i * 1e-3},{np.sin(i / 9)},{np.cos(i / 7)}\n"
                                                                     for i in range(N))),
     r"columns x0.. must be numbered 0, 1, 2, ... without gaps; x1 missing"),
    ("recording_shape_mismatch", lambda: g.Recording(t=np.arange(N) * 1e-3, x=np.zeros((N - 1, 1))),
     r"'x' has shape \(199, 1\), expected 200 samples to match 't'"),
    ("recording_masses_length", lambda: g.Recording(t=np.arange(N) * 1e-3, x=np.zeros((N, 2)), masses=np.ones(3)),
     r"'masses' has 3 entries but 'x' has 2 DOFs"),
    ("recording_no_columns", lambda: g.Recording(t=np.arange(N) * 1e-3, x=np.zeros((N, 0))),
     r"'x' has no columns; give one displacement column per DOF"),
    ("differentiate_constant", lambda: g.differentiate(np.ones(N), 1e-3), r"x of column 0 is constant.*pass window="),
    # settings objects
    ("library_order_negative", lambda: g.Library(restoring_order=-1), r"Library.restoring_order must be >= 1, got -1"),
    ("library_order_fraction", lambda: g.Library(restoring_order=2.5), r"Library.restoring_order must be a whole number, got 2.5"),
    ("library_order_bool", lambda: g.Library(restoring_order=True), r"Library.restoring_order must be a whole number, got True"),
    ("library_damping_negative", lambda: g.Library(damping_order=-1), r"Library.damping_order must be >= 0"),
    ("library_flag_text", lambda: g.Library(velocity_damping="no"), r"Library.velocity_damping must be True or False"),
    ("sweep_settle_negative", lambda: g.SweepSettings(settle_time=-5), r"SweepSettings.settle_time must be > 0, got -5"),
    ("sweep_settle_zero", lambda: g.SweepSettings(settle_time=0), r"SweepSettings.settle_time must be > 0, got 0"),
    ("sweep_settle_nan", lambda: g.SweepSettings(settle_time=float("nan")), r"SweepSettings.settle_time must be finite"),
    ("sweep_x_tol_zero", lambda: g.SweepSettings(x_tol=0.0), r"SweepSettings.x_tol must be > 0"),
    ("sweep_box_inside_wells", lambda: g.SweepSettings(box_spans=0.2), r"SweepSettings.box_spans must be > 0.5"),
    ("sweep_load", lambda: g.SweepSettings(load="top"), r"SweepSettings.load must be one of \('tip', 'base'\) or 'node:K' \(a force on mass K, from 0\), got 'top'"),
    ("sweep_batching", lambda: g.SweepSettings(batching="vmap"), r"SweepSettings.batching must be one of \('auto', 'native', 'lanes', 'joint', 'member'\)"),
    ("sweep_sign_eps", lambda: g.SweepSettings(sign_eps=-1.0), r"SweepSettings.sign_eps must be >= 0, got -1.0; give the velocity scale"),
    ("sweep_solver", lambda: g.SweepSettings(solver="rk4"), r"SweepSettings.solver must be one of \('tsit5', 'dopri5', 'dopri8'\)"),
    ("sweep_attempts", lambda: g.SweepSettings(attempts_per_pass=0), r"SweepSettings.attempts_per_pass must be an integer >= 1"),
    ("sweep_integrator", lambda: g.SweepSettings(integrator=1e-6), r"SweepSettings.integrator must be a gmr_jax.Integrator"),
    ("rule_alpha_zero", lambda: g.SelectionRule(alpha=0), r"SelectionRule.alpha must be > 0, got 0"),
    ("rule_alpha_above_one", lambda: g.SelectionRule(alpha=1.5), r"SelectionRule.alpha must be < 1, got 1.5"),
    ("rule_n_boot_zero", lambda: g.SelectionRule(n_boot=0), r"SelectionRule.n_boot must be >= 1, got 0"),
    ("rule_n_folds_one", lambda: g.SelectionRule(n_folds=1), r"SelectionRule.n_folds must be >= 2"),
    ("rule_stability", lambda: g.SelectionRule(stability=1.5), r"SelectionRule.stability must be <= 1"),
    ("rule_block_zero", lambda: g.SelectionRule(block=0), r"SelectionRule.block must be >= 1"),
    ("rule_min_cv_gain", lambda: g.SelectionRule(min_cv_gain=-0.1), r"SelectionRule.min_cv_gain must be >= 0"),
    ("rule_min_explained", lambda: g.SelectionRule(min_explained=2.0), r"SelectionRule.min_explained must be <= 1"),
    ("rule_max_new", lambda: g.SelectionRule(max_new=-1), r"SelectionRule.max_new must be >= 0"),
    ("rule_seed", lambda: g.SelectionRule(seed=-3), r"SelectionRule.seed must be >= 0"),
    # simulate
    ("simulate_x0_length", _simulate(x0=jnp.zeros(3)), r"x0 must hold 2 value\(s\), one per DOF of this 2-DOF model"),
    ("simulate_x0_nan", _simulate(x0=jnp.array([0.0, jnp.nan])), r"x0 has NaN/inf values"),
    ("simulate_v0_length", _simulate(extra={"v0": jnp.zeros(1)}), r"v0 must hold 2 value\(s\)"),
    ("simulate_ts_decreasing", _simulate(ts=jnp.array([0.0, 0.5, 0.4, 1.0])),
     r"ts must be strictly increasing; ts\[2\] = 0.4 <= ts\[1\] = 0.5"),
    ("simulate_ts_one_point", _simulate(ts=jnp.array([0.0])), r"ts must be a 1-D array of at least 2 save times"),
    ("simulate_inputs_type", _simulate(inputs=0.0), r"inputs must be an input object"),
    ("simulate_box_negative", _simulate(extra={"box": -1.0}), r"simulate: box must be > 0"),
    # stls: shapes are static, so refused at the call (audit: tracebacks from inside JAX)
    ("stls_target_n_by_1", lambda: g.stls(jnp.ones((50, 3)), jnp.ones((50, 1))),
     r"stls: y has shape \(50, 1\); give one target as \(samples,\), y\[:, 0\]"),
    ("stls_theta_transposed", lambda: g.stls(jnp.ones((3, 50)), jnp.ones(50)),
     r"stls: theta has 3 rows \(samples\) but y has 50 samples \(theta looks transposed: pass theta.T\)"),
    ("stls_theta_1d", lambda: g.stls(jnp.ones(50), jnp.ones(50)), r"stls: theta must be the library matrix"),
    ("stls_weights", lambda: g.stls(jnp.ones((50, 3)), jnp.ones(50), weights=jnp.ones(49)),
     r"stls: weights must be one per sample"),
]


@pytest.mark.parametrize("call,pattern", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_is_refused(call, pattern):
    with pytest.raises(g.GMRInputError, match=pattern) as info:
        call()
    assert "\n" not in str(info.value)  # one line


def table() -> list[tuple[str, str]]:
    """(id, message produced) for every row of `CASES`."""
    out = []
    for name, call, _ in CASES:
        try:
            call()
        except g.GMRInputError as e:
            out.append((name, str(e)))
        except Exception as e:  # noqa: BLE001 - reported, not raised
            out.append((name, f"NOT A GMRInputError: {type(e).__name__}: {e}"))
        else:
            out.append((name, "NOT REFUSED"))
    return out


if __name__ == "__main__":
    for name, msg in table():
        print(f"{name}: {msg}")
