"""The user-error type of gmr_jax and the small checks that raise it.

Convention (issue 13): anything a user hands the tool that is wrong raises `GMRInputError` at
call time, with a one-line message that names the offending key, column, sample or argument and
says the fix. The checks below run in plain Python on concrete values; a JAX tracer (the value
inside `jit`, `vmap` or `grad`) is never inspected, so the checked functions stay traceable.
"""

import math
import numbers

import numpy as np


class GMRInputError(ValueError):
    """A user mistake in the data or options given to gmr_jax.

    The message names the problem and how to fix it. The command line prints it as one line
    and exits with status 2.
    """


def is_tracer(value) -> bool:
    """True when `value` is (or holds) a JAX tracer: its value cannot be checked."""
    import jax

    return isinstance(value, jax.core.Tracer)


def describe(value, limit: int = 60) -> str:
    """A short repr of a value for a message (long ones cut)."""
    s = repr(value)
    return s if len(s) <= limit else s[: limit - 3] + "..."


def as_whole_number(value, name: str, *, lo: int | None = None, hi: int | None = None,
                    accept_float: bool = False, fix: str = "") -> int:
    """`value` as a Python int, or `GMRInputError` naming `name`.

    Booleans are refused (True is not the number 1 here); an integer-valued float (2.0) is
    accepted only with `accept_float` (JSON files may write 2.0)."""
    tail = f"; {fix}" if fix else ""
    if isinstance(value, (bool, np.bool_)) or value is None:
        raise GMRInputError(f"{name} must be a whole number, got {describe(value)}{tail}")
    whole_float = (accept_float and isinstance(value, numbers.Real) and math.isfinite(value)
                   and float(value).is_integer())
    if not (isinstance(value, numbers.Integral) or whole_float):
        raise GMRInputError(f"{name} must be a whole number, got {describe(value)}{tail}")
    out = int(value)
    if lo is not None and out < lo:
        raise GMRInputError(f"{name} must be >= {lo}, got {out}{tail}")
    if hi is not None and out > hi:
        raise GMRInputError(f"{name} must be <= {hi}, got {out}{tail}")
    return out


def check_real(value, name: str, *, lo: float | None = None, hi: float | None = None,
               lo_open: bool = False, hi_open: bool = False, fix: str = "") -> None:
    """Check that `value` (a number or an array of them) is real, finite and within the bounds
    (`lo_open`/`hi_open`: strict). Tracers are not inspected. Raises `GMRInputError`."""
    if is_tracer(value):
        return
    tail = f"; {fix}" if fix else ""
    if isinstance(value, (bool, np.bool_, str, bytes)) or value is None:
        raise GMRInputError(f"{name} must be a number, got {describe(value)}{tail}")
    try:
        arr = np.asarray(value)
    except Exception:  # noqa: BLE001 - anything that is not array-like
        raise GMRInputError(f"{name} must be a number, got {describe(value)}{tail}") from None
    if arr.dtype.kind not in "iuf":
        raise GMRInputError(f"{name} must be a real number, got {describe(value)}{tail}")
    arr = arr.astype(float)
    if not np.all(np.isfinite(arr)):
        raise GMRInputError(f"{name} must be finite, got {describe(value)}{tail}")
    if lo is not None and np.any(arr <= lo if lo_open else arr < lo):
        raise GMRInputError(f"{name} must be {'>' if lo_open else '>='} {lo:g}, got {describe(value)}{tail}")
    if hi is not None and np.any(arr >= hi if hi_open else arr > hi):
        raise GMRInputError(f"{name} must be {'<' if hi_open else '<='} {hi:g}, got {describe(value)}{tail}")


class GMRDataWarning(UserWarning):
    """The data or the model reconstructed from them break a physical assumption of GMR
    (small vibrations about distinct stable equilibria, inputs recorded, bounded restoring
    force); the model was built but should not be trusted without a look."""
