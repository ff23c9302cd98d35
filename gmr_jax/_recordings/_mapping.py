"""Recordings as labs store them: MATLAB files and a mapping from the recording's fields to the
file's own variables (names, units, scale factors), e.g. EMPS: `x = qm`, `force = gtau * vir`."""

import re
from pathlib import Path

import numpy as np

from .._errors import GMRInputError

#: The recording's fields a mapping may set (as `Recording`).
FIELDS = ("t", "x", "v", "a", "base_acc", "force", "masses", "equilibrium")
_TOKEN = re.compile(r"\s*([*/])\s*")


def repeated_value(val, field: str, what: str, src: str) -> np.ndarray:
    """The one value per DOF that a column (N,) or columns (N, D) repeat on every row (`field`: equilibrium, masses;
    a CSV has no scalars), refused where it varies (`what` names the column in the message)."""
    arr = np.asarray(val, float).reshape(np.shape(val)[0], -1)
    if not np.all(np.isfinite(arr)) or np.ptp(arr, axis=0).max() > 1e-9 * max(np.abs(arr).max(), 1e-300):
        raise GMRInputError(f"{src}: {what} varies over the record; '{field}' is one number per DOF (a column that "
                            f"repeats it, or a number: --columns {field}=0.012)")
    return arr[0]


def squeeze(v) -> np.ndarray:
    """A stored value as a signal: a 1x1 matrix (a gain) is a number, a column or row vector (N,)."""
    v = np.asarray(v, float)
    if v.size == 1:
        return v.reshape(())
    return v.reshape(-1) if v.ndim == 2 and 1 in v.shape else v


def read_mat(path: Path, src: str) -> dict:
    """Every numeric variable of a MATLAB file: v4-v7.2 by scipy.io, v7.3 (HDF5: the header's
    version 2.0, which scipy does not read) by h5py where it is installed (`read_mat73`)."""
    import scipy.io
    import scipy.io.matlab

    try:
        v73 = scipy.io.matlab.matfile_version(path)[0] == 2
    except Exception:  # noqa: BLE001 - not a MATLAB header: loadmat below names the problem
        v73 = False
    if v73:
        return read_mat73(path, src)
    try:
        raw = scipy.io.loadmat(path, squeeze_me=False)
    except Exception as e:  # noqa: BLE001 - any unreadable file is a user error here
        raise GMRInputError(f"{src}: cannot read as a MATLAB .mat file ({type(e).__name__}: {e})") from None
    out = {}
    for k, v in raw.items():
        if k.startswith("__") or not isinstance(v, np.ndarray) or v.dtype.kind not in "fiu":
            continue
        out[k] = v
    return out


