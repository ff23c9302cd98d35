"""Read and write models in the "gmr-model/1" JSON format (see README, "File formats")."""

import json
from pathlib import Path

import numpy as np

from .._errors import GMRInputError
from ._model import GlobalModel, from_terms
from .._topology import TOPOLOGIES

FORMAT = "gmr-model/1"
KNOWN_PHYSICS = ("stiffness", "velocity_damping", "position_damping")


def model_to_dict(model: GlobalModel, **extra) -> dict:
    out = {
        "format": FORMAT,
        "topology": model.topology.name,
        "masses": [float(m) for m in np.asarray(model.masses)],
        "terms": model.terms(),
    }
    out.update(extra)
    return out


def model_from_dict(d: dict, source: str = "model") -> GlobalModel:
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise GMRInputError(
            f"{source}: not a {FORMAT} model (missing or wrong 'format' key); "
            f"write it with gmr fit or see the README's model format"
        )
    topo = d.get("topology", "independent")
    if topo not in TOPOLOGIES:
        raise GMRInputError(f"{source}: topology must be one of {tuple(TOPOLOGIES)}, got {topo!r}")
    try:
        masses = np.asarray(d["masses"], dtype=float).reshape(-1)
    except (KeyError, TypeError, ValueError):
        raise GMRInputError(f"{source}: 'masses' must be a list of numbers, one per DOF") from None
    if masses.size == 0 or not np.all(np.isfinite(masses)) or np.any(masses <= 0):
        raise GMRInputError(f"{source}: masses must be finite and positive, got {masses.tolist()}")
    terms = d.get("terms", [])
    for t in terms:
        if t.get("physics") not in KNOWN_PHYSICS:
            raise GMRInputError(
                f"{source}: unknown physics {t.get('physics')!r}; known: {', '.join(KNOWN_PHYSICS)}"
            )
        if not (0 <= int(t.get("dof", -1)) < masses.size):
            raise GMRInputError(f"{source}: term {t} names a dof outside 0..{masses.size - 1}")
        if int(t.get("order", -1)) < 0 or not np.isfinite(float(t.get("coefficient", np.nan))):
            raise GMRInputError(f"{source}: term {t} needs an order >= 0 and a finite coefficient")
    return from_terms(masses, terms, topo)


def save_model(model: GlobalModel, path, **extra) -> None:
    """Write `model` as "gmr-model/1" JSON (coefficients as exact float reprs)."""
    Path(path).write_text(json.dumps(model_to_dict(model, **extra), indent=1))


def load_model(path) -> GlobalModel:
    """Read a "gmr-model/1" JSON file; a malformed file raises `GMRInputError`."""
    p = Path(path)
    if not p.exists():
        raise GMRInputError(f"{p}: no such model file")
    try:
        d = json.loads(p.read_text())
    except json.JSONDecodeError as e:
        raise GMRInputError(f"{p}: not valid JSON ({e.msg} at line {e.lineno})") from None
    return model_from_dict(d, str(p))
