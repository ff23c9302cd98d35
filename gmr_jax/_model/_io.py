"""Read and write models in the "gmr-model/1" JSON format (docs/formats.md)."""

import json
import os
from pathlib import Path

import numpy as np

from .._errors import GMRInputError, describe
from .._topology import TOPOLOGIES, Graph, check_elements
from ._model import (
    GlobalModel, check_covariance, check_masses, check_terms, covariance_entries, from_terms, term_key)

FORMAT = "gmr-model/1"


def model_to_dict(model: GlobalModel, **extra) -> dict:
    terms = model.terms()
    # a DOF whose coefficients are all zero would have no term and the file would not load
    # back (a DOF without terms is refused): write its linear stiffness as an explicit 0
    key = term_key(model.topology)
    present = {t[key] for t in terms}
    terms += [{key: i, "physics": "stiffness", "order": 1, "coefficient": 0.0}
              for i in range(model.n_elements) if i not in present]
    topo = model.topology
    out = {
        "format": FORMAT,
        "topology": topo.to_dict() if isinstance(topo, Graph) else topo.name,
        "masses": [float(m) for m in np.asarray(model.masses)],
        "terms": terms,
    }
    cov = covariance_entries(model)
    if cov is not None:  # optional extension (old readers ignore it; files without it still load)
        out["covariance"] = cov
    out.update(extra)
    return out


def model_from_dict(d: dict, source: str = "model") -> GlobalModel:
    """A `GlobalModel` from a "gmr-model/1" dict (the parsed JSON). Every key is checked:
    `GMRInputError` names the bad key or term and the fix (see `from_terms`)."""
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise GMRInputError(
            f"{source}: not a {FORMAT} model (missing or wrong 'format' key); "
            f"write it with gmr fit or see the model format in docs/formats.md"
        )
    topo = d.get("topology", "independent")
    if "masses" not in d:
        raise GMRInputError(f"{source}: no 'masses' key; add \"masses\": [m0, m1, ...], one per DOF")
    masses = check_masses(d["masses"], source)
    if isinstance(topo, dict):
        topo = graph_topology(topo, masses.size, source)
    elif not isinstance(topo, str) or topo not in TOPOLOGIES:
        raise GMRInputError(f"{source}: 'topology' must be one of {tuple(TOPOLOGIES)} or "
                            f"{{\"kind\": \"graph\", \"elements\": [[a, b], ...]}}, got {describe(topo)}")
    n, key = (topo.n_elements, "element") if isinstance(topo, Graph) else (masses.size, "dof")
    if "terms" not in d:
        raise GMRInputError(f"{source}: no 'terms' key; add the list of terms, "
                            f"e.g. {{\"{key}\": 0, \"physics\": \"stiffness\", \"order\": 1, \"coefficient\": 1.0}}")
    terms = check_terms(d["terms"], n, source, key=key)
    if "stderr" in d:
        raise GMRInputError(f"{source}: a top-level 'stderr' is not part of {FORMAT}; give each term "
                            f"its own \"stderr\" key")
    cov = d.get("covariance")
    if cov is not None:
        check_covariance(cov, n, source, key=key)  # messages name the file
    return from_terms(masses, terms, topo, covariance=cov)


def graph_topology(topo: dict, nodes: int, source: str) -> Graph:
    """The `Graph` of a model file's `{"kind": "graph", "elements": [[a, b], ...]}` on `nodes` nodes."""
    if set(topo) != {"kind", "elements"} or topo.get("kind") != "graph":
        raise GMRInputError(f"{source}: a graph topology is {{\"kind\": \"graph\", \"elements\": [[a, b], ...]}}, "
                            f"got {describe(topo)}")
    return Graph(nodes, parse_elements(topo["elements"], nodes, source))


def parse_elements(elements, nodes: int, source: str) -> list[tuple[int, int]]:
    """Checked [a, b] pairs (`GMRInputError` naming the bad element and the fix)."""
    if not isinstance(elements, (list, tuple)):
        raise GMRInputError(f"{source}: 'elements' must be a list of [a, b] pairs, got {describe(elements)}")
    out = []
    for e, pair in enumerate(elements):
        if (not isinstance(pair, (list, tuple)) or len(pair) != 2
                or any(isinstance(i, bool) or not isinstance(i, int) for i in pair)):
            raise GMRInputError(f"{source}: element {e} is {describe(pair)}, not an [a, b] pair of integers; node "
                                f"indices are 0..D-1 and -1 for the ground")
        out.append((pair[0], pair[1]))
    check_elements(out, nodes, source)
    return out


def load_graph(path) -> tuple[Graph, np.ndarray]:
    """Read a graph file `{"nodes": D, "masses": [m_0, ..., m_{D-1}], "elements": [[a, b], ...]}`
    (node indices 0..D-1, -1 for the ground or moving base; element e deforms by x_b - x_a).

    **Arguments:** `path`: the JSON file, or a dict in that format.

    **Returns:** `(graph, masses)`: the `Graph` and the (D,) masses.

    A missing file, invalid JSON, a missing or unknown key, a node count that is not a positive
    integer, a masses count other than D, an index outside -1..D-1, an element from a node to
    itself or a node that no element touches raises `GMRInputError` naming it and the fix."""
    if isinstance(path, dict):
        d, source = path, "graph dict"
    else:
        p, source = Path(path), str(path)
        if not p.is_file():
            raise GMRInputError(f"{p}: no such graph file")
        try:
            d = json.loads(p.read_text(encoding="utf-8-sig"), object_pairs_hook=_no_duplicate_keys)
        except (UnicodeDecodeError, json.JSONDecodeError) as e:
            raise GMRInputError(f"{p}: not a JSON graph file ({e}); write {{\"nodes\": D, \"masses\": [...], "
                                f"\"elements\": [[a, b], ...]}}") from None
    if not isinstance(d, dict) or set(d) != {"nodes", "masses", "elements"}:
        got = sorted(d) if isinstance(d, dict) else describe(d)
        raise GMRInputError(f"{source}: a graph file has exactly the keys 'nodes', 'masses', 'elements', got {got}; "
                            f"write {{\"nodes\": D, \"masses\": [m_0, ...], \"elements\": [[a, b], ...]}}")
    nodes = d["nodes"]
    if isinstance(nodes, bool) or not isinstance(nodes, int) or nodes < 1:
        raise GMRInputError(f"{source}: 'nodes' must be a positive integer, got {describe(nodes)}")
    masses = check_masses(d["masses"], source)
    if masses.size != nodes:
        raise GMRInputError(f"{source}: {masses.size} masses for {nodes} nodes; give one mass per node")
    return Graph(nodes, parse_elements(d["elements"], nodes, source)), masses


