"""Every `gmr` subcommand on bad or suspicious input: one line on stderr naming the problem and
the fix, exit 2 (input) or 1 (computation), never a traceback, never exit 0 with a wrong result.

`CASES` is the table; `table()` returns (id, exit status, message) for the results index
(`python studies/bad_inputs_table.py`)."""

import atexit
import json
import re
import shutil
import tempfile
from contextlib import redirect_stderr, redirect_stdout
from functools import lru_cache
from io import StringIO
from pathlib import Path

import numpy as np
import pytest

from gmr_jax._cli._main import main


@lru_cache(maxsize=1)
def files() -> dict:
    """A small, valid set of inputs made by hand (a chain model, an independent model, recordings)."""
    d = Path(tempfile.mkdtemp(prefix="gmr_bad_cli_"))
    atexit.register(shutil.rmtree, d, True)  # the files outlive one test (cached), not the process
    terms = []
    for i, (k1, k3) in enumerate([(-30.0, 1e5), (-60.0, 2e5)]):
        terms += [{"dof": i, "physics": "stiffness", "order": 1, "coefficient": k1},
                  {"dof": i, "physics": "stiffness", "order": 3, "coefficient": k3},
                  {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": 0.5}]
    chain = {"format": "gmr-model/1", "topology": "chain", "masses": [0.05, 0.05], "terms": terms}
    (d / "chain.json").write_text(json.dumps(chain))
    indep = {"format": "gmr-model/1", "topology": "independent", "masses": [1.0],
             "terms": [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": 100.0},
                       {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.5}]}
    (d / "indep.json").write_text(json.dumps(indep))
    indep2 = {**indep, "masses": [1.0, 1.0], "terms": indep["terms"] + [{**t, "dof": 1} for t in indep["terms"]]}
    (d / "indep2.json").write_text(json.dumps(indep2))
    # a linear spring-mass under a base sine: a valid recording for discover/refine/fit
    t = np.arange(2000) * 1e-3
    x = 1e-3 * np.sin(2 * np.pi * 3 * t)
    np.savez(d / "rec.npz", t=t, x=x[:, None], base_acc=np.sin(2 * np.pi * 3 * t))
    np.savez(d / "rec2.npz", t=t, x=0.01 + x[:, None], base_acc=np.sin(2 * np.pi * 3 * t))
    np.savez(d / "rec_chain.npz", t=t, x=np.stack([x, 0.5 * x], 1), base_acc=np.sin(2 * np.pi * 3 * t))
    np.savez(d / "nan.npz", t=t, x=np.where(t > 0.5, np.nan, x)[:, None], base_acc=np.sin(t))
    np.savez(d / "nonuniform.npz", t=t**1.2, x=x[:, None], base_acc=np.sin(t))
    np.savez(d / "short.npz", t=t[:10], x=x[:10, None], base_acc=np.sin(t[:10]))
    np.savez(d / "mismatch.npz", t=t, x=x[:900, None], base_acc=np.sin(t))
    (d / "garbage.npz").write_text("not an npz")
    (d / "notjson.json").write_text("{ this is not json")
    (d / "wrongformat.json").write_text(json.dumps({"format": "something-else"}))
    (d / "negmass.json").write_text(json.dumps({**chain, "masses": [0.05, -1.0]}))
    (d / "badphys.json").write_text(json.dumps({**chain, "terms": [{**terms[0], "physics": "magic"}]}))
    (d / "baddof.json").write_text(json.dumps({**chain, "terms": [{**terms[0], "dof": 7}]}))
    (d / "badtopo.json").write_text(json.dumps({**chain, "topology": "ring"}))
    (d / "nowell.json").write_text(json.dumps({**chain, "terms": [
        {"dof": i, "physics": "stiffness", "order": 1, "coefficient": -5.0} for i in range(2)]}))
    (d / "afile").write_text("x")
    return {k.stem if k.suffix != ".npz" else k.stem + "_npz": str(k) for k in d.iterdir()} | {"dir": str(d)}


def F(name):
    return files()[name]


def OUT(name="out"):
    return str(Path(files()["dir"]) / name)


B = ["basins"]  # the contract's shape: gmr basins MODEL --f --A --out
GRID = ["--f", "0.5:4:3", "--A", "0.3:2.5:2"]

# (id, argv (callable: files are made lazily), expected exit status, regex the stderr must match)
CASES = [
    # basins
    ("basins: model file missing", lambda: B + ["nope.json", *GRID, "--out", OUT()], 2, r"no such model file"),
    ("basins: model not JSON", lambda: B + [F("notjson"), *GRID, "--out", OUT()], 2, r"not valid JSON"),
    ("basins: model of another format", lambda: B + [F("wrongformat"), *GRID, "--out", OUT()], 2, r"gmr-model/1"),
    ("basins: NPZ given as the model", lambda: B + [F("rec_npz"), *GRID, "--out", OUT()], 2, r"rec\.npz"),
    ("basins: negative mass", lambda: B + [F("negmass"), *GRID, "--out", OUT()], 2, r"masses must be finite and positive"),
    ("basins: unknown physics", lambda: B + [F("badphys"), *GRID, "--out", OUT()], 2, r"unknown physics 'magic'"),
    ("basins: term on a DOF that does not exist", lambda: B + [F("baddof"), *GRID, "--out", OUT()], 2, r"dof"),
    ("basins: unknown topology", lambda: B + [F("badtopo"), *GRID, "--out", OUT()], 2, r"topology'? must be one of"),
    ("basins: no stable well in the model", lambda: B + [F("nowell"), *GRID, "--out", OUT()], 2,
     r"no stable equilibrium"),
    ("basins: --f not a range", lambda: B + [F("chain"), "--f", "abc", "--A", "0.3:2.5:2", "--out", OUT()], 2,
     r"--f must be START:STOP:NUM"),
    ("basins: --f negative", lambda: B + [F("chain"), "--f", "-1:5:4", "--A", "0.3:2.5:2", "--out", OUT()], 2,
     r"frequencies must be > 0"),
    ("basins: --f zero points", lambda: B + [F("chain"), "--f", "1:5:0", "--A", "0.3:2.5:2", "--out", OUT()], 2,
     r"NUM >= 1"),
    ("basins: --f infinite", lambda: B + [F("chain"), "--f", "1:inf:4", "--A", "0.3:2.5:2", "--out", OUT()], 2,
     r"finite bounds"),
    ("basins: --f START == STOP", lambda: B + [F("chain"), "--f", "1:1:4", "--A", "0.3:2.5:2", "--out", OUT()], 2,
     r"START equals STOP"),
    ("basins: --A negative", lambda: B + [F("chain"), "--f", "1:2:2", "--A", "-2:1:3", "--out", OUT()], 2,
     r"amplitudes must be >= 0"),
    ("basins: --x-range inverted", lambda: B + [F("chain"), *GRID, "--x-range=0.05:-0.05", "--out", OUT()], 2,
     r"--x-range must be LO:HI"),
    ("basins: --x-range without wells", lambda: B + [F("chain"), *GRID, "--x-range=0.5:0.6", "--out", OUT()], 2,
     r"no stable equilibrium in --x-range"),
    ("basins: --settle-time 0", lambda: B + [F("chain"), *GRID, "--settle-time", "0", "--out", OUT()], 2,
     r"--settle-time: must be a finite number > 0"),
    ("basins: --settle-time negative", lambda: B + [F("chain"), *GRID, "--settle-time", "-5", "--out", OUT()], 2,
     r"--settle-time"),
    ("basins: --rtol 0", lambda: B + [F("chain"), *GRID, "--rtol", "0", "--out", OUT()], 2, r"--rtol: must be"),
    ("basins: --atol >= 1", lambda: B + [F("chain"), *GRID, "--atol", "2", "--out", OUT()], 2, r"--atol: must be below 1"),
    ("basins: --rtol not a number", lambda: B + [F("chain"), *GRID, "--rtol", "tight", "--out", OUT()], 2,
     r"--rtol: must be a number"),
    ("basins: --chunk 0", lambda: B + [F("chain"), *GRID, "--chunk", "0", "--out", OUT()], 2, r"--chunk: must be >= 1"),
    ("basins: --cpu-devices 1.5", lambda: B + [F("chain"), *GRID, "--cpu-devices", "1.5", "--out", OUT()], 2,
     r"--cpu-devices: must be a whole number"),
    ("basins: --load unknown", lambda: B + [F("chain"), *GRID, "--load", "side", "--out", OUT()], 2,
     r"--load must be tip, base or node:K"),
    ("basins: --start malformed", lambda: B + [F("chain"), *GRID, "--start", "a-b", "--out", OUT()], 2,
     r"--start must look like 0-1-1-0-0"),
    ("basins: --start wrong length", lambda: B + [F("chain"), *GRID, "--start", "0-1-1", "--out", OUT()], 2,
     r"need 2 well indices"),
    ("basins: --start well index too high", lambda: B + [F("chain"), *GRID, "--start", "0-5", "--out", OUT()], 2,
     r"number of wells"),
    ("basins: --out is a file", lambda: B + [F("chain"), *GRID, "--out", F("afile")], 2, r"not a directory"),
    ("basins: --out not writable", lambda: B + [F("chain"), *GRID, "--out", "/proc/gmr_out"], 2,
     r"cannot write there"),
    ("basins: --out missing", lambda: B + [F("chain"), *GRID], 2, r"the following arguments are required: --out"),
    # actuate
    ("actuate: independent model of two DOFs", lambda: ["actuate", F("indep2"), "--target", "1-1", "--out", OUT()],
     2, r"needs a chain model .* 2 independent DOFs has no tip"),
    # one mass is its own tip: taken, then refused for its single well
    ("actuate: one-DOF model with one well", lambda: ["actuate", F("indep"), "--target", "1", "--out", OUT()], 2,
     r"fewer than two stable wells"),
    ("actuate: target malformed", lambda: ["actuate", F("chain"), "--target", "x-y", "--out", OUT()], 2, r"target"),
    ("actuate: target wrong length", lambda: ["actuate", F("chain"), "--target", "1-1-1", "--out", OUT()], 2,
     r"target"),
    ("actuate: --f-range inverted", lambda: ["actuate", F("chain"), "--target", "1-1", "--f-range", "5:1",
                                             "--out", OUT()], 2, r"--f-range"),
    ("actuate: --A-range negative", lambda: ["actuate", F("chain"), "--target", "1-1", "--A-range", "-1:1",
                                             "--out", OUT()], 2, r"--A-range"),
    ("actuate: --grid 0", lambda: ["actuate", F("chain"), "--target", "1-1", "--grid", "0", "--out", OUT()], 2,
     r"--grid: must be >= 1"),
    ("actuate: --grid 1", lambda: ["actuate", F("chain"), "--target", "1-1", "--grid", "1", "--out", OUT()], 2,
     r"--grid >= 2"),
    ("actuate: --sign-eps 0", lambda: ["actuate", F("chain"), "--target", "1-1", "--sign-eps", "0",
                                       "--out", OUT()], 2, r"--sign-eps"),
    ("actuate: monostable cells", lambda: ["actuate", F("chain"), "--target", "1-1", "--x-range=0.0:0.05",
                                           "--out", OUT()], 2, r"fewer than two stable wells"),
    # fit
    ("fit: --out in a missing folder", lambda: ["fit", F("rec_npz"), F("rec_npz"), "--out", "/nonexistent/dir/m.json"],
     2, r"the folder /nonexistent/dir does not exist"),
    ("fit: NaN in x", lambda: ["fit", F("nan_npz"), F("rec_npz"), "--out", OUT("m.json")], 2, r"NaN"),
    ("fit: non-uniform time", lambda: ["fit", F("nonuniform_npz"), F("rec_npz"), "--out", OUT("m.json")], 2,
     r"not uniformly sampled"),
    ("fit: 10 samples", lambda: ["fit", F("short_npz"), F("rec_npz"), "--out", OUT("m.json")], 2, r"only 10 samples"),
    ("fit: columns of different lengths", lambda: ["fit", F("mismatch_npz"), F("rec_npz"), "--out", OUT("m.json")],
     2, r"shape"),
    ("fit: not an NPZ", lambda: ["fit", F("garbage_npz"), F("rec_npz"), "--out", OUT("m.json")], 2, r"garbage\.npz"),
    ("fit: one recording", lambda: ["fit", F("rec_npz"), "--out", OUT("m.json")], 2,
     r"at least two distinct equilibria"),
    ("fit: the same file twice", lambda: ["fit", F("rec_npz"), F("rec_npz"), "--out", OUT("m.json")], 2,
     r"same equilibrium"),
    ("fit: file missing", lambda: ["fit", "missing.csv", F("rec_npz"), "--out", OUT("m.json")], 2, r"no such file"),
    ("fit: -r 0", lambda: ["fit", F("rec_npz"), F("rec2_npz"), "-r", "0", "--out", OUT("m.json")], 2, r"must be >= 1"),
    ("fit: --method unknown", lambda: ["fit", F("rec_npz"), F("rec2_npz"), "--method", "sindy", "--out",
                                       OUT("m.json")], 2, r"invalid choice"),
    # discover
    ("discover: model missing", lambda: ["discover", "nope.json", F("rec_npz"), "--out", OUT()], 2,
     r"no such model file"),
    ("discover: recording not an NPZ", lambda: ["discover", F("indep"), F("garbage_npz"), "--out", OUT()], 2,
     r"garbage\.npz"),
    ("discover: holdout NaN", lambda: ["discover", F("indep"), F("rec_npz"), "--holdout", F("nan_npz"),
                                       "--out", OUT()], 2, r"NaN"),
    ("discover: --alpha 0", lambda: ["discover", F("indep"), F("rec_npz"), "--alpha", "0", "--out", OUT()], 2,
     r"--alpha must lie in \(0, 1\)"),
    ("discover: --n-boot 5", lambda: ["discover", F("indep"), F("rec_npz"), "--n-boot", "5", "--out", OUT()], 2,
     r"--n-boot must be at least 20"),
    ("discover: --hold-masses and --refit-masses", lambda: ["discover", F("indep"), F("rec_npz"), "--hold-masses",
                                                            "--refit-masses", "--out", OUT()], 2,
     r"not allowed with argument"),
    ("discover: --refit-masses on a chain", lambda: ["discover", F("chain"), F("rec_chain_npz"), "--refit-masses",
                                                     "--out", OUT()], 2, r"refit_masses needs the independent"),
    ("discover: --decimate 0", lambda: ["discover", F("indep"), F("rec_npz"), "--decimate", "0", "--out", OUT()], 2,
     r"--decimate must be >= 1"),
    ("discover: --out is a file", lambda: ["discover", F("indep"), F("rec_npz"), "--out", F("afile")], 2,
     r"not a directory"),
    ("discover: DOF count differs", lambda: ["discover", F("chain"), F("rec_npz"), "--out", OUT()], 2, r"DOF|dof"),
    # refine
    ("refine: --window 0", lambda: ["refine", F("indep"), F("rec_npz"), "--window", "0", "--out", OUT("r.json")], 2,
     r"--window"),
    ("refine: --max-iterations 0", lambda: ["refine", F("indep"), F("rec_npz"), "--max-iterations", "0",
                                            "--out", OUT("r.json")], 2, r"--max-iterations"),
    ("refine: --free unknown", lambda: ["refine", F("indep"), F("rec_npz"), "--free", "springs",
                                        "--out", OUT("r.json")], 2, r"unknown"),
    ("refine: --out in a missing folder", lambda: ["refine", F("indep"), F("rec_npz"), "--out",
                                                   "/nonexistent/dir/r.json"], 2, r"does not exist"),
    ("refine: --out is a folder", lambda: ["refine", F("indep"), F("rec_npz"), "--out", files()["dir"]], 2,
     r"is a directory"),
    ("refine: window longer than the record", lambda: ["refine", F("indep"), F("rec_npz"), "--window", "100",
                                                       "--out", OUT("r.json")], 2, r"longer than recording"),
    # demo
    ("demo: unknown system", lambda: ["demo", "--system", "bridge"], 2, r"invalid choice"),
    ("demo: --out is a file", lambda: ["demo", "--out", F("afile")], 2, r"not a directory"),
]


def run_case(argv) -> tuple[int, str]:
    """(exit status, stderr) of the command in-process; argparse's own errors exit via SystemExit."""
    err, out = StringIO(), StringIO()
    with redirect_stderr(err), redirect_stdout(out):
        try:
            rc = main(argv)
        except SystemExit as e:
            rc = e.code
    return rc, err.getvalue()


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_input(case):
    _, argv, want_rc, pattern = case
    rc, err = run_case(argv())
    assert rc == want_rc, err
    assert "Traceback" not in err and "internal error" not in err, err
    last = err.strip().splitlines()[-1]
    assert re.search(pattern, last), last
    # one line: argparse's usage block comes before its one error line, nothing else does
    if not err.startswith("usage:"):
        assert len(err.strip().splitlines()) == 1, err


def table() -> list[tuple[str, int, str]]:
    rows = []
    for name, argv, _, _ in CASES:
        rc, err = run_case(argv())
        rows.append((name, rc, err.strip().splitlines()[-1] if err.strip() else ""))
    return rows
