"""What a fitted model's file carries beside its coefficients, read from the `Solution` of
`reconstruct` / `gmc_sindy`: one definition for `save_model(solution, ...)` and `gmr fit`, so a
model saved from Python holds what the command line writes (the method, library orders, training
scores, warnings, the data and speed ranges, and per DOF the route, degree and design)."""

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


def coordination_of(stats: dict) -> list[dict]:
    """Per DOF, how `reconstruct` found the global law, JSON-ready: the route ("evidence",
    "hermite", "gls"), the restoring degree, and on the evidence route the DOFs that share its
    design with its spread about the shared law; [] where the fit has none (GMC-SINDy)."""
    rows = []
    for rep in stats.get("dofs", []):
        st = rep.stats if isinstance(rep.stats, dict) else {}
        if st.get("coordination") is None:
            return []
        row = {"route": str(st["coordination"]), "degree": int(st.get("degree", st.get("K_r", -1)))}
        if "design" in st:
            row |= {"design": [int(k) for k in st["design"]], "design_spread": float(st["design_spread"])}
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
    routes = coordination_of(stats)
    if routes:
        meta["coordination"] = routes
    return meta
