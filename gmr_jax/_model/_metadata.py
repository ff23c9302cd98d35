"""What a fitted model's file carries beside its coefficients, read from the `Solution` of
`reconstruct` / `gmc_sindy`: one definition for `save_model(solution, ...)` and `gmr fit`, so a
model saved from Python holds what the command line writes (the method, library orders, training
scores, warnings, the data and speed ranges, the resolution report, the coordination route and
the shared design)."""

import json

import numpy as np


def ranges(recordings, key: str) -> list[list[float]]:
    """[min, max] per DOF of `key` ("x" or "v") over the (completed) training recordings; v as recorded or
    estimated, else the central difference of x."""
    cols = []
    for r in recordings:
        a = getattr(r, key)
        if a is None and key == "v":
            a = np.gradient(np.asarray(r.x, float), r.dt, axis=0)
        cols.append(np.asarray(a, float).reshape(len(r.t), -1))
    a = np.concatenate(cols)
    return [[float(a[:, i].min()), float(a[:, i].max())] for i in range(a.shape[1])]


def shared_design_of(stats: dict) -> list[dict]:
    """Per DOF, `reconstruct`'s `stats["shared_design"]` (JSON-ready), or [] where the fit had none
    (a single DOF, GMC-SINDy, or sharing off)."""
    rows = [rep.stats.get("shared_design") for rep in stats.get("dofs", [])]
    if not rows or not any(isinstance(r, dict) and "tau" in r for r in rows):
        return []
    return [json.loads(json.dumps(r, default=float)) if isinstance(r, dict) else {} for r in rows]


def coordination_of(stats: dict) -> list[dict]:
    """Per DOF, the coordination route `reconstruct` took (auto: "gls", "joint", "gls + joint
    damping") and its notes (why the paper's route was replaced or kept, or its degree changed),
    JSON-ready; [] where the fit has none (GMC-SINDy)."""
    rows = []
    for rep in stats.get("dofs", []):
        route = rep.stats.get("coordination") if isinstance(rep.stats, dict) else None
        if route is None:
            return []
        row = {"route": str(route), "notes": [str(n) for n in rep.stats.get("paper_route_rejected", [])]}
        if any(rep.stats.get("errors_in_variables") or []):
            row["errors_in_variables"] = rep.stats["errors_in_variables"]
        if any(w and w.get("applied") for w in rep.stats.get("velocity_noise") or []):
            row["velocity_noise"] = rep.stats["velocity_noise"]
        rows.append(row)
    return rows


def fit_metadata(stats: dict) -> dict:
    """The top-level keys a fitted model's file carries, from a fit's `stats`."""
    meta = {}
    if "method" in stats:
        meta["method"] = stats["method"]
    lib = stats.get("library")
    if lib is not None and hasattr(lib, "restoring_order"):
        meta["library"] = {"r": lib.restoring_order, "d": lib.damping_order}
    for key in ("training", "data_range", "speed_range", "units"):
        if key in stats:
            meta[key] = stats[key]
    if "warnings" in stats:
        meta["warnings"] = list(stats["warnings"])
    if "resolution" in stats and hasattr(stats["resolution"], "to_dict"):
        meta["resolution"] = stats["resolution"].to_dict()  # gmr show prints it
    design = shared_design_of(stats)
    if design:
        meta["shared_design"] = design
    routes = coordination_of(stats)
    if routes:
        meta["coordination"] = routes
    return meta
