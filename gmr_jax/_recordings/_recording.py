"""Recordings: one experiment or simulation run, in the NPZ/CSV format of the contracts."""

import csv
import io
import math
import os
import re
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .._errors import GMRDataWarning, GMRInputError, describe, is_tracer
from .._topology import as_topology
from ._derivatives import _odd_window, auto_window, differentiate
from ._integrate import integrated_signals
from ._mapping import repeated_value

MIN_SAMPLES = 64


@dataclass(frozen=True)
class Recording:
    """One run. `t` (N,), `x` (N, D) displacements (cell deformations for a chain, base cell
    first); optional `v`, `a` (absolute accelerations of the masses), inputs `base_acc` (N,) or
    `force` (N, D), optional `masses` (D,). `derived` lists the signals estimated, not measured.

    Velocity- or acceleration-only sensors: give `v` or `a` without `x`; x (and v from a) is
    integrated with drift removal (`_integrate`), listed in `derived`, and described in
    `integration` (source, high-pass cut-off, equilibrium). The integrated x has zero mean: the
    equilibrium it vibrates about is unobservable unless given as `equilibrium` (D,), where the
    mean of x is then put (for a chain, each cell's deformation at rest). From `a` alone, x holds
    each mass's displacement relative to the base until `complete(topology)` makes chain cell
    deformations of it (with the equilibrium as cell deformations).

    Construction checks types and shapes (float arrays, not integer, boolean or object ones;
    one length N; D columns in x, v, a, force; D masses; a 1-D x, v, a or force is one DOF)
    and raises `GMRInputError`; values (NaN, sampling, length) are checked by `validate`, which
    every fit, refinement and discovery runs.
    """

    t: np.ndarray
    x: np.ndarray | None = None
    v: np.ndarray | None = None
    a: np.ndarray | None = None
    base_acc: np.ndarray | None = None
    force: np.ndarray | None = None
    masses: np.ndarray | None = None
    name: str = "recording"
    derived: tuple = field(default_factory=tuple)
    equilibrium: np.ndarray | None = None
    integration: dict | None = field(default=None, compare=False)
    derivation: dict | None = field(default=None, compare=False)
    #: the unit of its lengths where its file's header named one ("mm": x, v, a, base_acc are in mm, mm/s, mm/s^2);
    #: None: as given (no unit in the file)
    length_unit: str | None = field(default=None, compare=False)

    def __post_init__(self):
        for key in SIGNALS:  # lists and tuples of numbers (a notebook's data, ints included) as float arrays
            if isinstance(getattr(self, key), (list, tuple)):
                try:
                    object.__setattr__(self, key, np.asarray(getattr(self, key), float))
                except (TypeError, ValueError):
                    pass  # ragged or not numbers: `_check_fields` names it
        _check_fields(self)
        for key in ("x", "v", "a", "force"):  # one DOF may be given as (N,)
            val = getattr(self, key)
            if val is not None and np.ndim(val) == 1:
                object.__setattr__(self, key, val[:, None])
        if self.base_acc is not None and np.ndim(self.base_acc) == 2:  # (N, 1)
            object.__setattr__(self, "base_acc", self.base_acc[:, 0])
        for key in ("masses", "equilibrium"):
            if getattr(self, key) is not None and np.ndim(getattr(self, key)) == 0:  # one DOF
                object.__setattr__(self, key, np.reshape(np.asarray(getattr(self, key), float), (1,)))
        if self.x is None:
            self._integrate()
        elif self.equilibrium is not None and "x" not in self.derived:
            raise GMRInputError(f"{self.name}: 'equilibrium' is for velocity- or acceleration-only recordings "
                                f"(x integrated); with x measured, x itself says where the equilibrium is: "
                                f"drop 'equilibrium'")
        d = np.shape(self.x)[1]
        if d == 0:
            raise GMRInputError(f"{self.name}: 'x' has no columns; give one displacement column per DOF")
        for key in ("v", "a", "force"):
            val = getattr(self, key)
            if val is not None and np.shape(val)[1] != d:
                raise GMRInputError(f"{self.name}: '{key}' has {np.shape(val)[1]} columns but 'x' has {d} DOFs")
        if self.masses is not None and np.shape(self.masses)[0] != d:
            raise GMRInputError(f"{self.name}: 'masses' has {np.shape(self.masses)[0]} entries but 'x' has {d} "
                                f"DOFs; give one mass per DOF")
        if self.equilibrium is not None and np.shape(self.equilibrium)[0] != d:
            raise GMRInputError(f"{self.name}: 'equilibrium' has {np.shape(self.equilibrium)[0]} entries but "
                                f"the recording has {d} DOFs; give one static displacement per DOF")

    def _integrate(self):
        """x (and v from a) integrated from the velocity- or acceleration-only sensors."""
        x, v, info = integrated_signals(self.t, self.v, self.a, self.base_acc, self.name)
        derived = tuple(self.derived) + ("x",) + (("v",) if v is not None else ())
        if self.equilibrium is not None:
            eq = np.asarray(self.equilibrium, float)
            if eq.shape != (x.shape[1],) or not np.all(np.isfinite(eq)):
                raise GMRInputError(f"{self.name}: 'equilibrium' must hold {x.shape[1]} finite number(s) (one "
                                    f"static displacement per DOF), got {describe(eq.tolist())} (shape "
                                    f"{eq.shape})")
            x = x + eq[None, :]
            info["equilibrium"] = "given"
        else:
            info["equilibrium"] = ("unobservable: x has zero mean (the static position is not in v or a); "
                                   "give 'equilibrium' to place it")
        object.__setattr__(self, "x", x)
        if v is not None:
            object.__setattr__(self, "v", v)
        object.__setattr__(self, "derived", derived)
        object.__setattr__(self, "integration", info)

    @property
    def driven(self) -> bool:
        """True when an input was recorded (base_acc or force); False: a free decay, or an input column left out."""
        return self.base_acc is not None or self.force is not None

    def free_decay_sentence(self, taken: str) -> str:
        """What a user is told where a record without an input column is `taken` ("the model is run", ...) as
        a free decay: it may be a driven record whose input column was left out."""
        return (f"{self.name}: has no input column (base_acc or force), so {taken} as a free decay; if the structure "
                f"was driven, add its input column (or map it: --columns base_acc=NAME)")

    @property
    def equilibrium_observed(self) -> bool:
        """False when x was integrated from v or a and no `equilibrium` was given."""
        return "x" not in self.derived or self.equilibrium is not None

    def derivative_source(self) -> str:
        """The signal a missing acceleration is differentiated from: 'v' when x was integrated
        from a measured v (one derivative of the measurement, not two of its integral), else 'x'."""
        return "v" if (self.integration or {}).get("from") == "v" else "x"

    @property
    def n_samples(self) -> int:
        return self.t.shape[0]

    @property
    def n_dof(self) -> int:
        return self.x.shape[1]

    @property
    def dt(self) -> float:
        if self.t.shape[0] < 2:
            raise GMRInputError(f"{self.name}: 't' has {self.t.shape[0]} sample(s): no sampling step; "
                                f"record at least {MIN_SAMPLES} samples")
        return float(self.t[1] - self.t[0])

    def inputs(self):
        """(base_acc (N,), force (N, D)), zeros where absent."""
        n, d = self.x.shape
        b = self.base_acc if self.base_acc is not None else np.zeros(n)
        f = self.force if self.force is not None else np.zeros((n, d))
        return b, f

    def complete(self, topology: str = "chain", window: int | None = None,
                 exclude_center: bool = False, window_scale: float = 1.0) -> "Recording":
        """Fill missing `v` and `a` by Savitzky-Golay differentiation of x (recorded in
        `derived`; of a measured v when x was integrated from it). `a` is absolute: x'' plus base
        acceleration (chain: cumulated over cells). An acceleration-only recording's integrated
        mass displacements become cell deformations for a chain. `exclude_center`: x'' at each
        sample leaves that sample out (`differentiate`), so that its noise is independent of x
        there (a regression on x(t) needs it; a first derivative's centre weight is 0 already).
        `derivation` then says, per derived signal, what it was differentiated from, the
        order, the window of each column and whether the centre was left out (the noise model
        of `reconstruct`'s local fits, `_fit/_target_noise.py`). `window_scale`: the automatic
        windows scaled by it (odd, at least polyorder + 2; `reconstruct` refits at 0.7 to test the damping against the window)."""
        x, v, a, derived = self.x, self.v, self.a, list(self.derived)
        info = self.integration
        how = dict(self.derivation or {})
        topo = as_topology(topology)
        if info and info["from"] == "a" and info["topology"] is None:  # not yet given a topology
            if topo.name == "chain" and x.shape[1] > 1:  # mass displacements -> cell deformations
                # the given equilibrium is each cell's deformation at rest (the docs' x), not a mass's
                # position: difference the vibration, then place it (audit: cell 1's wells were moved by
                # cell 0's rest deformation)
                eq = np.zeros(x.shape[1]) if self.equilibrium is None else np.asarray(self.equilibrium, float)
                x = np.diff(x - eq, axis=1, prepend=0.0) + eq
                v = np.diff(v, axis=1, prepend=0.0)
            info = {**info, "topology": topo.name, "coordinates": (
                "cell deformations" if topo.name == "chain" else
                "displacement of each mass relative to the base") + f" ({topo.name})"}
        def windows(sig):  # chosen once per signal, then applied (and recorded) as chosen
            return [window or (scaled(auto_window(c, self.dt), c.size) if np.ptp(c) > 0 else None) for c in sig.T]

        def scaled(w, n):
            return w if window_scale == 1.0 else _odd_window(window_scale * w, n, 5)

        x_windows = windows(x) if v is None or (a is None and self.derivative_source() == "x") else None
        if v is None:
            v = differentiate(x, self.dt, 1, x_windows)
            derived.append("v")
        if a is None:
            src, order = ("v", 1) if self.derivative_source() == "v" else ("x", 2)
            sig_windows = windows(v) if src == "v" else x_windows
            xdd = differentiate(v if src == "v" else x, self.dt, order, sig_windows,
                                exclude_center=exclude_center and order == 2)
            b, _ = self.inputs()
            a = topo.absolute(xdd, b)
            derived.append("a")
            how["a"] = {"from": src, "order": order, "windows": sig_windows, "polyorder": 5,
                        "exclude_center": bool(exclude_center and order == 2)}
        return replace(self, x=x, v=v, a=a, derived=tuple(derived), integration=info, derivation=how or None)

    def save(self, path) -> None:
        save_recording(self, path)


