"""Argument types and checks shared by the `gmr` subcommands (each names the option and the fix)."""

import argparse
import re
import sys
import warnings
from pathlib import Path

import numpy as np

from .._errors import GMRDataWarning, GMRInputError


def positive_int(s):
    try:
        v = int(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {s!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {v}")
    return v


def positive_float(s):
    """A finite number > 0 (times, tolerances)."""
    try:
        v = float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {s!r}") from None
    if not np.isfinite(v) or v <= 0:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {s}")
    return v


def tolerance(s):
    """A relative or absolute ODE tolerance: 0 < tol < 1."""
    v = positive_float(s)
    if v >= 1:
        raise argparse.ArgumentTypeError(f"must be below 1 (e.g. 1e-6), got {s}")
    return v


#: options whose values may start with '-' (argparse would take "-1:5:4" for an option)
VALUE_OPTIONS = ("--f", "--A", "--x-range", "--f-range", "--A-range")


def join_negative_values(argv):
    """`--f -1:5:4` -> `--f=-1:5:4`, so that a range with a negative bound reaches its checker
    (which then names the problem) instead of argparse's "expected one argument"."""
    out, i = [], 0
    while i < len(argv):
        a = argv[i]
        if a in VALUE_OPTIONS and i + 1 < len(argv) and argv[i + 1].startswith("-") \
                and len(argv[i + 1]) > 1 and (argv[i + 1][1].isdigit() or argv[i + 1][1] == "."):
            out.append(f"{a}={argv[i + 1]}")
            i += 2
        else:
            out.append(a)
            i += 1
    return out


def output_dir(path) -> Path:
    """Create --out DIR before any computation, so a bad path fails in a second, not after it."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise GMRInputError(f"--out {out}: exists and is not a directory; give a directory to write into")
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".gmr_write_test"
        probe.write_text("")
        probe.unlink()
    except OSError as e:
        raise GMRInputError(f"--out {out}: cannot write there ({e.strerror}); give a writable directory") from None
    return out


def output_file(path) -> Path:
    """Check that --out FILE can be written before any computation."""
    out = Path(path)
    if out.is_dir():
        raise GMRInputError(f"--out {out}: is a directory; give a file name, e.g. {out / 'model.json'}")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise GMRInputError(f"--out {out}: the folder {parent} does not exist; create it or choose another path")
    return out


def grid(spec, name):
    """START:STOP:NUM -> np.linspace (f must stay positive)."""
    try:
        a, b, n = spec.split(":")
        a, b, n = float(a), float(b), int(n)
    except ValueError:
        raise GMRInputError(f"--{name} must be START:STOP:NUM, e.g. 0.1:5:50, got {spec!r}") from None
    if n < 1 or not (np.isfinite(a) and np.isfinite(b)):
        raise GMRInputError(f"--{name} {spec!r}: need NUM >= 1 and finite bounds")
    if name == "f" and min(a, b) <= 0:
        raise GMRInputError(f"--f {spec!r}: frequencies must be > 0 Hz, e.g. 0.1:5:50")
    if name == "A" and min(a, b) < 0:
        raise GMRInputError(f"--A {spec!r}: amplitudes must be >= 0 (the half-sine's sign is fixed), e.g. 0.02:1:50")
    if n > 1 and a == b:
        raise GMRInputError(f"--{name} {spec!r}: START equals STOP with NUM > 1 (every point the same); "
                            "use NUM 1 or widen the range")
    return np.linspace(a, b, n)


def interval(spec, name, positive=False):
    """LO:HI with 0 <= LO < HI (LO > 0 if `positive`)."""
    try:
        a, b = (float(v) for v in spec.split(":"))
    except ValueError:
        raise GMRInputError(f"--{name} must be LO:HI, e.g. 0.1:5, got {spec!r}") from None
    if not (np.isfinite(a) and np.isfinite(b)) or a >= b or a < 0 or (positive and a <= 0):
        raise GMRInputError(f"--{name} {spec!r}: need finite LO < HI" + (" and LO > 0" if positive else ", LO >= 0"))
    return a, b


def x_range(spec):
    """--x-range LO:HI (negative values allowed: write --x-range=-0.05:0.05)."""
    try:
        a, b = (float(v) for v in spec.rsplit(":", 1)) if spec.count(":") == 1 else (None, None)
    except ValueError:
        a = None
    if a is None or not (np.isfinite(a) and np.isfinite(b)) or a >= b:
        raise GMRInputError(f"--x-range must be LO:HI (write --x-range=-0.05:0.05), got {spec!r}")
    return a, b


def recorded_range(model_path, n_dof: int, key: str = "data_range") -> np.ndarray | None:
    """(n_dof, 2) the model file's `data_range` (each DOF's training displacement, written by `gmr fit`; `key`
    "speed_range": its training velocity), or None where the file has none (a hand-written model, or one written
    before the key) or cannot be read as JSON."""
    import json

    if model_path is None:
        return None
    try:
        rng = json.loads(Path(model_path).read_text()).get(key)
    except (OSError, ValueError, AttributeError):
        return None
    return None if rng is None else np.asarray(rng, float).reshape(n_dof, 2)


def find_wells(model, spec, model_path=None):
    """Stable wells per DOF and a sentence saying where they came from.

    With --x-range: the stable zeros inside it. Without: the real stable roots of each DOF's
    restoring polynomial, restricted to the model file's `data_range` (written by `gmr fit`)
    widened by half its width when present; otherwise an isolated outer root (farther from its
    neighbour than 10x the widest gap between the others) is dropped as a spurious outer well
    of the fitted polynomial and named."""
    import gmr_jax as gmr
    from .._basins._wells import pad_wells, polynomial_wells

    d = model.n_elements
    if spec:
        lo, hi = x_range(spec)
        wells = gmr.stable_wells(model, [[lo, hi]] * d)
        how = f"stable zeros in --x-range [{lo}, {hi}]"
    else:
        box = recorded_range(model_path, d)
        if box is not None:
            w = box[:, 1] - box[:, 0]
            box = np.stack([box[:, 0] - 0.5 * w, box[:, 1] + 0.5 * w], 1)
            roots = polynomial_wells(model, box)
            how = "stable roots of the restoring polynomial within the training data range (+-50 %)"
        else:
            roots, dropped = [], []
            for i, r in enumerate(polynomial_wells(model)):
                while r.size >= 3:
                    gaps = np.diff(r)
                    if gaps[0] > 10 * np.max(gaps[1:]):
                        dropped.append((i, r[0]))
                        r = r[1:]
                    elif gaps[-1] > 10 * np.max(gaps[:-1]):
                        dropped.append((i, r[-1]))
                        r = r[:-1]
                    else:
                        break
                roots.append(r)
            how = "stable roots of the restoring polynomial"
            if dropped:
                how += "; dropped as spurious outer roots: " + ", ".join(f"DOF {i} at {x:.6g}" for i, x in dropped) + \
                       " (give --x-range to choose the wells yourself)"
        wells = pad_wells(roots)
    empty = [i for i in range(d) if np.all(np.isnan(wells[i]))]
    if empty:
        where = f"in --x-range {spec}" if spec else "(its restoring polynomial has no real root with positive slope)"
        raise GMRInputError(f"DOF {empty} of the model has no stable equilibrium {where}; "
                            "check the model's stiffness terms" + ("" if spec else " or give --x-range=LO:HI"))
    return wells, how


def draw_box(wells) -> np.ndarray:
    """(dof, 2) where the wells of models drawn from a covariance are searched (`basin_probability`): the span of
    the model's own wells widened by half of it on each side (as `find_wells` widens the data range)."""
    lo, hi = np.nanmin(wells, axis=1), np.nanmax(wells, axis=1)
    half = 0.5 * np.where(hi > lo, hi - lo, np.maximum(np.abs(hi), 1.0))
    return np.stack([lo - half, hi + half], 1)


def start_configuration(spec, wells, graph_model=None):
    """x0 from a configuration label like 0-1-1-0-0 (cell 0 first; a digit = that cell's well). For
    a `graph_model` the digits are the elements' wells (default: every element in its first) and
    x0 the node displacements of that stable configuration (`configuration`)."""
    if graph_model is not None:
        from .._basins._wells import configuration

        pattern = np.zeros(wells.shape[0], int) if spec is None else _digits(spec, wells)
        return configuration(graph_model, wells, pattern)
    if spec is None:
        return None
    idx = _digits(spec, wells)
    return np.array([wells[i, k] for i, k in enumerate(idx)])


def _digits(spec, wells) -> list[int]:
    try:
        idx = [int(c) for c in spec.split("-")]
    except ValueError:
        raise GMRInputError(f"--start must look like 0-1-1-0-0 (one well index per DOF), got {spec!r}") from None
    n_wells = np.sum(~np.isnan(wells), axis=1)
    if len(idx) != wells.shape[0] or any(k < 0 or k >= n for k, n in zip(idx, n_wells)):
        raise GMRInputError(f"--start {spec!r}: need {wells.shape[0]} well indices, each below that DOF's "
                            f"number of wells {n_wells.tolist()}")
    return idx


COLUMNS_HELP = ("map the recording's fields to the file's variables, as the lab stored them: "
                "'x=qm,force=gtau*vir' (names and numbers joined by * or /, terms by + or -: "
                "'a=acc+base_acc'; one DOF per ';': 'x=q1*1e-3;q2*1e-3'); needed for .mat/.npz/.csv files whose names are not t, x, ...")


def add_columns_option(parser) -> None:
    parser.add_argument("--columns", default=None, metavar="FIELD=EXPR,...", help=COLUMNS_HELP)


def columns(spec):
    """'x=qm,force=gtau*vir' -> {"x": "qm", "force": "gtau*vir"}; ';' separates DOFs."""
    if spec is None:
        return None
    out = {}
    for item in filter(None, (p.strip() for p in spec.split(","))):
        field, eq, expr = item.partition("=")
        if not eq or not field.strip() or not expr.strip():
            raise GMRInputError(f"--columns: {item!r} is not FIELD=EXPR (e.g. --columns x=qm,force=gtau*vir)")
        parts = [e.strip() for e in expr.split(";")]
        out[field.strip()] = parts if len(parts) > 1 else parts[0]
    if not out:
        raise GMRInputError("--columns is empty; e.g. --columns x=qm,force=gtau*vir")
    return out


def load_recordings(paths, column_spec=None) -> tuple[list, list[str]]:
    """Load recording files (mapped by `--columns` if given); their load-time data warnings
    (time stamps resampled onto a uniform grid) are printed as `warning:` lines and returned, for
    the output file's metadata."""
    from .._recordings._recording import load_recording

    mapping = columns(column_spec)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", GMRDataWarning)
        recs = [load_recording(p, mapping) for p in paths]
    msgs = [str(w.message) for w in caught if issubclass(w.category, GMRDataWarning)]
    for w in caught:
        if not issubclass(w.category, GMRDataWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    for m in msgs:
        print(f"warning: {short_warning(m)}", file=sys.stderr)
    return recs, msgs


#: where a warning's fix starts: a clause (after ':', ';' or a full stop) that opens with an imperative
_FIX = re.compile(r"(?i)(?:[;:]\s+|\.\s+)(?=(?:give|fix|label|scale|record|re-record|measure|excite|use|pass|flip|"
                  r"check|remove|lower|raise|map|add|cut|convert|keep|set|try|refit|narrow|widen|drop|turn)\b)")


def short_warning(msg: str, width: int = 220) -> str:
    """One line of a warning for the terminal: its first clause (the problem) and its fix (the last clause that
    opens with an imperative, give, label, record, ..., to the end). The full sentence is in the model file
    (`gmr show`)."""
    text = " ".join(str(msg).split())
    if len(text) <= width:
        return text
    cut = [k for k in (text.find(" ("), text.find("; "), text.find(": ", text.find(": ") + 2)) if k > 20]
    problem = text[:min(cut)] if cut else text[:120]
    if len(problem) > 130:
        problem = problem[:127].rsplit(" ", 1)[0] + "..."
    starts = [m.end() for m in _FIX.finditer(text)]
    fix = text[starts[-1]:].rstrip(" .") if starts else "see gmr show MODEL --detail"
    room = max(width - len(problem) - 4, 40)
    if len(fix) > room:
        fix = fix[:room - 3].rsplit(" ", 1)[0] + "..."
    return f"{problem} -> {fix}"
