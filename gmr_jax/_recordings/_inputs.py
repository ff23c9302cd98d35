"""What the fitting entry points accept as recordings: `Recording`s, file paths, or arrays in memory."""

import os
from collections.abc import Mapping

import numpy as np

from .._errors import GMRInputError
from ._recording import Recording, load_recording

#: the names a dict or structured array may use for each field (as a one-DOF CSV header or an NPZ)
_ALIASES = {"t": "t", "time": "t", "x": "x", "x0": "x", "v": "v", "v0": "v", "a": "a", "a0": "a",
            "base_acc": "base_acc", "force": "force", "f": "force", "f0": "force", "masses": "masses",
            "mass": "masses", "m": "masses", "m0": "masses", "equilibrium": "equilibrium"}

_HOW = ("a Recording, the path of an .npz/.csv/.mat file, a dict of arrays {'t': t, 'x': x, 'base_acc': b} (or "
        "'force', 'v', 'a', 'masses'), or a structured array with those field names (np.genfromtxt(path, "
        "delimiter=',', names=True))")


def as_recording(item, index: int = 0) -> Recording:
    """One recording from `item`: a `Recording` (returned as is), a path (`load_recording`), a mapping of named
    arrays (a dict, an opened NPZ) or a structured array whose field names are the recording's (`t`, `x`, `v`,
    `a`, `base_acc`, `force`, `masses`, `equilibrium`; one-DOF CSV names `time`, `f`, `m` too).

    **Arguments:** `item`, the object; `index`, its place in the list (names an unnamed recording `recording
    {index}`). **Returns:** a `Recording`. A plain array without field names, or a name that is no field, raises
    `GMRInputError` naming the forms accepted."""
    if isinstance(item, Recording):
        return item
    if isinstance(item, (str, os.PathLike)):
        return load_recording(item)
    if isinstance(item, np.ndarray) and item.dtype.names:
        item = {n: item[n] for n in item.dtype.names}
    if isinstance(item, Mapping):
        fields, unknown = {}, []
        for key in item:
            name = _ALIASES.get(str(key).strip().lower())
            if name is None:
                unknown.append(key)
            else:
                fields[name] = np.asarray(item[key], float)
        if unknown:
            raise GMRInputError(f"recording {index}: unknown field(s) {unknown}; the fields are t, x, v, a, base_acc, "
                                f"force, masses, equilibrium (map a lab file's own names with load_recording(path, "
                                f"columns={{...}}))")
        if "t" not in fields:
            raise GMRInputError(f"recording {index}: no time 't'; give the sample times in s")
        for key in ("masses", "equilibrium"):  # a column that repeats one value per DOF, as a CSV stores it
            if key in fields and np.ndim(fields[key]) >= 1 and np.shape(fields[key])[0] == np.shape(fields["t"])[0]:
                fields[key] = np.asarray(fields[key]).reshape(fields["t"].shape[0], -1)[0]
        return Recording(**fields, name=f"recording {index}")
    raise GMRInputError(f"recording {index}: got {type(item).__name__}"
                        + (f" of shape {item.shape} without field names" if isinstance(item, np.ndarray) else "")
                        + f"; give {_HOW}")


def as_recordings(items) -> list[Recording]:
    """`as_recording` for each item of a list (a single item, not in a list, is refused with the fix)."""
    if isinstance(items, (Recording, str, os.PathLike, Mapping, np.ndarray)):
        raise GMRInputError(f"recordings must be a list, one per equilibrium (e.g. [rec_well1, rec_well2]), got one "
                            f"{type(items).__name__}; wrap it in a list")
    return [as_recording(r, i) for i, r in enumerate(items)]