SIGNALS = ("t", "x", "v", "a", "base_acc", "force", "masses", "equilibrium")
_DERIVABLE = ("x", "v", "a")


def _check_dtype(name, arr, src):
    """A numeric, real, non-boolean array or `GMRInputError` naming the signal and the fix."""
    kind = arr.dtype.kind
    if kind == "f":
        return
    what = {"b": "boolean", "i": "integer", "u": "integer", "c": "complex", "O": "object (Python)",
            "U": "text", "S": "bytes", "M": "datetime", "m": "timedelta"}.get(kind, f"dtype {arr.dtype}")
    fix = ("convert it with .astype(float) (in the units of the contracts: s, m, m/s, m/s², N, kg)"
           if kind in "biu" else "store plain float arrays")
    raise GMRInputError(f"{src}: '{name}' holds {what} values ({arr.dtype}), not floats; {fix}")


def _check_fields(rec: "Recording") -> None:
    """Types, dtypes and shapes of a `Recording`'s fields (values are checked by `validate`)."""
    src = rec.name if isinstance(rec.name, str) else "recording"
    if not isinstance(rec.name, str):
        raise GMRInputError(f"Recording: name must be a string, got {describe(rec.name)}")
    if not isinstance(rec.derived, tuple) or any(d not in _DERIVABLE for d in rec.derived):
        raise GMRInputError(f"{src}: derived must be a tuple of {_DERIVABLE}, got {describe(rec.derived)}")
    n = None
    for key in SIGNALS:
        val = getattr(rec, key)
        if val is None:
            if key == "t" or (key == "x" and rec.v is None and rec.a is None):
                raise GMRInputError(f"{src}: '{key}' is required (Recording(t=..., x=...); or v=... or a=... "
                                    f"without x for velocity- or acceleration-only sensors)")
            continue
        if is_tracer(val):
            continue
        if isinstance(val, (str, bytes, dict)):
            raise GMRInputError(f"{src}: '{key}' must be an array of numbers, got {type(val).__name__}")
        try:
            arr = np.asarray(val)
        except Exception:  # noqa: BLE001 - ragged lists and the like
            raise GMRInputError(f"{src}: '{key}' is not a rectangular array of numbers") from None
        _check_dtype(key, arr, src)
        if key == "t":
            if arr.ndim != 1:
                raise GMRInputError(f"{src}: 't' must be 1-D (N,), got shape {arr.shape}")
            n = arr.shape[0]
        elif key == "base_acc":
            if not (arr.ndim == 1 or (arr.ndim == 2 and arr.shape[1] == 1)):
                raise GMRInputError(f"{src}: 'base_acc' must be 1-D (N,), one value per sample, got shape "
                                    f"{arr.shape}")
        elif key in ("masses", "equilibrium"):
            if arr.ndim > 1:
                raise GMRInputError(f"{src}: '{key}' must be 1-D (D,), one per DOF, got shape {arr.shape}")
        elif arr.ndim not in (1, 2):
            raise GMRInputError(f"{src}: '{key}' has shape {arr.shape}, expected (N, D) or (N,)")
        if key not in ("masses", "equilibrium") and n is not None and arr.shape[0] != n:
            raise GMRInputError(f"{src}: '{key}' has shape {arr.shape}, expected {n} samples to match 't' "
                                f"({n} samples)")


