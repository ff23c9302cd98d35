"""Argument types and checks shared by the `gmr` subcommands (each names the option and the fix)."""

import argparse

import numpy as np

from .._errors import GMRInputError


def positive_int(s):
    v = int(s)
    if v < 1:
        raise argparse.ArgumentTypeError("must be >= 1")
    return v


def grid(spec, name):
    """START:STOP:NUM -> np.linspace (f must stay positive)."""
    try:
        a, b, n = spec.split(":")
        a, b, n = float(a), float(b), int(n)
    except ValueError:
        raise GMRInputError(f"--{name} must be START:STOP:NUM, e.g. 0.1:5:50, got {spec!r}") from None
    if n < 1 or not (np.isfinite(a) and np.isfinite(b)) or (name == "f" and min(a, b) <= 0):
        raise GMRInputError(f"--{name} {spec!r}: need NUM >= 1, finite bounds (and f > 0)")
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


def start_configuration(spec, wells):
    """x0 from a configuration label like 0-1-1-0-0 (cell 0 first; a digit = that cell's well)."""
    if spec is None:
        return None
    try:
        idx = [int(c) for c in spec.split("-")]
    except ValueError:
        raise GMRInputError(f"--start must look like 0-1-1-0-0 (one well index per DOF), got {spec!r}") from None
    n_wells = np.sum(~np.isnan(wells), axis=1)
    if len(idx) != wells.shape[0] or any(k < 0 or k >= n for k, n in zip(idx, n_wells)):
        raise GMRInputError(f"--start {spec!r}: need {wells.shape[0]} well indices, each below that DOF's "
                            f"number of wells {n_wells.tolist()}")
    return np.array([wells[i, k] for i, k in enumerate(idx)])