def save_graph(path, graph: Graph, masses) -> None:
    """Write a graph file (the format of `load_graph`)."""
    masses = check_masses(masses, "save_graph")
    if not isinstance(graph, Graph) or masses.size != graph.nodes:
        raise GMRInputError(f"save_graph: needs a gmr_jax.Graph and one mass per node, got "
                            f"{type(graph).__name__} and {masses.size} masses")
    Path(path).write_text(json.dumps({"nodes": graph.nodes, "masses": masses.tolist(),
                                      "elements": [list(e) for e in graph.elements]}))


def save_model(model, path, **extra) -> None:
    """Write `model` as "gmr-model/1" JSON (coefficients as exact float reprs).

    `model`: a `GlobalModel`, or the `Solution` that `reconstruct` / `gmc_sindy` returned: then
    the file also carries what `gmr fit` writes with it (`_metadata.fit_metadata`): the method,
    the library orders, the training R² and NRMSE, the warnings, the data and speed ranges, and
    per DOF the route, degree and design (`gmr show` prints them; `gmr basins` and
    `gmr actuate` read the ranges). `extra`: further top-level
    keys (they override those)."""
    from .._solution import Solution

    if isinstance(model, Solution):
        from ._metadata import fit_metadata

        model, extra = model.value, fit_metadata(model.stats if isinstance(model.stats, dict) else {}) | extra
    if not isinstance(model, GlobalModel):
        raise GMRInputError(f"save_model writes a GlobalModel (or the Solution of reconstruct), got "
                            f"{type(model).__name__}")
    Path(path).write_text(json.dumps(model_to_dict(model, **extra), indent=1))


def _no_duplicate_keys(pairs):
    out = {}
    for k, v in pairs:
        if k in out:
            raise GMRInputError(f"key {k!r} appears twice in one JSON object; keep one")
        out[k] = v
    return out


def load_model(path) -> GlobalModel:
    """Read a "gmr-model/1" model.

    **Arguments:** `path`: a path (str or `os.PathLike`) to the JSON file written by
    `save_model` / `gmr fit`, or a dict already in that format (an in-memory model, e.g. the
    parsed JSON; read with `model_from_dict`).

    Anything else, a missing file, a directory, a binary file (an NPZ recording given as the
    model, say), invalid JSON, a key that appears twice, or any malformed key or term raises
    `GMRInputError` naming it and the fix.

    Examples:
        >>> import gmr_jax as gmr
        >>> model = gmr.load_model({"format": "gmr-model/1", "topology": "independent", "masses": [1.0],
        ...     "terms": [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -2244.0},
        ...               {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1755.0},
        ...               {"dof": 0, "physics": "velocity_damping", "order": 3, "coefficient": 10.0}]})
        >>> print(model)
        F_0(x, v) = -2244 x + 1755 x^3 + 10 v^3
        >>> gmr.load_model("no_such_model.json")
        Traceback (most recent call last):
        ...
        gmr_jax._errors.GMRInputError: no_such_model.json: no such model file
    """
    if isinstance(path, dict):
        return model_from_dict(path, "model dict")
    if not isinstance(path, (str, os.PathLike)):
        raise GMRInputError(f"load_model needs the path of a {FORMAT} .json file or a {FORMAT} dict, got "
                            f"{type(path).__name__}")
    p = Path(path)
    if not p.exists():
        raise GMRInputError(f"{p}: no such model file")
    if p.is_dir():
        raise GMRInputError(f"{p}: is a directory, not a model file; give the .json model inside it")
    try:
        raw = p.read_bytes()
    except OSError as e:
        raise GMRInputError(f"{p}: cannot read the model file ({e.strerror})") from None
    if not raw.strip():
        raise GMRInputError(f"{p}: the model file is empty; write it with gmr fit or save_model")
    try:
        text = raw.decode("utf-8-sig")  # a byte-order mark (Windows editors) is not an error
    except UnicodeDecodeError:
        kind = "a zip/NPZ archive (a recording?)" if raw[:2] == b"PK" else "binary data"
        raise GMRInputError(f"{p}: not a JSON text file but {kind}; give the {FORMAT} .json model "
                            f"written by gmr fit or save_model") from None
    try:
        d = json.loads(text, object_pairs_hook=_no_duplicate_keys)
    except json.JSONDecodeError as e:
        raise GMRInputError(f"{p}: not valid JSON ({e.msg} at line {e.lineno})") from None
    except GMRInputError as e:
        raise GMRInputError(f"{p}: {e}") from None
    except RecursionError:
        raise GMRInputError(f"{p}: JSON nested too deeply to be a {FORMAT} model") from None
    return model_from_dict(d, str(p))
