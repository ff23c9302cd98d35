"""Physical sanity checks of the recordings and of the reconstructed model (GitHub issue 13).

GMR assumes one small-vibration recording about each stable equilibrium, with its input
recorded, and gives back a polynomial restoring force that is only measured near those
equilibria. Data that break these assumptions still give numbers; the checks here say so in
plain words. Each check is a small NumPy function stating its rule and its threshold;
`reconstruct` runs them and either refuses (`GMRInputError`: the data cannot give a model) or
warns (the model is built but suspect): the warnings are returned in `stats["warnings"]`,
emitted as `GMRDataWarning`, printed by `gmr fit` and written into the model file.

The thresholds leave the paper's nominal cases silent: the built-in systems at their default
amplitudes (bistable joint 0.5-5 degrees both damping models, tri-stable NES 0.5 mm, Kresling
chains at 0.3 mm), seeds 0-2, and the `gmr demo` cases; the clean and the bad values that fixed
each threshold are quoted in its docstring.
"""

from itertools import pairwise

import numpy as np

from .._errors import GMRDataWarning as GMRDataWarning  # noqa: F401  (re-exported)
from .._errors import GMRInputError


#: Percentile of |x - mean| taken as a recording's vibration amplitude (robust to a few spikes).
AMPLITUDE_PERCENTILE = 99.9
#: two wells closer than this fraction of the smaller vibration amplitude are one well.
SAME_WELL_FRACTION = 0.5
#: fraction of samples in the middle quarter of a record's range below which it is bimodal.
SWING_GAP_FRACTION = 0.05
#: fraction (and least number) of samples in flat tops (runs of `CLIP_RUN` or more at
#: the extreme value) that makes a column clipped.
CLIP_FRACTION, CLIP_MIN_SAMPLES, CLIP_RUN = 0.005, 5, 3
#: an input-less record is driven if it builds up (rise over the noise floor before its
#: start) or does not die out (last window over its peak).
FREE_DECAY_RISE, FREE_DECAY_END = 1.5, 0.35
#: vibration amplitude over the distance to the nearest other equilibrium.
LARGE_AMPLITUDE_RATIO = 0.3
#: training R² below which a fit is reported.
MIN_R2 = 0.5
#: outer wells are looked for within this many data spans of the recorded range; an
#: escape barrier below this multiple of the energy differences inside the range is reported;
#: a force between the wells above this multiple of (local stiffness x distance) is a blow-up.
OUTER_SPANS, ESCAPE_RATIO, BLOWUP_RATIO = 1.0, 1.0, 10.0


def vibration_amplitude(x) -> float:
    """Amplitude of a record about its mean: the `AMPLITUDE_PERCENTILE` percentile of |x - mean|."""
    x = np.asarray(x, float)
    return float(np.percentile(np.abs(x - x.mean()), AMPLITUDE_PERCENTILE))


def vibration_range(x) -> tuple[float, float]:
    """(lo, hi): the 0.1 and 99.9 percentiles of x (the range a record covers, spikes aside)."""
    lo, hi = np.percentile(np.asarray(x, float), [100 - AMPLITUDE_PERCENTILE, AMPLITUDE_PERCENTILE])
    return float(lo), float(hi)


def _g(v) -> str:
    return f"{v:.4g}"


# --- refusals -------------------------------------------------------------------------------


def check_masses(names, masses) -> None:
    """Refusal: every recording that carries `masses` must carry the same ones
    (relative difference below 1e-6); the model has one mass per DOF, and taking the first
    file's silently would scale the other files' forces wrongly.

    `names`, `masses`: per recording, `masses` None where a file has none."""
    found = [(n, np.asarray(m, float).reshape(-1)) for n, m in zip(names, masses) if m is not None]
    for n, m in found[1:]:
        n0, m0 = found[0]
        if m.shape != m0.shape or not np.allclose(m, m0, rtol=1e-6, atol=0.0):
            raise GMRInputError(
                f"{n0} and {n} carry different masses ({m0.tolist()} and {m.tolist()}); one model has one "
                f"mass per DOF: fix the files, or pass the right masses (gmr fit --masses, reconstruct(masses=...))"
            )


def check_distinct_wells(dof: int, groups, means, amplitudes) -> None:
    """Refusal: two wells of one DOF whose equilibria (recording means) are closer
    than `SAME_WELL_FRACTION` (0.5) times the smaller of their vibration amplitudes are not
    two equilibria: each record sweeps through the other's mean (runs of one well, or records
    swinging across wells). Two such recordings give no global information, and treating them
    as two equilibria makes the Hermite solve divide by their tiny distance (bistable joint,
    a 1 and a 0.5 degree run of the same well: means 0.0002 apart, amplitudes 0.027 and
    0.034, ratio 0.008; the "model" F = 390 - 1204 x + 923 x^2 + 2028 x^3 for the truth
    -2244 x + 1755 x^3). Clean built-in data: ratio >= 17 (Kresling 3-cell chain, base cell).

    `groups`: per well, the names of its recordings; `means`: per well, its equilibrium;
    `amplitudes`: per well, the smallest amplitude of its recordings."""
    means, amps = np.asarray(means, float), np.asarray(amplitudes, float)
    order = np.argsort(means)
    for a, b in pairwise(order):
        gap = means[b] - means[a]
        if gap < SAME_WELL_FRACTION * min(amps[a], amps[b]):
            na, nb = ", ".join(groups[a]), ", ".join(groups[b])
            raise GMRInputError(
                f"DOF {dof}: {na} and {nb} do not give two distinct equilibria: their means x = {means[a]:.6g} and "
                f"{means[b]:.6g} are {_g(gap)} apart, less than half their vibration amplitude "
                f"{_g(min(amps[a], amps[b]))}, so they are runs around the same equilibrium (or records swinging "
                f"across wells); GMR needs a small-vibration recording around each of at least two distinct stable "
                f"equilibria: record around another equilibrium (runs of one well are then pooled), or drop one of "
                f"these files"
            )


# --- warnings on the data -------------------------------------------------------------------


def _flat_samples(at: np.ndarray, run: int) -> int:
    """Number of True samples of `at` that lie in runs of at least `run` consecutive ones."""
    edges = np.diff(np.concatenate([[0], at.astype(int), [0]]))
    lengths = np.nonzero(edges == -1)[0] - np.nonzero(edges == 1)[0]
    return int(lengths[lengths >= run].sum())


#: at least this share (and `CLIP_MIN_SAMPLES`) of the samples at the extreme value,
#: where no value just inside it repeats (`_at_a_rail`)
CLIP_RAIL_FRACTION = 1e-4