def _as2d(name, arr, n, src):
    arr = np.asarray(arr, dtype=float)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[0] != n:
        raise GMRInputError(
            f"{src}: '{name}' has shape {arr.shape}, expected ({n}, D) to match 't' ({n} samples)"
        )
    return arr


def validate(rec: Recording, src: str = "recording", min_samples: int = MIN_SAMPLES) -> Recording:
    """Check shapes, finiteness and uniform sampling; return a normalised copy.

    Raises `GMRInputError` naming the problem and the fix."""
    t = np.asarray(rec.t, dtype=float)
    if t.ndim != 1:
        raise GMRInputError(f"{src}: 't' must be 1-D (N,), got shape {t.shape}")
    n = t.shape[0]
    if n < min_samples:
        raise GMRInputError(
            f"{src}: only {n} samples; at least {min_samples} are needed to fit a local model or compare a run "
            f"with the record (record longer or sample faster)"
        )
    x = _as2d("x", rec.x, n, src)
    out = {"t": t, "x": x}
    for key in ("v", "a", "force"):
        val = getattr(rec, key)
        if val is not None:
            out[key] = _as2d(key, val, n, src)
            if out[key].shape[1] != x.shape[1]:
                raise GMRInputError(
                    f"{src}: '{key}' has {out[key].shape[1]} columns but 'x' has {x.shape[1]} DOFs"
                )
    if rec.base_acc is not None:
        b = np.asarray(rec.base_acc, dtype=float).reshape(-1)
        if b.shape[0] != n:
            raise GMRInputError(f"{src}: 'base_acc' has {b.shape[0]} samples, 't' has {n}")
        out["base_acc"] = b
    if rec.masses is not None:
        m = np.asarray(rec.masses, dtype=float).reshape(-1)
        if m.shape[0] != x.shape[1] or np.any(~np.isfinite(m)) or np.any(m <= 0):
            raise GMRInputError(
                f"{src}: 'masses' must hold {x.shape[1]} positive numbers, got {m.tolist()}"
            )
        out["masses"] = m
    for key, val in out.items():
        bad = ~np.isfinite(val)
        if np.any(bad):
            idx = np.argwhere(bad)[0]
            raise GMRInputError(
                f"{src}: '{key}' has {int(bad.sum())} NaN/inf value(s), first at sample {int(idx[0])}; "
                f"remove or interpolate them before fitting"
            )
    for key in ("x", "v", "a"):  # a constant column: nothing to fit (x), a dead channel (v, a)
        val = out.get(key)
        for k in range(0 if val is None else val.shape[1]):
            if val.shape[0] and np.all(val[:, k] == val[0, k]):  # (no max - min: it overflows near 1e308)
                why = ("nothing to fit; check that sensor's column or drop that DOF" if key == "x" else
                       "a dead or disconnected sensor? check that column" + ("" if "x" in rec.derived else
                       f", or leave '{key}' out of the file (it is then estimated from x)"))
                raise GMRInputError(f"{src}: {key} of column {k} is constant ({val[0, k]:g} throughout): {why}")
    dt = np.diff(t)
    if np.any(dt <= 0):
        i = int(np.argmax(dt <= 0))
        what = (f"sample {i + 1} repeats the time stamp of sample {i} ({t[i]:g}): a duplicated row? remove "
                f"repeated rows" if dt[i] == 0 else f"sample {i + 1} ({t[i + 1]:g}) comes before sample {i} "
                f"({t[i]:g}): sort the rows by time, or split the file where a new run starts")
        raise GMRInputError(f"{src}: 't' is not strictly increasing: {what}")
    out = _uniform_time(out, _stamp_resolution(rec.t, t), src)
    return replace(rec, **out)


