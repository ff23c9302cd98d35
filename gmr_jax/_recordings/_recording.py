"""Recordings: one experiment or simulation run, in the NPZ/CSV format of the contracts."""

import csv
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .._errors import GMRInputError
from .._topology import as_topology
from ._derivatives import differentiate

MIN_SAMPLES = 64


@dataclass(frozen=True)
class Recording:
    """One run. `t` (N,), `x` (N, D) displacements (cell deformations for a chain, base cell
    first); optional `v`, `a` (absolute accelerations of the masses), inputs `base_acc` (N,) or
    `force` (N, D), optional `masses` (D,). `derived` lists the signals estimated, not measured.
    """

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray | None = None
    a: np.ndarray | None = None
    base_acc: np.ndarray | None = None
    force: np.ndarray | None = None
    masses: np.ndarray | None = None
    name: str = "recording"
    derived: tuple = field(default_factory=tuple)

    @property
    def n_samples(self) -> int:
        return self.t.shape[0]

    @property
    def n_dof(self) -> int:
        return self.x.shape[1]

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])

    def inputs(self):
        """(base_acc (N,), force (N, D)), zeros where absent."""
        n, d = self.x.shape
        b = self.base_acc if self.base_acc is not None else np.zeros(n)
        f = self.force if self.force is not None else np.zeros((n, d))
        return b, f

    def complete(self, topology: str = "chain", window: int | None = None) -> "Recording":
        """Fill missing `v` and `a` by Savitzky-Golay differentiation of x (recorded in
        `derived`). `a` is absolute: x'' plus base acceleration (chain: cumulated over cells)."""
        v, a, derived = self.v, self.a, list(self.derived)
        if v is None:
            v = differentiate(self.x, self.dt, 1, window)
            derived.append("v")
        if a is None:
            xdd = differentiate(self.x, self.dt, 2, window)
            b, _ = self.inputs()
            a = as_topology(topology).absolute(xdd, b)
            derived.append("a")
        return replace(self, v=v, a=a, derived=tuple(derived))

    def save(self, path) -> None:
        save_recording(self, path)


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
            f"{src}: only {n} samples; at least {min_samples} are needed to fit a local model "
            f"(record longer or sample faster)"
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
    dt = np.diff(t)
    if np.any(dt <= 0):
        i = int(np.argmax(dt <= 0))
        raise GMRInputError(f"{src}: 't' is not strictly increasing (at sample {i + 1})")
    if np.max(np.abs(dt - dt.mean())) > 1e-6 * dt.mean() + 1e-12:
        raise GMRInputError(
            f"{src}: time is not uniformly sampled (steps from {dt.min():.3g} to {dt.max():.3g} s); "
            f"resample onto a uniform grid first"
        )
    return replace(rec, **out)


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
        np.savetxt(path, np.hstack(cols), delimiter=",", header=",".join(names), comments="")
        return
    data = {k: getattr(rec, k) for k in ("t", "x", "v", "a", "base_acc", "force", "masses")}
    data = {k: v for k, v in data.items() if v is not None and k not in rec.derived}
    np.savez(path, **data)


def load_recording(path) -> Recording:
    """Read and validate a recording (NPZ with keys t, x, [v, a, base_acc, force, masses], or
    CSV with a header row t, x0.., v0.., a0.., base_acc or f0..)."""
    path = Path(path)
    src = str(path)
    if not path.exists():
        raise GMRInputError(f"{src}: no such file")
    if path.suffix.lower() == ".csv":
        try:
            with open(path) as fh:
                header = next(csv.reader(fh))
            data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        except (StopIteration, ValueError) as e:
            raise GMRInputError(f"{src}: cannot read as CSV with a header row ({e})") from None
        header = [h.strip() for h in header]
        if data.shape[1] != len(header):
            raise GMRInputError(f"{src}: {len(header)} header names but {data.shape[1]} columns")
        col = {h: data[:, i] for i, h in enumerate(header)}

        def group(pre):
            keys = sorted((h for h in header if h.startswith(pre) and h[len(pre):].isdigit()),
                          key=lambda h: int(h[len(pre):]))
            return np.stack([col[k] for k in keys], axis=1) if keys else None

        if "t" not in col or group("x") is None:
            raise GMRInputError(f"{src}: CSV needs columns 't' and 'x0' (and x1.. for more DOFs)")
        rec = Recording(t=col["t"], x=group("x"), v=group("v"), a=group("a"),
                        base_acc=col.get("base_acc"), force=group("f"), name=path.stem)
    else:
        try:
            z = np.load(path, allow_pickle=False)
        except Exception as e:  # noqa: BLE001 - any unreadable file is a user error here
            raise GMRInputError(f"{src}: cannot read as NPZ ({type(e).__name__})") from None
        if "t" not in z or "x" not in z:
            raise GMRInputError(f"{src}: NPZ needs arrays 't' and 'x'; found {sorted(z.files)}")
        rec = Recording(**{k: z[k] for k in ("t", "x", "v", "a", "base_acc", "force", "masses") if k in z},
                        name=path.stem)
    return validate(rec, src)