#: MATLAB's numeric classes (v7.3 stores each variable's class in its MATLAB_class attribute)
NUMERIC_CLASSES = ("double", "single", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64")


def read_mat73(path: Path, src: str) -> dict:
    """Every numeric variable of a MATLAB v7.3 file: an HDF5 file behind a 512-byte user block.
    Each top-level dataset of a numeric MATLAB_class (`NUMERIC_CLASSES`), transposed (MATLAB
    stores column-major, so h5py sees the dimensions reversed: an N x 1 column arrives (1, N));
    structs, cells (groups and `#refs#`), text, logicals, objects (string, datetime, tables:
    uint32 references with MATLAB_object_decode), complex and empty values are left out (as
    scipy.io leaves the older formats' text, cells, structs and objects)."""
    try:
        import h5py
    except ImportError:
        raise GMRInputError(f"{src}: a MATLAB v7.3 (HDF5) file; reading it needs h5py (`pip install h5py`, or the "
                            f"package's `mat73` extra), or save it with save(..., '-v7') or export the channels to "
                            f".npz/.csv") from None
    out = {}
    try:
        with h5py.File(path, "r") as fh:
            for k, d in fh.items():
                if k.startswith("#") or not isinstance(d, h5py.Dataset):
                    continue
                cls = d.attrs.get("MATLAB_class", b"double")
                cls = cls.decode() if isinstance(cls, bytes) else str(cls)
                if (cls not in NUMERIC_CLASSES or "MATLAB_object_decode" in d.attrs or d.attrs.get("MATLAB_empty", 0)
                        or d.dtype.kind not in "fiu"):  # complex is a compound (real, imag)
                    continue
                out[k] = np.asarray(d[()]).T
    except Exception as e:  # noqa: BLE001 - any unreadable file is a user error here
        raise GMRInputError(f"{src}: cannot read as a MATLAB v7.3 (HDF5) file ({type(e).__name__}: {e})") from None
    return out


#: the text before a + or - that makes it the sign of a number's exponent (1e-3, 2.5E+2), not a join
_EXPONENT = re.compile(r"(?:^|[^\w.])(?:\d+\.?\d*|\.\d+)[eE]$")


def _terms(expr: str) -> list[tuple[float, str]]:
    """'a + b*2 - c' -> [(1, 'a'), (1, 'b*2'), (-1, 'c')]; a leading sign is the first term's."""
    out, sign, start = [], 1.0, 0
    for i, c in enumerate(expr):
        if c in "+-" and not _EXPONENT.search(expr[:i].rstrip()):
            out.append((sign, expr[start:i]))
            sign, start = (1.0 if c == "+" else -1.0), i + 1
    out.append((sign, expr[start:]))
    if len(out) > 1 and not out[0][1].strip():
        out = out[1:]
    return out


def _product(expr: str, given: str, variables: dict, names: list, field: str, src: str):
    """A product/quotient of names and numbers, left to right."""
    parts = _TOKEN.split(expr.strip())
    if not expr.strip() or len(parts) % 2 == 0:
        raise GMRInputError(f"{src}: column mapping {field}={given!r}: write names and numbers joined by * or /, "
                            f"terms by + or -")
    value, op = None, "*"
    for i, tok in enumerate(parts):
        if i % 2:
            op = tok
            continue
        if tok in variables:
            term = squeeze(variables[tok])
        else:
            try:
                term = np.asarray(float(tok))
            except ValueError:
                raise GMRInputError(f"{src}: column mapping {field}={given!r}: {tok!r} is neither a variable of the "
                                    f"file nor a number; the file has {names}") from None
        value = term if value is None else (value * term if op == "*" else value / term)
    return value


def _evaluate(expr: str, variables: dict, field: str, src: str):
    """`expr`: terms joined by + or - (a leading - negates), each a product/quotient of the file's names and
    numbers (`*`, `/` bind first): 'x=q*1e-3', 'force=gtau*vir', 'a=acc+base_acc' (a relative acceleration
    made absolute)."""
    # a file's names that hold an operator ("v [m/s]", "x-ref") are names, not operations: matched whole, longest first
    given, names = expr, sorted(variables)
    named = sorted((k for k in variables if any(c in k for c in "*/+-") and k in expr), key=len, reverse=True)
    alias = {}
    for j, k in enumerate(named):
        alias[f"\x00{j}\x00"] = k
        expr = expr.replace(k, f"\x00{j}\x00")
    if alias:
        variables = {**variables, **{a: variables[k] for a, k in alias.items()}}
    value = None
    for sgn, piece in _terms(expr):
        term = sgn * _product(piece, given, variables, names, field, src)
        if value is not None:  # a column (N,) added to columns (N, D) is added to each
            if np.ndim(value) == 1 and np.ndim(term) == 2 and len(value) == len(term):
                value = value[:, None]
            elif np.ndim(term) == 1 and np.ndim(value) == 2 and len(value) == len(term):
                term = term[:, None]
            try:
                term = value + term
            except ValueError:
                raise GMRInputError(f"{src}: column mapping {field}={given!r}: its terms have different shapes "
                                    f"({np.shape(value)} and {np.shape(term)}); add columns of the same length") from None
        value = term
    return value


def map_columns(variables: dict, columns: dict | None, src: str) -> dict:
    """The recording's fields from the file's variables: `columns[field]` is an expression (or a
    list of expressions, one per DOF); unmapped fields are taken by their own name if present."""
    columns = dict(columns or {})
    bad = sorted(set(columns) - set(FIELDS))
    if bad:
        raise GMRInputError(f"{src}: column mapping names unknown field(s) {bad}; the fields are {list(FIELDS)}")
    out = {}
    for field in FIELDS:
        if field in columns:
            spec = columns[field]
            if isinstance(spec, (list, tuple)):
                vals = [_evaluate(str(e), variables, field, src) for e in spec]
                try:
                    out[field] = np.stack(np.broadcast_arrays(*vals), axis=1)
                except ValueError:
                    raise GMRInputError(f"{src}: column mapping for '{field}': the DOFs' columns have different "
                                        f"lengths {[np.shape(v) for v in vals]}") from None
            else:
                out[field] = _evaluate(str(spec), variables, field, src)
        elif field in variables:
            out[field] = squeeze(variables[field])
    for need in ("t", "x"):
        if need == "x" and ("v" in out or "a" in out):
            continue  # velocity- or acceleration-only sensors: x is integrated
        if need not in out:
            raise GMRInputError(f"{src}: no '{need}': the file has {sorted(variables)}; map one, e.g. "
                                f"columns={{'{need}': '<name>'}} (CLI: --columns {need}=<name>)")
    n = np.shape(out["t"])[0] if np.ndim(out["t"]) else 0
    for field in ("equilibrium", "masses"):  # a column that repeats one value per DOF (a CSV has no scalars)
        val = out.get(field)
        if val is not None and np.ndim(val) >= 1 and n > 1 and np.shape(val)[0] == n:
            out[field] = repeated_value(val, field, f"the column mapped to '{field}'", src)
    for field, val in out.items():  # a scalar scale alone (e.g. force=gtau) is a mistake, not a signal
        if field not in ("masses", "equilibrium") and np.ndim(val) == 0:
            raise GMRInputError(f"{src}: column mapping gives a single number for '{field}', not {n} samples")
    return out