#: Time stamps within this fraction of a step of a uniform grid are put on the grid silently
#: (the sampling is uniform, the stamps are rounded: a logger's clock, a float32 column).
SNAP_JITTER = 1e-3
#: Up to this fraction of a step, the channels are resampled onto the uniform grid (with a
#: GMRDataWarning); beyond it the record has gaps or a changing rate and is refused.
RESAMPLE_JITTER = 0.25


def _stamp_resolution(t_raw, t):
    """The rounding unit of the stored time stamps: a few ulps of their dtype at max |t|
    (float32 stamps of a 100 s record are only good to 8e-6 s)."""
    dtype = np.asarray(t_raw).dtype
    eps = np.finfo(dtype).eps if dtype.kind == "f" else np.finfo(float).eps
    return 4.0 * eps * float(np.max(np.abs(t)))


def _uniform_time(out: dict, resolution: float, src: str) -> dict:
    """Put `t` on the uniform grid t0 + k * step (the least-squares line through the stamps).

    Stamps off the grid by at most max(SNAP_JITTER * step, the stamps' own rounding) are
    replaced by the grid (nothing else changes); up to RESAMPLE_JITTER * step, every channel
    is interpolated (linearly) onto the grid and a GMRDataWarning says so; beyond that the
    record is refused."""
    t = out["t"]
    n = t.shape[0]
    dt = np.diff(t)
    if np.max(np.abs(dt - dt.mean())) <= 1e-6 * dt.mean() + 1e-12:
        return out  # uniform already (to rounding): the stamps are kept as given
    k = np.arange(n) - 0.5 * (n - 1)
    step = float(k @ (t - t.mean()) / (k @ k))  # least-squares line through the stamps
    grid = t.mean() + step * k
    dev = float(np.max(np.abs(t - grid)))
    if dev <= max(SNAP_JITTER * step, resolution) and dt.min() > 0.5 * step:
        return {**out, "t": grid}
    if dev <= RESAMPLE_JITTER * step and dt.min() > 0.5 * step and dt.max() < 1.5 * step:
        warnings.warn(
            f"{src}: time stamps deviate from a uniform grid by up to {dev / step:.2g} of a step "
            f"(steps {dt.min():.4g} to {dt.max():.4g} s); every channel was resampled linearly onto "
            f"the uniform grid of step {step:.4g} s",
            GMRDataWarning,
            stacklevel=4,
        )
        res = {"t": grid}
        for key, val in out.items():
            if key == "t":
                continue
            if key == "masses":
                res[key] = val
            elif val.ndim == 1:
                res[key] = np.interp(grid, t, val)
            else:
                res[key] = np.stack([np.interp(grid, t, val[:, k]) for k in range(val.shape[1])], 1)
        return res
    typical = float(np.median(dt))
    odd = np.nonzero(np.abs(dt - typical) > 0.25 * typical)[0]  # where the step is not the usual one
    where = ""
    if odd.size:
        i = int(odd[0])
        where = (f"; the first irregular step is from sample {i} (t = {t[i]:.6g} s) to {i + 1} (t = {t[i + 1]:.6g} "
                 f"s), {dt[i] / typical:.3g} x the usual {typical:.4g} s" + (
                     f", and {odd.size - 1} more after it" if odd.size > 1 else "") + (
                     " (samples dropped?)" if dt[i] > 1.5 * typical else ""))
    raise GMRInputError(
        f"{src}: time is not uniformly sampled (steps from {dt.min():.3g} to {dt.max():.3g} s, "
        f"stamps up to {dev / step:.2g} of a step off a uniform grid; up to {SNAP_JITTER:g} of a step "
        f"is accepted as is, up to {RESAMPLE_JITTER:g} resampled){where}; resample onto a uniform grid first, "
        f"or cut the record at the gap"
    )


def save_recording(rec: Recording, path) -> None:
    """Write a recording as NPZ (or CSV if the path ends in .csv)."""
    path = Path(path)
    if path.suffix.lower() == ".csv":
        cols, names = [rec.t[:, None]], ["t"]
        for key, pre in (("x", "x"), ("v", "v"), ("a", "a"), ("force", "f")):
            val = getattr(rec, key)
            if val is not None and key not in rec.derived:
                cols.append(val)
                names += [f"{pre}{i}" for i in range(val.shape[1])]
        if rec.base_acc is not None:
            cols.append(rec.base_acc[:, None])
            names.append("base_acc")
        for key, pre in (("masses", "m"), ("equilibrium", "equilibrium")):  # one value per DOF, on every row
            val = getattr(rec, key)
            if val is not None:
                val = np.atleast_1d(np.asarray(val, float))
                cols.append(np.broadcast_to(val, (rec.t.shape[0], val.shape[0])))
                names += [f"{pre}{i}" for i in range(val.shape[0])]
        np.savetxt(path, np.hstack(cols), delimiter=",", header=",".join(names), comments="")
        return
    data = {k: getattr(rec, k) for k in SIGNALS}
    data = {k: v for k, v in data.items() if v is not None and k not in rec.derived}
    np.savez(path, **data)