def _at_a_rail(col: np.ndarray, at: np.ndarray, tol: float) -> bool:
    """The samples `at` the column's extreme are a rail: at least `CLIP_MIN_SAMPLES` and `CLIP_RAIL_FRACTION`
    of them, while the value of the sample nearest the extreme inside it occurs at most twice or a fifth as
    often. A response that saturates briefly sits at the rail for a sample or two per peak (audit: an
    accelerometer clipped at its 99.9 % quantile, 52 samples in runs of 1-2, moved a barrier by 63 % unflagged);
    a noise-free periodic signal repeats its top sample every period but every other value as well, and a
    quantised one (an encoder) repeats every level."""
    n_top = int(at.sum())
    if n_top < max(CLIP_MIN_SAMPLES, CLIP_RAIL_FRACTION * col.size):
        return False
    inside = col[~at]
    if inside.size == 0:
        return False
    top = col[at][0]
    nearest = inside[np.argmin(np.abs(inside - top))]
    n_next = int(np.sum(np.abs(col - nearest) <= tol))
    return n_next <= max(2, n_top // 5)


def check_clipping(name: str, columns: dict) -> list[str]:
    """a measured column is clipped (saturated sensor or recorder) when at least
    `CLIP_FRACTION` (0.5 %) of its samples, and at least `CLIP_MIN_SAMPLES` (5), sit at its
    maximum or at its minimum (within 1e-9 of its range) in flat tops: runs of at least
    `CLIP_RUN` (3) consecutive samples. A smooth peak is sampled at most twice at its top
    value, so a noise-free periodic input (which repeats its top sample every period: 1 % of
    a 10 Hz sine at 1 kHz) is not flagged; a continuous signal with noise reaches its
    extreme once (clean built-in data: 1 sample in every column). A record clipped at its
    97th percentile: 3 %. Brief saturations (runs of 1-2 samples, a fast response sampled
    slowly) are found by their rail instead (`_at_a_rail`). Constant columns (a zero force
    column) are skipped.

    `columns`: label (e.g. "x0", "base_acc") -> 1-D array of measured samples."""
    out = []
    for label, col in columns.items():
        col = np.asarray(col, float)
        span = np.ptp(col)
        if span == 0:
            continue
        tol = 1e-9 * span
        need = max(CLIP_MIN_SAMPLES, CLIP_FRACTION * col.size)
        for side, value, at in (("maximum", col.max(), col >= col.max() - tol),
                                ("minimum", col.min(), col <= col.min() + tol)):
            count, how = _flat_samples(at, CLIP_RUN), "in flat tops"
            if count < need and _at_a_rail(col, at, tol):  # brief saturations: runs of 1-2 samples at one value
                count, how = int(at.sum()), "a sample or two at a time, while no value just inside it repeats"
                need = count
            if count >= need:
                out.append(
                    f"{name}: column {label} looks clipped: {count} samples ({100 * count / col.size:.1f} %) sit "
                    f"exactly at its {side} {_g(value)}, {how}; the sensor or the recorder probably "
                    f"saturated, and the fit takes the flat tops as real motion: re-record with more range, or cut "
                    f"the clipped parts"
                )
                break
    return out


def free_decay_violation(x, n_windows: int = 16) -> str | None:
    """Why a displacement record cannot be a free decay, or None. With r the RMS of x about its
    mean over `n_windows` consecutive windows, p the loudest window and j the first window
    reaching 20 % of it, an unforced (possibly tapped) structure

    - (A) is quiet before its start: every window before j stays within `FREE_DECAY_RISE`
      (1.5) times the quietest one (the noise floor of a pre-trigger): a tap or a release
      starts the motion at once, a drive builds it up;
    - (B) never gains energy after its peak: no window exceeds twice the quietest one between
      the peak and it (a second tap is an input too);
    - (C) decays: the last window is below `FREE_DECAY_END` (0.35) times the loudest.

    Simulated free decays of the joint and the NES (released, or tapped after a quiet
    second, 30 and 60 dB noise): A <= 1.0, B <= 1.22, C <= 0.22. Built-in base sweeps of the
    joint and the NES: A >= 1.72 or C >= 0.40 in every record (both in most); Kresling
    chains: at least one cell per record; a steady sine: C = 0.94. A sweep that is quiet
    until a sharp resonance and dies out within the record would pass as a free decay."""
    x = np.asarray(x, float)
    x = x - x.mean()
    r = np.array([np.sqrt(np.mean(w**2)) for w in np.array_split(x, n_windows)])
    if not r.max() > 0:
        return None
    floor, p = max(r.min(), np.finfo(float).tiny), int(np.argmax(r))
    j = int(np.argmax(r >= 0.2 * r[p]))
    if j > 0 and r[:j].max() > FREE_DECAY_RISE * floor:
        return f"its vibration builds up over {j} of {n_windows} windows before its peak"
    for k in range(p + 1, n_windows):
        if r[k] > 2.0 * r[p:k].min():
            return "its vibration grows again after its peak"
    if r[-1] > FREE_DECAY_END * r[p]:
        return f"its vibration does not die out (its last stretch still has {100 * r[-1] / r[p]:.0f} % of its peak RMS)"
    return None


def check_missing_input(name: str, x, has_input: bool) -> list[str]:
    """a recording without an input column (no `base_acc`, no `force`) must be a free
    decay (contracts: an input may be absent only then); warn when `free_decay_violation`
    finds that some DOF's motion is not one (it was driven, so the fit, which takes the force
    as zero, misses the input).

    `x`: (N, D) displacements."""
    if has_input:
        return []
    x = np.asarray(x, float).reshape(np.shape(x)[0], -1)
    for i in range(x.shape[1]):
        why = free_decay_violation(x[:, i])
        if why:
            return [
                f"{name}: no input column (base_acc or force), yet it is not a free decay ({why}"
                + (f", DOF {i}" if x.shape[1] > 1 else "") + "): the input seems missing, and the fit treats the "
                "record as unforced; add its base_acc or force column (an input may be absent only for a free decay)"
            ]
    return []


#: a measured v or a and the matching derivative of x (both through one Savitzky-Golay
#: filter) agree in scale within this factor, or are reported, where they correlate at least
#: `UNITS_MIN_CORR` (below it the noise hides the scale: no verdict).
UNITS_FACTOR, UNITS_MIN_CORR = 1.25, 0.9

#: a measured a that is the relative acceleration x'' (a simulation's state, a sensor on the base
#: subtracted), not the absolute one the equation of motion takes (a = x'' + base_acc): reported where the share
#: of the smoothed a - base_acc that x'' does not explain (1 - r^2) is this many times the share of a itself.
#: Built-in base-driven systems (both joints, NES, arch, magnet, Kresling-3; noise-free, 60 and 30 dB, seeds 0-1;
#: absolute a): at most 1.0 (equal where the base acceleration is 0); a Duffing double well with relative a in the
#: file (base 0.03-0.05 m/s^2 tones, 10 % vibrations): 32 (0.0255 against 0.0008), fitted with a negative viscous
#: term, a v|v| term and a degree-7 law, and no other warning on the columns. Also reported where a - base_acc does
#: not match x'' (the scale check would give a factor as the fix, or no verdict) and a itself does, better.
RELATIVE_A_RATIO = 10.0


def _scale_hint(s: float) -> str:
    k = np.log10(abs(s)) / 3.0
    g = np.log(abs(s)) / np.log(9.80665)
    hints = []
    if s < 0:
        hints.append("opposite sign")
    if abs(k - round(k)) < 0.05 and round(k) != 0:
        hints.append("a power of 1000, as with t in ms or x in mm where the others are in s and m")
    elif abs(g - round(g)) < 0.05 and round(g) != 0:
        hints.append("a power of g = 9.81, as with accelerations in g where x and t are in m and s")
    return "; ".join(hints)


#: a measured acceleration whose mean departs from what the motion allows by more than this share of its
#: RMS is reported (audit 8: +0.1 m/s^2, 0.077 of the RMS, on one well's a: restoring error 2.3 % against a band of
#: +-0.78 %, a barrier interval that excluded the truth; +0.5 m/s^2: 12 %; clean records of the audit 0.0003-0.0011)
OFFSET_SHARE = 0.01


def check_acceleration_offset(name: str, rec, topology) -> list[str]:
    """the mean of x'' over a record is (v(T) - v(0)) / T, near 0 for a structure vibrating about a well;
    a measured a - base_acc (per cell for a chain) whose mean departs from it by more than `OFFSET_SHARE` of its RMS
    holds an offset (an accelerometer's DC bias, gravity on a tilted sensor), which the fit takes as a constant
    force at that well, moving its restoring force. v(T) - v(0) from the measured v, else from x (Savitzky-Golay).
    Skipped: a derived a, an x integrated from a, a record without an input column."""
    from .._recordings._derivatives import differentiate

    info = rec.integration or {}
    if rec.a is None or "a" in rec.derived or info.get("from") == "a" or not rec.driven:
        return []
    x = np.asarray(rec.x, float)
    b = np.zeros(x.shape[0]) if rec.base_acc is None else np.asarray(rec.base_acc, float)
    rel = np.asarray(rec.a, float) - b[:, None]
    if topology.name == "chain":
        rel = np.diff(rel, axis=1, prepend=0.0)  # cell i: a_i - a_(i-1), the cell's x_i''
    if rec.v is not None and "v" not in rec.derived:
        v = np.asarray(rec.v, float)
    else:
        v = np.column_stack([differentiate(c, float(rec.dt), 1) if np.ptp(c) > 0 else np.zeros_like(c)
                             for c in x.T])
    allowed = (v[-1] - v[0]) / float(rec.t[-1] - rec.t[0])  # the mean of x'' the motion allows
    mean = rel.mean(axis=0)
    out = []
    for i in range(rel.shape[1]):
        spread = float(np.std(rel[:, i]))
        excess = float(mean[i] - allowed[i])
        if not spread > 0 or abs(excess) <= OFFSET_SHARE * spread:
            continue
        col = "a" if rel.shape[1] == 1 else f"a{i}"
        fix = (f"remove it (`gmr fit --columns {col}=<{col}'s column>{-excess:+.4g}`)" if topology.name != "chain" or i == 0
               else f"remove it at the accelerometer of mass {i} or {i - 1} (a cell's x'' is the difference of theirs)")
        out.append(f"{name}: the measured acceleration of DOF {i} holds an offset of {excess:.4g} ({100 * abs(excess) / spread:.2g} "
                   f"% of its RMS): a - base_acc is x'', whose mean over a record is the change of speed over its "
                   f"length ({float(allowed[i]):.3g} here), and it averages {float(mean[i]):.4g}; an accelerometer's DC bias or gravity on a tilted sensor. The "
                   f"fit takes it as a constant force at this well, which moves its restoring force and the wells' "
                   f"law between them: {fix}, or drop the a column (x is then differentiated)")
    return out


def check_units(name: str, rec, topology) -> list[str]:
    """the measured velocities and accelerations are the derivatives of the measured x
    in the same units. Per DOF, x' (x'') by Savitzky-Golay differentiation and the measured v (the
    relative acceleration from a: a minus the base acceleration, per cell for a chain), smoothed by
    the same filter (the window `auto_window` picks for x), are compared by the two least-squares
    scales <d, m>/<d, d> and <m, m>/<d, m>, which bracket the true one when both carry noise; a
    record whose scale lies outside `UNITS_FACTOR` (1.25) both ways, or is negative, at a
    correlation of at least `UNITS_MIN_CORR` (0.9), is reported with the factor (a time column in
    ms, x in mm, a in g: the fit would take the columns as consistent and put the factor into
    the damping or the restoring force). Skipped: a signal derived or integrated from another, and
    the accelerations of a record without an input column (its base acceleration is unknown).
    Built-in systems (both joints, NES, arch, magnet, 3- and 5-cell Kresling chains; 30 and 60 dB,
    seeds 0-1; 108 columns of v and of a): the noise sits in the derivative of x, so the first
    scale is attenuated and the second is not: v at correlation >= 0.93, scales 0.86-1.002; a at
    correlation >= 0.9 (101 columns), 0.81-1.006. A time column in ms gives 1e6 for a, 1e3 for v. Where a
    DOF's x has no measured derivative to compare (x only), the base-acceleration check compares it with base_acc (`_base_scale`)."""
    from .._recordings._derivatives import auto_window, differentiate

    x = np.asarray(rec.x, float)
    info = rec.integration or {}
    dt = float(rec.dt)
    windows = [auto_window(c, dt) if np.ptp(c) > 0 else None for c in x.T]
    pairs = []
    if rec.v is not None and "v" not in rec.derived and info.get("from") != "v":
        pairs.append(("v", 1, np.asarray(rec.v, float)))
    if rec.a is not None and "a" not in rec.derived and info.get("from") != "a" and rec.driven:
        b = np.zeros(x.shape[0]) if rec.base_acc is None else np.asarray(rec.base_acc, float)
        rel = np.asarray(rec.a, float) - b[:, None]
        as_given = np.asarray(rec.a, float)  # the other reading: a itself is x''
        if topology.name == "chain":
            rel = np.diff(rel, axis=1, prepend=0.0)  # cell i: a_i - a_(i-1), the cell's x_i''
            as_given = np.diff(as_given, axis=1, prepend=0.0)  # differs from `rel` in cell 0 only (checked there)
        if not np.any(b != 0):
            as_given = None  # no base acceleration: the two readings are one
        pairs.append(("a", 2, rel))
    out, scales = [], {}
    for key, order, meas in pairs:
        for i, w in enumerate(windows):
            if w is None or w > x.shape[0]:
                continue
            d = differentiate(x[:, i], dt, order, w)
            bracket = _scale_bracket(d, differentiate(meas[:, i], dt, 0, w))
            if bracket is None:
                continue
            r, lo, hi = bracket
            if (key == "a" and as_given is not None and not np.array_equal(as_given[:, i], meas[:, i])
                    and (msg := _relative_acceleration(name, i, d, as_given[:, i], bracket, dt, w,
                                                       topology.name == "chain"))):
                out.append(msg)
                continue
            if abs(r) < UNITS_MIN_CORR:
                if (key == "a" and rec.base_acc is not None and (topology.name != "chain" or x.shape[1] == 1)
                        and _reversed_accelerometer(d, meas[:, i] + 2 * b, dt, w)):
                    out.append(f"{name}: the measured acceleration of DOF {i} has the opposite sign: -a minus the "
                               f"base acceleration is the second derivative of its x, a minus it is not (correlation "
                               f"{abs(r):.3f}): an accelerometer mounted or wired reversed; flip it (e.g. --columns "
                               f"'a=-COLUMN'), or the fit takes the input as pushing the wrong way")
                continue
            if _same_scale(r, lo, hi):
                continue  # the bracket reaches the band about 1
            s = float(np.sign(r) * np.sqrt(abs(lo * hi)))
            what = "velocity" if key == "v" else "relative acceleration (a minus the base's)"
            deriv = "first" if order == 1 else "second"
            hint = _scale_hint(s)
            scales[(i, key)] = (s, len(out))
            out.append(
                f"{name}: the measured {what} of DOF {i} is {s:.4g} times the {deriv} derivative of its x "
                f"(correlation {abs(r):.3f}{'; ' + hint if hint else ''}): the columns' units or signs disagree, "
                f"and the fit takes them as consistent (the factor goes into the "
                f"{'damping' if key == 'v' else 'restoring and damping'} forces): fix the scale of t, x or {key} "
                f"(e.g. --columns '{key}=COLUMN*FACTOR')"
            )
    out = _time_unit(name, out, scales)
    if rec.base_acc is not None and info.get("from") is None and (topology.name != "chain" or x.shape[1] == 1):
        for i, w in enumerate(windows):
            if w is None or w > x.shape[0] or any(k[0] == i for k in scales):
                continue  # a DOF the scale check already reported is not reported twice
            msg = _base_scale(name, i, x[:, i], rec, dt, w)
            if msg:
                out.append(msg)
    return out


#: in m (x'' + base_acc) + F(x, v) = f, base_acc enters x'' with the factor -1 whatever the mass and the
#: forces. Its factor fitted from x (with x, its square and cube, x' and the force) is reported when its
#: `BASE_SIGMAS`-standard-error interval lies outside 1 / `BASE_FACTOR` .. `BASE_FACTOR` (or is positive).
#: Built-in systems (both joints, NES, arch, magnet; noise-free, 60 and 30 dB, seeds 0-1; 60 records): -0.946 ..
#: -1.230 (the magnet's far well, whose law the cubic does not follow), standard errors <= 0.07; t in ms gives
#: 1e-6, x in mm with base_acc in m/s^2 1e3, base_acc in g 9.81 (x only: nothing else compares the units).
#: No verdict where less than `BASE_UNIQUE` of base_acc's variance is not a combination of the other columns: under
#: one tone it is x and x' (arch single-tone records: 0.0002; the noise in x' then leaks into its factor, -6 .. -8 at
#: 30 dB); base sweeps of the built-in systems: 0.21 - 0.82.
BASE_FACTOR, BASE_SIGMAS, BASE_UNIQUE = 3.0, 3.0, 0.05


def _base_scale(name: str, i: int, x, rec, dt: float, w: int) -> str | None:
    """The message for DOF `i` (x its column, `w` the Savitzky-Golay window), or None."""
    from .._recordings._derivatives import differentiate

    d2, d1, xs = (differentiate(x, dt, k, w) for k in (2, 1, 0))
    b = differentiate(np.asarray(rec.base_acc, float), dt, 0, w)
    z = (xs - xs.mean()) / max(float(np.std(xs)), 1e-300)
    cols = [b, z, z ** 2, z ** 3, d1, np.ones_like(z)]
    if rec.force is not None:
        cols.append(differentiate(np.asarray(rec.force, float)[:, i], dt, 0, w))
    h = w // 2
    a, y = np.column_stack(cols)[h:x.shape[0] - h], d2[h:x.shape[0] - h]
    if y.size <= 2 * a.shape[1] or float(np.std(a[:, 0])) == 0.0:
        return None
    other = np.linalg.lstsq(a[:, 1:], a[:, 0], rcond=None)[0]
    e, bc = a[:, 0] - a[:, 1:] @ other, a[:, 0] - a[:, 0].mean()
    if float(e @ e) < BASE_UNIQUE * float(bc @ bc):
        return None  # the input is (nearly) a combination of x and x' (one tone): its factor is not identified
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    r = y - a @ coef
    try:
        var = np.linalg.inv(a.T @ a)[0, 0] * float(r @ r) / (y.size - a.shape[1])
    except np.linalg.LinAlgError:
        return None
    alpha, se = float(coef[0]), float(np.sqrt(max(var, 0.0)))
    outside = alpha - BASE_SIGMAS * se > -1 / BASE_FACTOR or alpha + BASE_SIGMAS * se < -BASE_FACTOR
    if not np.isfinite(alpha) or not outside:
        return None
    s = -alpha
    head = (f"{name}: the base acceleration enters the second derivative of DOF {i}'s x with the factor {alpha:.4g} "
            f"(+- {se:.2g}) where the equation of motion, x'' + base_acc = ..., gives -1")
    if s < 0:
        return (f"{head}: base_acc has the opposite sign (a base accelerometer mounted or wired reversed), and the fit "
                f"takes the input as pushing the wrong way; flip it (e.g. --columns 'base_acc=-COLUMN')")
    hint = _scale_hint(s)
    p = np.log10(s) / 2
    if s < 1 / BASE_FACTOR and abs(p - round(p)) < 0.05 and round(p) % 3 == 0:
        hint = (f"as with a time column in 1/{10.0 ** -round(p):.4g} of a second (ms for 1000) where x and base_acc "
                f"are per s")
    return (f"{head}{'; ' + hint if hint else ''}: t, x and base_acc are not in one set of units (t in s, x in m "
            f"and base_acc in m/s^2, or the header's units, 't [ms]', 'x0 [mm]', 'base_acc [g]'), and the fit takes "
            f"them as consistent; fix the scale of t, x or base_acc (e.g. --columns 'base_acc=COLUMN*FACTOR')")


def _scale_bracket(d, m):
    """(correlation, lo, hi) of a measured signal `m` against the derivative `d` of x: the two least-squares
    scales <d, m>/<d, d> and <m, m>/<d, m>, ordered by size, which bracket the true one when both carry noise;
    None where either is zero."""
    dd, dm, mm = float(d @ d), float(d @ m), float(m @ m)
    if dd <= 0 or mm <= 0:
        return None
    lo, hi = sorted((dm / dd, mm / dm), key=abs)
    return dm / np.sqrt(dd * mm), lo, hi


def _same_scale(r, lo, hi) -> bool:
    """The verdict of agreement: a positive correlation and a bracket that reaches the band
    1 / `UNITS_FACTOR` .. `UNITS_FACTOR`."""
    return r > 0 and abs(lo) <= UNITS_FACTOR and abs(hi) >= 1 / UNITS_FACTOR


def _matches(bracket) -> bool:
    """A reading whose `_scale_bracket` against x's derivative correlates at least `UNITS_MIN_CORR` and has
    the same scale (`_same_scale`): it is that derivative (rules 13c and the reversed accelerometer)."""
    return bracket is not None and bracket[0] >= UNITS_MIN_CORR and _same_scale(*bracket)


def _relative_acceleration(name: str, i: int, d, a, minus, dt, w, chain: bool) -> str | None:
    """the measured `a` (DOF i's column as given, no base acceleration subtracted) read as x'' matches
    the second derivative of x `d` (`_same_scale` at a correlation of at least `UNITS_MIN_CORR`) and explains it
    better than a - base_acc (`minus`: its `_scale_bracket`), either by `RELATIVE_A_RATIO` in the unexplained share
    1 - r^2 or where a - base_acc does not match (the scale check would report a scale, or give no verdict: at 40 dB the
    relative joint's a - base_acc read as 1.3-1.9 x'', and the fix it gave was a factor): the file holds the relative
    acceleration. None otherwise."""
    from .._recordings._derivatives import differentiate

    bracket = _scale_bracket(d, differentiate(a, dt, 0, w))
    if not _matches(bracket):
        return None
    alone, left = 1.0 - bracket[0] ** 2, 1.0 - minus[0] ** 2
    if not (left > RELATIVE_A_RATIO * alone or (not _matches(minus) and alone < left)):
        return None
    where = "every a column (each mass's)" if chain else "the a column"
    return (f"{name}: the measured acceleration of DOF {i} is the relative one, not the absolute one: the column "
            f"itself is the second derivative of its x (share unexplained {alone:.2g}), the column minus the base "
            f"acceleration is not ({left:.2g}); the fit takes a as the absolute acceleration of the mass, a = x'' + "
            f"base_acc (what an accelerometer on it gives), and would put the base's push into the restoring and "
            f"damping forces: add the base acceleration to {where} (`gmr fit --columns a=<a's column>+<base_acc's "
            f"column>`), or remove the a columns (x is then differentiated)")


def _reversed_accelerometer(d, flipped_rel, dt, w) -> bool:
    """-(a) - b (`flipped_rel` = a + b, negated here) matches x'' `d` (`_same_scale`) at a correlation of at least
    `UNITS_MIN_CORR` (audit: a reversed accelerometer, a = -(x'' + b), was reported as records leaving their
    wells: a - b does not correlate with x'' where b is large)."""
    from .._recordings._derivatives import differentiate

    return _matches(_scale_bracket(d, -differentiate(flipped_rel, dt, 0, w)))


def _time_unit(name: str, out: list[str], scales: dict) -> list[str]:
    """The messages, where v is s times x' and a is s^2 times x'' on a DOF (within `UNITS_FACTOR`), as one:
    the time column is in 1/s seconds (t in ms: v 1000 x, a 1e6 x), and v and a are right."""
    for (i, key), (sv, kv) in sorted(scales.items()):
        if key != "v" or (i, "a") not in scales or sv <= 0:
            continue
        sa, ka = scales[(i, "a")]
        if sa <= 0 or abs(np.log(sa) - 2.0 * np.log(sv)) > np.log(UNITS_FACTOR):
            continue
        factor = 10.0 ** round(np.log10(sv)) if abs(np.log10(sv) - round(np.log10(sv))) < 0.05 else sv
        out[kv] = (f"{name}: the measured velocity of DOF {i} is {sv:.4g} times the derivative of its x and the "
                   f"relative acceleration {sa:.4g} times its second derivative ({sv:.4g}^2 = {sv * sv:.4g}): the time "
                   f"column is in 1/{factor:.4g} of a second (ms for 1000), not in s, and the fit would take the "
                   f"rest as consistent; give t in seconds (e.g. --columns 't=t/{factor:.4g}', or the unit in the "
                   f"header, 't [ms]')")
        out[ka] = None
    return [m for m in out if m is not None]


def check_swings(dof: int, names, xs, labels, equilibria, stiffness) -> tuple[list[str], set]:
    """a recording should stay in its well. It is reported as swinging between wells
    when (a) its range (0.1-99.9 percentiles) covers the equilibrium of another well, or (b)
    the middle quarter of its range holds fewer than `SWING_GAP_FRACTION` (5 %) of its samples
    (bimodal: it sat in two places; a sine puts 16 % there, clean built-in records 34-79 %, the
    tri-stable NES driven across its wells at 3.5-4 mm 0.7-2.9 %), or (c) the local linear
    stiffness fitted at its mean is not positive (its mean is not a stable equilibrium; clean:
    >= 19.9, Kresling base cell; the NES at 3.5 mm: -62). GMR takes each record as a small vibration about one stable
    equilibrium: a swinging record smears the local fit and misplaces the equilibrium.

    `xs`: per recording, x of this DOF; `labels`: per recording, its well; `equilibria`,
    `stiffness`: per well. Returns the warnings and the indices of the recordings reported."""
    out, flagged = [], set()
    eq = np.asarray(equilibria, float)
    for k, (name, x) in enumerate(zip(names, xs)):
        x = np.asarray(x, float)
        lo, hi = vibration_range(x)
        why = []
        covered = [j for j in range(eq.size) if j != labels[k] and lo <= eq[j] <= hi]
        if covered:
            why.append(f"its x runs from {_g(lo)} to {_g(hi)}, across the equilibrium of another well "
                       f"(x = {', '.join(_g(eq[j]) for j in covered)})")
        mid = 0.5 * (lo + hi)
        if hi > lo and np.mean(np.abs(x - mid) < 0.125 * (hi - lo)) < SWING_GAP_FRACTION:
            why.append("the middle of its range is almost empty (it sat in two places)")
        if stiffness[labels[k]] <= 0:
            why.append(f"the stiffness fitted at its mean x = {_g(eq[labels[k]])} is {_g(stiffness[labels[k]])} "
                       f"(not positive: not a stable equilibrium)")
        if why:
            flagged.add(k)
            out.append(
                f"{name} (DOF {dof}) does not stay in one well: {'; '.join(why)}. GMR takes every recording as "
                f"a small vibration about one stable equilibrium: record with a smaller excitation, or cut the "
                f"record before it leaves its well"
            )
    return out, flagged


def check_amplitude(dof: int, names, xs, labels, equilibria, skip=()) -> list[str]:
    """GMR's local Taylor fits assume small vibrations; warn when a recording's
    amplitude exceeds `LARGE_AMPLITUDE_RATIO` (30 %) of the distance from its equilibrium to
    the nearest other one. Clean built-in data: <= 6.5 % (Kresling 3-cell chain, base cell);
    bistable joint with position-dependent damping swept at 30 degrees (still in its wells):
    35 %; the middle NES record at 4 mm: 92 %.

    `skip`: indices already reported by `check_swings`."""
    out = []
    eq = np.asarray(equilibria, float)
    for k, (name, x) in enumerate(zip(names, xs)):
        if k in skip or eq.size < 2:
            continue
        others = np.delete(eq, labels[k])
        dist = float(np.min(np.abs(others - eq[labels[k]])))
        amp = vibration_amplitude(x)
        if dist > 0 and amp > LARGE_AMPLITUDE_RATIO * dist:
            out.append(
                f"{name} (DOF {dof}): vibration amplitude {_g(amp)} is {100 * amp / dist:.0f} % of the distance "
                f"{_g(dist)} to the nearest other equilibrium; GMR assumes small vibrations (below "
                f"{100 * LARGE_AMPLITUDE_RATIO:.0f} %): the local fit may be biased; record with a smaller excitation"
            )
    return out


#: the vibration amplitudes of one DOF's wells differ by more than this factor: units? (`check_scales`)
SCALE_RATIO = 100.0


def check_scales(dof: int, names, xs, labels) -> list[str]:
    """one DOF's wells vibrate at amplitudes within a factor of a few of each other under one kind of
    excitation (the built-in systems: within 10, the Kresling cells' stiff deployed wells included); a factor
    above `SCALE_RATIO` (100) is more likely a file whose x is in other units (mm where the others are in m: 1000),
    which the fit would take as a well 1000 x as far and as soft (hand-made Duffing, one file in mm: 415 % restoring
    error, warned only as a poor fit)."""
    amps = {}
    for name, x, lab in zip(names, xs, labels):
        a = vibration_amplitude(x)
        if a > 0 and (lab not in amps or a > amps[lab][0]):
            amps[lab] = (a, name)
    if len(amps) < 2:
        return []
    (lo, lo_name), (hi, hi_name) = min(amps.values()), max(amps.values())
    ratio = hi / lo
    if ratio <= SCALE_RATIO:
        return []
    power = next((p for p in (1e3, 1e6) if abs(np.log10(ratio / p)) < np.log10(2.0)), None)
    hint = f" (about {power:g}: one file in mm or um where the other is in m?)" if power else ""
    return [f"DOF {dof}: {hi_name} vibrates {_g(ratio)} times as far as {lo_name}{hint}; the wells of one structure "
            f"under one kind of excitation differ by a few times at most: check that every file's x is in the same "
            f"units (a file in mm: its x times 1e-3, before the fit)"]


# --- warnings on the fits and the model -----------------------------------------------------


def check_fit_quality(training: dict) -> list[str]:
    """A training R² (model force against measured force, per recording and
    DOF) below `MIN_R2` (0.5) means the model does not explain its own data (wrong orders,
    a record that is not a small vibration, a missing input, or a global polynomial that
    blew up between the wells). Clean built-in data: R² >= 0.99999 everywhere; default
    orders on displacement-only 10 Hz sine records of the joint: -2e8 (2 noise seeds of 12;
    the blow-up check flags all 12); records swinging across the NES wells: -4e12.

    `training`: recording name -> {"r2": [per DOF], ...}; where a DOF's accelerations were estimated
    on a sweep, its "r2_in_band" (both forces low-passed alike, `training_scores`) is judged instead.
    """
    out = []
    for name, sc in training.items():
        band = sc.get("r2_in_band") or [None] * len(sc["r2"])
        for i, r2 in enumerate(sc["r2"]):
            what = "R²" if band[i] is None else "R² in the response's band"
            r2 = band[i] if band[i] is not None else r2
            if not np.isfinite(r2) or r2 < MIN_R2:
                out.append(
                    f"{name} (DOF {i}): the model explains its own training data poorly ({what} {_g(r2)}, "
                    f"below {MIN_R2}); do not trust it: lower the library orders (-r/-d), check that the "
                    f"record is a small vibration with its input recorded"
                )
    return out






def restoring_uncertainty(stiffness, covariance, x_lo: float, x_hi: float) -> float:
    """Two standard deviations of F_r(x) = sum_k c_k x^k under `covariance`, RMS over [x_lo, x_hi],
    relative to the RMS of F_r there (0 where undefined)."""
    k = np.asarray(stiffness, float)
    c = np.asarray(covariance, float)[: k.shape[0], : k.shape[0]]
    if not (np.all(np.isfinite(c)) and np.isfinite(x_lo) and np.isfinite(x_hi) and x_hi > x_lo):
        return 0.0
    phi = np.polynomial.polynomial.polyvander(np.linspace(x_lo, x_hi, 201), k.shape[0] - 1)
    f = phi @ k
    sd = np.sqrt(np.clip(np.einsum("ij,jk,ik->i", phi, c, phi), 0.0, None))
    return float(2.0 * np.linalg.norm(sd) / max(np.linalg.norm(f), 1e-300))


def _potential_and_roots(stiffness, centre, half):
    """The restoring polynomial in u = (x - centre) / half (well scaled), its real roots in x,
    the sign of F' there, and the potential U(x) = ∫ F dx as a callable."""
    s = np.trim_zeros(np.asarray(stiffness, float), "b")
    p = np.polynomial.Polynomial(s)
    q = p(np.polynomial.Polynomial([centre, half]))  # F(centre + half u)
    r = q.roots()
    keep = np.abs(r.imag) <= 1e-7 * (1.0 + np.abs(r.real))
    u = np.sort(r[keep].real)
    rising = q.deriv()(u) > 0
    return p, centre + half * u, rising, p.integ()


def _outward_sides(s, eq, roots):
    """Each side where the polynomial `s` (ascending, trimmed) turns outward for good (F -> -inf
    as x -> +inf, or +inf as x -> -inf): (side "+"/"-", sign, x_w the outermost equilibrium on
    that side, x_e the outermost real zero beyond it, x_w if none)."""
    k, lead = s.size - 1, s[-1]
    for side, wrong, sign in (("+", lead < 0, 1.0), ("-", (-1) ** k * lead > 0, -1.0)):
        if not wrong:
            continue
        x_w = float(np.max(eq)) if sign > 0 else float(np.min(eq))
        beyond = roots[roots * sign > x_w * sign]
        yield side, sign, x_w, float(beyond[-1] if sign > 0 else beyond[0]) if beyond.size else x_w


def escapes(stiffness, equilibria) -> list[dict]:
    """Where a restoring polynomial turns outward for good (F -> -inf as x -> +inf, or +inf as
    x -> -inf): per such side, the escape point x_e (its outermost zero beyond the outermost
    equilibrium) and the energy a motion in that outer well needs to get past it, the barrier
    max U over [x_w, x_e] - U(x_w) (U = int F dx). Ascending coefficients of x^k."""
    eq = np.asarray(equilibria, float)
    s = np.trim_zeros(np.asarray(stiffness, float), "b")
    if s.size < 2 or eq.size < 1 or not np.all(np.isfinite(s)):
        return []
    half = max(0.5 * float(np.ptp(eq)), 1e-300)
    p, roots, _, pot = _potential_and_roots(s, float(eq.mean()), half)
    out = []
    for side, _, x_w, x_e in _outward_sides(s, eq, roots):
        path = np.linspace(x_w, x_e, 401)
        out.append({"side": side, "x": x_e, "barrier": float(np.max(pot(path)) - pot(x_w))})
    return out


def check_global_shape(dof: int, stiffness, equilibria, amplitudes, local_stiffness) -> list[str]:
    """the global polynomial is measured near the recorded equilibria only; between and
    beyond them it is interpolated or extrapolated. Let [lo, hi] be the span of the recorded
    equilibria widened by their amplitudes, L its length. Warn when

    - (a) F has a stable zero (F = 0, F' > 0: a well) outside [lo, hi] but within
      `OUTER_SPANS` (1) L of it: a well no recording was made in, an artefact of the
      polynomial (clean data: none; the NES at seed 0 has one 42 L away, ignored);
    - (b) F has the wrong sign far out (F -> -inf as x -> +inf, i.e. a negative leading
      coefficient, or F -> +inf as x -> -inf), and the potential barrier from the outermost
      recorded equilibrium to the point where F turns outward is below `ESCAPE_RATIO` (1)
      times the potential differences inside [lo, hi]: a motion that leaves the recorded
      range runs away. The NES truth itself turns outward (-4.7e9 x^7); its reconstructions
      have barriers 9.6-10.7 times their interwell energies, the 5-cell Kresling cells >= 44;
      the NES driven across its wells (a 16th-degree law): 1e-9;
    - (c) between the outermost recorded equilibria |F| exceeds `BLOWUP_RATIO` (10) times the
      largest local stiffness times their distance: the interpolant blew up (clean data:
      <= 0.143, the NES; a true cubic gives about 0.1; the NES with one clipped record: 158;
      default orders on displacement-only 10 Hz sine records of the joint: about 500).

    `stiffness`: ascending coefficients of x^k; `equilibria`, `amplitudes`,
    `local_stiffness`: per well."""
    eq, amp = np.asarray(equilibria, float), np.asarray(amplitudes, float)
    s = np.trim_zeros(np.asarray(stiffness, float), "b")
    if s.size < 2 or eq.size < 2 or not np.all(np.isfinite(s)):
        return []
    lo, hi = float(np.min(eq - amp)), float(np.max(eq + amp))
    span = hi - lo
    if not span > 0:
        return []
    _, roots, rising, pot = _potential_and_roots(s, 0.5 * (lo + hi), 0.5 * span)
    out = []
    outer = [x for x, up in zip(roots, rising)
             if up and (lo - OUTER_SPANS * span <= x < lo or hi < x <= hi + OUTER_SPANS * span)]
    if outer:
        out.append(
            f"DOF {dof}: the model has a well (stable equilibrium) at x = {', '.join(_g(x) for x in outer)}, outside "
            f"the recorded range [{_g(lo)}, {_g(hi)}] where no recording was made: most likely an artefact of the "
            f"extrapolated polynomial (spurious outer well); lower the orders, or record around it if it is real"
        )
    grid = np.linspace(lo, hi, 401)
    depth = float(np.ptp(pot(grid)))
    k, lead = s.size - 1, s[-1]
    for side, sign, x_w, x_e in _outward_sides(s, eq, roots):
        barrier = float(pot(x_e) - pot(x_w))
        if barrier < ESCAPE_RATIO * depth:
            out.append(
                f"DOF {dof}: the restoring force turns outward beyond x = {_g(x_e)} (F -> {'-' if sign > 0 else '+'}inf "
                f"as x -> {side}inf; leading term {_g(lead)} x^{k}) and the energy barrier there ({_g(barrier)}) is "
                f"below the energy differences inside the recorded range ({_g(depth)}): a motion that leaves the "
                f"recorded range [{_g(lo)}, {_g(hi)}] runs away; lower the orders, or record further out"
            )
    b = blowup(s, eq, local_stiffness)
    if b is not None:
        out.append(
            f"DOF {dof}: between the recorded equilibria the restoring force reaches {_g(b['force'])} (at x = "
            f"{_g(b['x'])}), {b['ratio']:.3g} times the largest measured local stiffness "
            f"times their distance ({_g(b['scale'])}): the global polynomial blew up between the wells (local high-order "
            f"terms from records that cannot fix them, e.g. near-sinusoidal ones); lower the orders (-r), or excite "
            f"over a band of frequencies"
        )
    return out


def blowup(stiffness, equilibria, local_stiffness) -> dict | None:
    """Where |F| between the outermost equilibria exceeds `BLOWUP_RATIO` times the
    largest local stiffness (|F'| per well) times their distance, the peak (`force`, at `x`),
    `scale` and `ratio`; None where it does not (or cannot be judged)."""
    s, eq = np.asarray(stiffness, float), np.asarray(equilibria, float)
    if eq.size < 2 or not np.all(np.isfinite(s)):
        return None
    inner = np.linspace(eq.min(), eq.max(), 401)
    force = np.abs(np.polynomial.polynomial.polyval(inner, s))
    scale = float(np.max(np.abs(np.asarray(local_stiffness, float)))) * float(np.ptp(eq))
    if not (np.isfinite(scale) and scale > 0 and force.max() > BLOWUP_RATIO * scale):
        return None
    return {"force": float(force.max()), "x": float(inner[np.argmax(force)]), "scale": scale,
            "ratio": float(force.max() / scale)}


#: the data-preferred law differs from the chosen one by more than this many times the chosen
#: law's own 95 % half-band somewhere on the recorded range ("much more than its band").
CONFLICT_BAND_RATIO = 2.0


#: the data cannot decide the damping law where another set of velocity terms scores within this of the
#: chosen one (-2 log evidence; "very strong" evidence on Kass and Raftery's scale decides, as `_joint.CONFLICT`)
DAMPING_UNDECIDED = 10.0
#: ... and the two laws' damping forces part by more than this share below the model's speed bound
DAMPING_SPREAD = 0.25


#: `check_force_units`: a measured force that balances this many times more, or less, inertia than the masses and
#: units given imply is reported (a length unit off by 1000 gives 1000; the clean built-in records' margin:
#: results/units_check.md)
FORCE_UNITS_FACTOR = 3.0
#: `check_force_units`: the relative standard error of the balance's inertia factor above which the record cannot
#: tell (a steady single sine: its inertia and stiffness columns are collinear)
FORCE_UNITS_MAX_SE = 0.1
#: length-unit slips a factor is named by: factor of the kinematics over what the force implies -> what was written
UNIT_SLIPS = {1e3: ("mm", "m", "1e-3"), 1e-3: ("m", "mm", "1e3"), 1e2: ("cm", "m", "1e-2"), 1e-2: ("m", "cm", "1e2"),
              1e6: ("µm", "m", "1e-6"), 1e-6: ("m", "µm", "1e6"), 25.4: ("mm", "in", "1/25.4"),
              1 / 25.4: ("in", "mm", "25.4")}


def force_balance_factors(rec, topology, masses) -> list:
    """Per DOF, (mu, its standard error) of the regression force = mu (m a) + F(x, v) that `check_force_units`
    reads (None for a DOF without a force, or a record without one). `rec` a completed `Recording`."""
    from .._recordings._derivatives import band_edge

    if rec.force is None or not np.any(np.asarray(rec.force) != 0) or rec.a is None or rec.x is None:
        return []
    _, f = rec.inputs()
    a, x, v = (np.asarray(z, float) for z in (rec.a, rec.x, rec.v))
    n = x.shape[0]
    keep = slice(n // 20, n - n // 20)  # the ends: estimated derivatives and the low-pass's edges
    inertia = np.asarray(topology.carried(a * np.asarray(masses, float)[None, :]))
    load = np.asarray(topology.carried(np.asarray(f, float)))
    out = []
    for i in range(x.shape[1]):
        if not np.any(load[:, i] != 0):
            out.append(None)
            continue
        q = x[:, i] - np.mean(x[:, i])
        q = q / (np.std(q) or 1.0)
        w = v[:, i] / (np.std(v[:, i]) or 1.0)
        cols = np.column_stack([inertia[:, i], load[:, i]] + [q ** k for k in range(6)]
                               + [w, q * w, q ** 2 * w, w ** 3])
        # every column through one low-pass at 1.5 x the response's band edge: the equation holds filtered, and
        # the noise an estimated a carries far above the band (it would pull mu towards 0) is gone
        spec = np.fft.rfft(cols, axis=0)
        spec[np.fft.rfftfreq(n, float(rec.dt)) > 1.5 * band_edge(x[:, i], float(rec.dt))] = 0.0
        cols = np.fft.irfft(spec, n, axis=0)[keep]
        target, cols = cols[:, 1], np.delete(cols, 1, axis=1)
        norm = np.linalg.norm(cols, axis=0)
        if norm[0] == 0:
            out.append(None)
            continue
        norm = np.where(norm > 0, norm, 1.0)
        coef, *_ = np.linalg.lstsq(cols / norm, target, rcond=None)
        resid = target - (cols / norm) @ coef
        dof = max(len(resid) - cols.shape[1], 1)
        cov = np.linalg.pinv((cols / norm).T @ (cols / norm)) * (resid @ resid / dof)
        out.append((float(coef[0] / norm[0]), float(np.sqrt(max(cov[0, 0], 0.0)) / norm[0])))
    return out


def check_force_units(name: str, rec, topology, masses, factor: float = FORCE_UNITS_FACTOR) -> list[str]:
    """Whether a force-driven record's force balance holds in the units and masses given.

    The equation of motion m a + F(x, v) = force (chain: per cell, with the carried inertia and force) is
    regressed with the inertia's factor mu free: force = mu (m a) + F(x, v), F a polynomial in x (to x^5) and v
    (v, x v, x^2 v, v^3) about the record's mean. In consistent units mu = 1 whatever F is; lengths written in
    the wrong unit scale x, v and a by a factor s that F absorbs (a polynomial stays one) and the inertia does
    not: mu = 1/s. A record whose mu lies beyond `factor` (`FORCE_UNITS_FACTOR`) either way, with a standard error below
    `FORCE_UNITS_MAX_SE` of it, is reported with s and the slip it points to (`UNIT_SLIPS`). Skipped: records
    without a nonzero force (a base excitation scales with the kinematics: no unit shows) and DOFs whose record
    cannot separate inertia from stiffness.

    **Arguments:** `name`, the record's name; `rec`, a completed `Recording` (a filled); `topology`, the
    topology; `masses` (D,). **Returns:** one sentence per DOF reported."""
    out = []
    for i, fit in enumerate(force_balance_factors(rec, topology, masses)):
        if fit is None:
            continue
        mu, se = fit
        if mu <= 0 or se > FORCE_UNITS_MAX_SE * mu:
            continue
        s = 1.0 / mu
        if max(s, mu) < factor:
            continue
        slip = min(UNIT_SLIPS, key=lambda k: abs(np.log(s / k)))
        if abs(np.log(s / slip)) < np.log(1.5):
            real, said, scale = UNIT_SLIPS[slip]
            why = (f"lengths in {real} where the file says {said} (factor {slip:g}): label the columns "
                   f"'x [{real}]', or scale x, v, a by {scale} (--columns 'x=COLUMN*{scale}')")
        else:
            why = "check the units of x, v, a, the force and the masses"
        out.append(f"{name}: units: DOF {i}'s x, v, a are {s:.3g} times what its force and masses imply "
                   f"(force balance): {why}")
    return out


def unit_checks(recordings, *, masses=None, topology=None, factor: float = FORCE_UNITS_FACTOR) -> list[str]:
    """The units checks `reconstruct` runs, on recordings alone (before any fit): per recording, whether its
    measured v and a are the derivatives of its x in the same units, and, for a force-driven record, whether
    its force balance holds in the units and masses given (`check_force_units`: a length written in mm where
    the file says m is named with the factor 1000).

    **Arguments:**

    - `recordings`: `Recording`s, file paths or dicts of arrays (as `reconstruct` takes them).
    - `masses`, `topology`: as `reconstruct` (default: the recordings' masses, else 1; a chain for several DOFs).
    - `factor`: how far the force balance's inertia factor may be from 1, either way, before it is reported.

    **Returns:** the sentences, each naming the record, the problem and the fix (empty: consistent)."""
    from .._recordings._inputs import as_recordings
    from .._recordings._recording import validate
    from .._topology import as_topology

    recs = [validate(r, r.name) for r in as_recordings(recordings)]
    if not recs:
        return []
    d = recs[0].n_dof
    topo = as_topology(("chain" if d > 1 else "independent") if topology is None else topology)
    found = [r.masses for r in recs if r.masses is not None]
    m = np.asarray(masses if masses is not None else (found[0] if found else np.ones(d)), float).reshape(-1)
    out = []
    for r in recs:
        out += check_units(r.name, r, topo)
        done = r.complete(topo)
        out += check_force_units(r.name, done, topo, m, factor)
    return out