#: the CSV columns numbered per DOF (x0, v0, ..., m0, equilibrium0)
_NUMBERED = ("x", "v", "a", "f", "m", "equilibrium")
_NUMBERED_NAME = re.compile(f"({'|'.join(_NUMBERED)})\\d+")


def _signal_name(name: str) -> bool:
    """A contract column name: t, base_acc, or a numbered x0, v0, a0, f0, m0, equilibrium0, ..."""
    return name in ("t", "base_acc") or bool(_NUMBERED_NAME.fullmatch(name))
#: CSV headers of a one-DOF recording read as the numbered columns (an extension of the contract's
#: t, x0.., v0.., a0.., f0..: the names lab files and the NPZ keys use)
_CSV_ALIASES = {"x": "x0", "v": "v0", "a": "a0", "f": "f0", "force": "f0", "equilibrium": "equilibrium0",
                "m": "m0", "mass": "m0", "masses": "m0"}


def _read_csv(path: Path, src: str, raw: bool = False):
    """The recording in a CSV file; with `raw`, every column by its header name (for a mapping)."""
    try:
        text = path.read_text(encoding="utf-8-sig")  # a byte-order mark (Windows editors) is not a column
    except UnicodeDecodeError:
        raise GMRInputError(f"{src}: not a text CSV file (binary data); save CSV text with a header row "
                            f"t, x0, ... or use an .npz file") from None
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise GMRInputError(f"{src}: the first line must be the header row naming the columns (t, x0, ...)")
    # the separator: ',' (the contract), or ';' / a tab as spreadsheets in many locales write them,
    # where a ',' inside a number is its decimal mark ("0,5;1,25")
    delim = next((d for d in (",", ";", "\t") if d in lines[0]), ",")
    decimal_comma = delim != "," and any("," in r for r in lines[1:50])
    if decimal_comma:
        lines = [lines[0]] + [r.replace(",", ".") for r in lines[1:]]
    header = [h.strip() for h in next(csv.reader([lines[0]], delimiter=delim))]
    if _numbers(header):
        raise GMRInputError(f"{src}: the first line holds numbers ({lines[0][:60].strip()}), not column names: a "
                            f"header row is needed, e.g. t,x,v,a,base_acc (see `gmr fit --help`), as the first line")
    expected = ("t, x0.. (one per DOF; or v0.. or a0.. alone), optional v0.., a0.., f0.., base_acc, m0.. (masses), "
                "equilibrium0.. (one DOF: x, v, a, f or force, m or mass, equilibrium also read as x0, v0, a0, f0, m0, "
                "equilibrium0)")
    t_scale, scales, unit = 1.0, [1.0] * len(header), None
    if not raw:  # the names a one-DOF lab file uses (and the NPZ keys), in any case, with a unit: "v [m/s]"
        header, t_scale, scales, unit = _standard_names(header, src)

    unknown = [] if raw else [h for h in header if not _signal_name(h)]
    if unknown or (not raw and ("t" not in header or not {"x0", "v0", "a0"} & set(header))):
        what = (f"unknown column(s) {unknown}" if unknown else "no column 't'" if "t" not in header else
                "no column of DOF 0 (x0, v0 or a0): every DOF, from 0 on, needs a sensor (x, v or a; a chain's "
                "cells numbered from the base); a DOF without one cannot be fitted")
        raise GMRInputError(f"{src}: {what}; found columns {header}, expected {expected} (the first line must be "
                            f"this header; a unit in brackets is allowed, 'v [m/s]'). To read a lab file's own "
                            f"names, map them: --columns t=Time,x=disp (CLI) or columns={{'t': 'Time', 'x': "
                            f"'disp'}} (API); the columns not mapped are then ignored")
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise GMRInputError(f"{src}: column(s) {dup} appear more than once in the header (x, v, a, f, force are read "
                            f"as x0, v0, a0, f0); keep one of each")
    rows = [(i + 1, r) for i, r in enumerate(lines) if i > 0 and r.strip()]
    if not rows:
        raise GMRInputError(f"{src}: the header is there but no data rows follow")
    ncol = len(header)
    try:  # fast path; on any failure the scan below names the row and column
        data = np.loadtxt(io.StringIO("\n".join(r for _, r in rows)), delimiter=delim, comments=None, ndmin=2)
        ok = data.shape == (len(rows), ncol)
    except ValueError:
        ok = False
    for j, (line_no, line) in enumerate([] if ok else rows):
        if j == 0:
            data = np.empty((len(rows), ncol))
        cells = line.split(delim)
        if len(cells) != ncol:
            raise GMRInputError(f"{src}: line {line_no} (sample {j}) has {len(cells)} cells, the header has "
                                f"{ncol} columns; every row needs one value per column")
        for c, cell in enumerate(cells):
            try:
                data[j, c] = float(cell)
            except ValueError:
                raise GMRInputError(f"{src}: line {line_no} (sample {j}), column '{header[c]}': {cell.strip()!r} "
                                    f"is not a number; fix or remove that row") from None
    col = {h: data[:, i] * scales[i] for i, h in enumerate(header)}
    if raw:
        return col

    def group(pre):
        idx = sorted(int(h[len(pre):]) for h in header if h.startswith(pre) and h[len(pre):].isdigit())
        if not idx:
            return None
        if idx != list(range(len(idx))):
            missing = sorted(set(range(max(idx) + 1)) - set(idx))
            raise GMRInputError(f"{src}: columns {pre}0.. must be numbered 0, 1, 2, ... without gaps; "
                                f"{', '.join(pre + str(i) for i in missing)} missing")
        return np.stack([col[f"{pre}{i}"] for i in idx], axis=1)

    eq, masses = group("equilibrium"), group("m")
    if eq is not None:
        eq = repeated_value(eq, "equilibrium", "the 'equilibrium' column", src)
    if masses is not None:
        masses = repeated_value(masses, "masses", "the mass column", src)
    return Recording(t=col["t"] * t_scale, x=group("x"), v=group("v"), a=group("a"),
                     base_acc=col.get("base_acc"), force=group("f"), name=path.stem, equilibrium=eq, masses=masses,
                     length_unit=unit)


#: a time column's unit in a CSV header ("t [ms]"): its factor to seconds
TIME_UNITS = {"s": 1.0, "sec": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "μs": 1e-6, "min": 60.0}
_UNIT = re.compile(r"^(.*?)\s*[\[(]\s*([^\])]*?)\s*[\])]$")


def _numbers(cells) -> bool:
    """Whether every cell of a header row parses as a number (a file without a header)."""
    try:
        [float(c.replace(",", ".")) for c in cells]
    except ValueError:
        return False
    return bool(cells)


#: length and angle units of a CSV header's kinematic columns (x, v, a, base_acc, equilibrium): factor to m or rad
LENGTH_UNITS = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "um": 1e-6, "µm": 1e-6, "μm": 1e-6, "km": 1e3, "in": 0.0254}
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180, "°": math.pi / 180}
#: standard gravity: an acceleration column in g ("a0 [g]", what many accelerometers give)
STANDARD_GRAVITY = 9.80665
FORCE_UNITS = {"N": 1.0, "kN": 1e3, "mN": 1e-3}
MASS_UNITS = {"kg": 1.0, "g": 1e-3}
_PER_S = re.compile(r"^(.+?)/s$")
_PER_S2 = re.compile(r"^(.+?)(?:/s\^2|/s2|/s²|/s\*\*2|/s/s)$")


def _unit_factor(kind: str, unit: str, column: str, src: str) -> tuple[str, float]:
    """(family, factor to SI) of a column's unit: family "length"/"angle" (the factor per m or rad; 'g' is
    "g"), "force" or "mass"."""
    u = unit.replace(" ", "")
    known = (f"x/equilibrium {sorted(LENGTH_UNITS) + sorted(ANGLE_UNITS)}, v in those per s ('mm/s'), a and base_acc "
             f"per s^2 ('m/s^2') or 'g', force {sorted(FORCE_UNITS)}, mass {sorted(MASS_UNITS)}")

    def length(name):
        if name in LENGTH_UNITS:
            return "length", LENGTH_UNITS[name]
        if name in ANGLE_UNITS:
            return "angle", ANGLE_UNITS[name]
        return None

    found = None
    if kind in ("x", "equilibrium"):
        found = length(u)
    elif kind == "v":
        m = _PER_S.match(u)
        found = length(m.group(1)) if m else None
    elif kind in ("a", "base_acc"):
        m = _PER_S2.match(u)
        found = ("g", STANDARD_GRAVITY) if u == "g" else (length(m.group(1)) if m else None)
    elif kind == "f":
        found = ("force", FORCE_UNITS[u]) if u in FORCE_UNITS else None
    elif kind == "m":
        found = ("mass", MASS_UNITS[u]) if u in MASS_UNITS else None
    if found is None:
        raise GMRInputError(f"{src}: the unit '{unit}' of column '{column}' is not one gmr_jax converts; known: "
                            f"{known}. Convert the column, or leave the unit out of the header (the values are then "
                            f"taken as they are, in the model's units)")
    return found


def _column_scales(names, units, src, labels=None) -> tuple[list[float], str | None]:
    """Factors that bring a CSV's labelled columns to one coherent set of units: lengths (and 'g') to the first
    labelled kinematic column's length unit, or to m where a force or mass column carries a unit (then N and kg,
    coherent with m and s); unlabelled columns are taken as they are. An accelerometer in g becomes m/s^2 (audit:
    'a0 [g]' was read as m/s^2, the barriers 75 % off, and nothing said so)."""
    kind_of = {n: re.sub(r"\d+$", "", n) for n in names}
    parsed = {n: _unit_factor(kind_of[n], u, n, src) for n, u in zip(names, units) if u is not None and n != "t"}
    if not parsed:
        return [1.0] * len(names), None
    families = {fam for fam, _ in parsed.values() if fam in ("length", "angle")}
    if len(families) > 1:
        raise GMRInputError(f"{src}: the header mixes lengths and angles ({', '.join(f'{n} [{u}]' for n, u in zip(names, units) if u)}); "
                            f"give the kinematic columns in one kind of unit")
    if "angle" in families and any(fam == "g" for fam, _ in parsed.values()):
        raise GMRInputError(f"{src}: an acceleration in g beside angles in the header: give angular accelerations in "
                            f"rad/s^2 or deg/s^2")
    coherent_si = any(fam in ("force", "mass") for fam, _ in parsed.values())
    ref_name = None if coherent_si else next((n for n, (fam, _) in parsed.items() if fam in ("length", "angle")), None)
    ref = 1.0 if ref_name is None else parsed[ref_name][1]
    scales = [1.0 if n not in parsed else parsed[n][1] / (ref if parsed[n][0] in ("length", "angle", "g") else 1.0)
              for n in names]
    labels = names if labels is None else labels  # the file's own header cells, for the message
    table = ANGLE_UNITS if ref_name is not None and parsed[ref_name][0] == "angle" else LENGTH_UNITS
    unit = next(k for k, f in table.items() if f == ref)  # the file's lengths (or angles) are now in this unit
    converted = [h for n, h, f in zip(names, labels, scales) if n in parsed and f != 1.0]
    bare = [h for n, h in zip(names, labels)
            if n not in parsed and n != "t" and kind_of[n] in ("x", "v", "a", "base_acc", "equilibrium")]
    if converted and bare:
        # audit: 'a0 [g]' labelled, x unlabelled in mm: a was made m/s^2 and x taken as m, 1000x apart, unsaid
        warnings.warn(f"{src}: {', '.join(converted)} converted to {unit} (per s, per s^2), but {', '.join(bare)} "
                      f"carr{'ies' if len(bare) == 1 else 'y'} no unit and {'is' if len(bare) == 1 else 'are'} taken "
                      f"as {'it is' if len(bare) == 1 else 'they are'}, in {unit}: if not, label "
                      f"{'it' if len(bare) == 1 else 'them'} in the header ('x0 [mm]', 'base_acc [g]')",
                      GMRDataWarning, stacklevel=4)
    return scales, unit


def _standard_names(header, src):
    """A CSV header's names as the contract's (`x0`, `v0`, ...): a unit in brackets or parentheses taken off
    ("v [m/s]", "t (ms)"), the case ignored where the lower-case name is the contract's, `time` read as `t`, and the
    one-DOF names (`x`, `v`, `a`, `f`, `force`, `m`, `mass`, `masses`, `equilibrium`) as `x0`, `m0`, ... The time
    column's unit, where given, scales it to seconds (`TIME_UNITS`); the other labelled columns are brought to one
    coherent set of units (`_column_scales`; the model is in the file's length unit, or SI where a force or mass is
    labelled). Returns the names, the factor of t, the factor of every column and the unit the lengths are now in
    (None: no unit labelled)."""
    out, units, t_scale = [], [], 1.0
    for h in header:
        m = _UNIT.match(h)
        name, unit = (m.group(1).strip(), m.group(2).strip()) if m else (h, None)
        low = name.lower()
        low = "t" if low == "time" else low
        if _signal_name(low) or _CSV_ALIASES.get(low):
            name = low
        name = _CSV_ALIASES.get(name, name)
        if name == "t" and unit is not None:
            t_scale = {k.lower(): f for k, f in TIME_UNITS.items()}.get(unit.lower())
            if t_scale is None:
                raise GMRInputError(f"{src}: the time column's unit '{unit}' is not one of {sorted(TIME_UNITS)}; "
                                    f"give t in seconds (or one of those units in the header, 't [ms]')")
        out.append(name)
        units.append(unit or None)
    known = [_signal_name(n) for n in out]
    scales, unit = _column_scales([n for n, k in zip(out, known) if k], [u for u, k in zip(units, known) if k], src,
                                  [h.strip() for h, k in zip(header, known) if k])
    it = iter(scales)
    return out, t_scale, [next(it) if k else 1.0 for k in known], unit


def _read_npz(path: Path, src: str, raw: bool = False):
    """The recording in an NPZ file; with `raw`, every array by its name (for a mapping)."""
    fix = "save it with np.savez(path, t=t, x=x, ...) or gmr_jax.save_recording"
    try:
        z = np.load(path, allow_pickle=False)
    except Exception as e:  # noqa: BLE001 - any unreadable file is a user error here
        raise GMRInputError(f"{src}: cannot read as NPZ ({type(e).__name__}); recordings are .npz "
                            f"(np.savez) or .csv files; {fix}") from None
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise GMRInputError(f"{src}: holds a single array (.npy), not named arrays; {fix}")
    with z:
        found = sorted(z.files)
        unknown = [] if raw else [k for k in found if k not in SIGNALS]
        if unknown or (not raw and ("t" not in found or not {"x", "v", "a"} & set(found))):
            what = (f"unknown array(s) {unknown}" if unknown else "no array 't'" if "t" not in found else
                    "no array 'x' (or 'v' or 'a')")
            raise GMRInputError(f"{src}: NPZ needs arrays 't' and 'x' (or 'v' or 'a' alone: velocity- or "
                                f"acceleration-only sensors; optional v, a, base_acc, force, masses, equilibrium); "
                                f"{what}; found {found}")
        arrays = {}
        for k in found:  # np.load is lazy: every read happens here, inside the check
            try:
                arrays[k] = np.asarray(z[k])
            except ValueError:
                raise GMRInputError(f"{src}: '{k}' is an object array (pickled Python objects), which is not "
                                    f"loaded; store it as a float array, {fix}") from None
            except Exception as e:  # noqa: BLE001 - a damaged member
                raise GMRInputError(f"{src}: cannot read array '{k}' ({type(e).__name__}); {fix}") from None
    if raw:
        return arrays
    return Recording(**arrays, name=path.stem)


def _split_units(raw: dict) -> tuple[dict, dict]:
    """A lab file's variables by their names with any unit in brackets taken off ('disp [mm]' -> 'disp', also kept
    under its full name), and the unit of each such name."""
    out, units = dict(raw), {}
    for key, val in raw.items():
        m = _UNIT.match(str(key))
        if m and m.group(1).strip() and m.group(1).strip() not in raw:
            out[m.group(1).strip()] = val
            units[m.group(1).strip()] = units[str(key)] = m.group(2).strip()
    return out, units


#: the contract's column name of each mapped field (`_column_scales` reads the kind from it)
_FIELD_COLUMN = {"x": "x0", "v": "v0", "a": "a0", "base_acc": "base_acc", "force": "f0", "masses": "m0",
                 "equilibrium": "equilibrium0"}


def _mapped_units(fields: dict, columns: dict, units: dict, src: str) -> tuple[dict, str | None]:
    """The mapped fields in one coherent set of units, where each maps one variable whose header carries a unit
    (`columns={'x': 'disp'}` with a column 'disp [mm]'), as a CSV with the contract's names would be read
    (`_column_scales`); a field computed from numbers or several variables is taken as it comes. Returns the fields
    and the unit their lengths are in (None: no unit stated)."""
    def unit_of(field):
        spec = columns.get(field, field)
        name = spec.strip().lstrip("+-").strip() if isinstance(spec, str) else None
        return units.get(name)

    fields = dict(fields)
    t_unit = unit_of("t")
    if t_unit is not None and "t" in fields:
        factor = {k.lower(): f for k, f in TIME_UNITS.items()}.get(t_unit.lower())
        if factor is None:
            raise GMRInputError(f"{src}: the time column's unit '{t_unit}' is not one of {sorted(TIME_UNITS)}")
        fields["t"] = np.asarray(fields["t"], float) * factor
    named = [(f, unit_of(f)) for f in _FIELD_COLUMN if f in fields and unit_of(f) is not None]
    if not named:
        return fields, None
    scales, unit = _column_scales([_FIELD_COLUMN[f] for f, _ in named], [u for _, u in named], src,
                                  [f"{f} [{u}]" for f, u in named])
    for (f, _), k in zip(named, scales):
        fields[f] = np.asarray(fields[f], float) * k
    return fields, unit


def load_recording(path, columns: dict | None = None) -> Recording:
    """Read and validate a recording (NPZ with keys t, x, [v, a, base_acc, force, masses], CSV
    with a header row t, x0.., v0.., a0.., base_acc or f0.., or MATLAB .mat with the NPZ's names).

    `columns` maps the recording's fields to the file's own variables as a lab stored them, each a
    product/quotient of variable names and numbers, or a list of those (one per DOF):
    `{"x": "qm", "force": "gtau*vir"}` (EMPS), `{"t": "time", "x": ["q1*1e-3", "q2*1e-3"]}`.
    Fields not mapped are read by their own names where the file has them.

    `path` is a str or `os.PathLike`. Anything else, a missing or empty file, a directory, an
    unreadable or object (pickled) array, an unknown or missing key/column, a non-numeric cell,
    an integer or boolean array, too few samples, NaN/inf, non-uniform time or a constant
    displacement column raises `GMRInputError` naming it and the fix."""
    if not isinstance(path, (str, os.PathLike)):
        raise GMRInputError(f"load_recording needs the path of an .npz or .csv file, got {type(path).__name__}; "
                            f"for arrays in memory build gmr_jax.Recording(t=..., x=...)")
    path = Path(path)
    src = str(path)
    if not path.exists():
        raise GMRInputError(f"{src}: no such file")
    if path.is_dir():
        raise GMRInputError(f"{src}: is a directory; give the .npz or .csv recording inside it")
    try:
        empty = path.stat().st_size == 0
    except OSError as e:
        raise GMRInputError(f"{src}: cannot read ({e.strerror})") from None
    if empty:
        raise GMRInputError(f"{src}: the file is empty (0 bytes)")
    try:
        suffix = path.suffix.lower()
        read = _read_csv if suffix == ".csv" else _read_npz
        if suffix == ".mat" or columns is not None:  # the file's own names, mapped to the fields
            from ._mapping import map_columns, read_mat

            raw = read_mat(path, src) if suffix == ".mat" else read(path, src, raw=True)
            raw, units = _split_units(raw)
            fields = map_columns(raw, columns, src)
            fields, unit = _mapped_units(fields, columns or {}, units, src)
            rec = Recording(**fields, name=path.stem, length_unit=unit)
        else:
            rec = read(path, src)
    except OSError as e:
        raise GMRInputError(f"{src}: cannot read ({e.strerror or type(e).__name__})") from None
    except GMRInputError as e:  # the Recording's own checks name it by its stem: use the path
        msg = str(e)
        if msg.startswith(f"{path.stem}: "):
            msg = msg[len(path.stem) + 2:]
        raise GMRInputError(msg if msg.startswith(src) else f"{src}: {msg}") from None
    return validate(rec, src)


def regression_targets(rec: Recording, masses: np.ndarray, topology) -> np.ndarray:
    """Force carried by each DOF (N, D): input force minus inertia, the left side of Eq. (8).

    Independent: force_i - m_i a_i. Chain: sum_{k>=i} (force_k - m_k a_k), i.e. H a with H of
    Eq. (9) written for base-first numbering (`AbstractTopology.carried`)."""
    _, f = rec.inputs()
    return as_topology(topology).carried(f - rec.a * masses[None, :])


def length_unit(recs) -> tuple[str | None, str | None]:
    """The unit of the recordings' lengths where their files' headers named one (`Recording.length_unit`), and a
    warning where some named none. Recordings in different units are refused: one fit takes every file's numbers
    as one set of units (audit: which unit a file's lengths end in depends on which columns carry a label, and
    nothing said which)."""
    named = {r.name: r.length_unit for r in recs if r.length_unit is not None}
    if len(set(named.values())) > 1:
        raise GMRInputError("the recordings' lengths are in different units ("
                            + ", ".join(f"{n}: {u}" for n, u in named.items()) + "): one fit takes them as one set; "
                            "label every file's columns alike (e.g. 'x0 [mm]' in each), or convert them")
    if not named:
        return None, None
    unit = next(iter(named.values()))
    bare = [r.name for r in recs if r.length_unit is None]
    return unit, (f"{', '.join(bare)} carr{'ies' if len(bare) == 1 else 'y'} no unit in the header while the other "
                  f"files are in {unit}: taken as {unit} too" if bare else None)
