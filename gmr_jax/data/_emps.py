"""The EMPS recordings: real measurements of an electro-mechanical positioning system.

Data of the EMPS nonlinear system-identification benchmark (A. Janot, M. Gautier, M. Brunot,
"Data Set and Reference Models of EMPS"); see `gmr_jax/data/emps/README.md` for the
attribution and the signals. One degree of freedom: the load position `qm` (m) and the motor
force `gtau * vir` (N), sampled at 1 kHz, recorded in closed loop (PD position controller).

Velocity and acceleration are not measured; they are derived from `qm` the way the
benchmark does it (its "bandpass filtering"): a zero-phase Butterworth low-pass (order 4,
cut-off 100 Hz = 5 x the 20 Hz position-loop bandwidth, `scipy.signal.filtfilt`) followed by
central differences. Optionally every channel (position, velocity, acceleration and force
alike) is then low-passed and decimated in parallel (the benchmark's "decimate" step,
`scipy.signal.decimate`, 8th-order Chebyshev I, zero phase), which removes the force ripples
the controller rejects. `compare_differentiation` in `studies/emps_study.py` compares the
choices: any cut-off from 60 to 200 Hz (or plain central differences, or a Savitzky-Golay
window of at most ~21 samples) gives the same estimates; longer windows or lower cut-offs
smear the bang-bang accelerations (M biased up, force error 2-15 x larger), and the
automatic Savitzky-Golay window (hundreds of samples, set by the slow trajectory) fails.
"""

from importlib import resources

import numpy as np

from .._errors import GMRInputError
from .._recordings._mapping import read_mat, squeeze
from .._recordings._recording import Recording, validate

FILES = {"estimation": "DATA_EMPS.mat", "validation": "DATA_EMPS_PULSES.mat"}
SAMPLE_TIME = 1e-3  # s, the dSPACE sampling period (1 kHz)

#: The benchmark's IDIM-LS reference estimates (description, section 3.4), in N, kg, s, m.
REFERENCE = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648}
#: Its asymmetric-friction estimates (description, section 4.2, Eq. 12, no offset).
REFERENCE_ASYMMETRIC = {"M": 95.1540, "Fv+": 166.7061, "Fc+": 20.1440, "Fv-": 240.4236,
                        "Fc-": 20.6277}
#: The benchmark's relative force errors of IDIM-LS (decimated data): direct and cross-test.
REFERENCE_RELATIVE_ERROR = {"estimation": 0.040834, "validation": 0.059824,
                            "estimation_asymmetric": 0.031117}

DEFAULT_CUTOFF_HZ = 100.0
DEFAULT_FILTER_ORDER = 4
BENCHMARK_DECIMATION = 10  # round(0.8 * 500 Hz / (2 * 20 Hz))


def _check_which(which: str) -> str:
    if which not in FILES:
        raise GMRInputError(
            f"load_emps: which={which!r}; choose 'estimation' (DATA_EMPS.mat) or "
            f"'validation' (DATA_EMPS_PULSES.mat)"
        )
    return which


def emps_raw(which: str = "estimation") -> dict:
    """The signals of one EMPS file, unprocessed except for flattening: `t`, `qm`, `qg`, `vir`
    (arrays, N,), `gtau`, `kp`, `kv` (floats), and `pulses_N` (validation file only).

    The file is found with `importlib.resources`, so this works from an installed wheel."""
    name = FILES[_check_which(which)]
    ref = resources.files("gmr_jax.data").joinpath("emps", name)
    with resources.as_file(ref) as path:
        mat = read_mat(path, name)
    return {key: float(v) if v.ndim == 0 else v.reshape(-1) for key, v in ((k, squeeze(a)) for k, a in mat.items())}


def lowpass_derivatives(
    x: np.ndarray,
    dt: float,
    cutoff_hz: float = DEFAULT_CUTOFF_HZ,
    order: int = DEFAULT_FILTER_ORDER,
):
    """(x_f, v, a): x low-passed by a zero-phase Butterworth filter (`filtfilt`, so the
    effective order is 2 x `order` and there is no lag), then differentiated twice by central
    differences (`np.gradient`; second order inside, one-sided at the two ends).

    `cutoff_hz=None` skips the filter (plain central differences)."""
    x = np.asarray(x, dtype=np.float64)
    if cutoff_hz is None:
        xf = x
    else:
        nyq = 0.5 / dt
        if not 0 < cutoff_hz < nyq:
            raise GMRInputError(f"cutoff_hz must lie in (0, {nyq:g}) Hz, got {cutoff_hz}")
        from scipy.signal import butter, filtfilt

        b, a = butter(order, cutoff_hz / nyq)
        xf = filtfilt(b, a, x, axis=0)
    v = np.gradient(xf, dt, axis=0)
    return xf, v, np.gradient(v, dt, axis=0)


def parallel_decimate(signals: dict, q: int) -> dict:
    """Low-pass and keep one sample in `q`, identically for every signal (zero-phase 8th-order
    Chebyshev I, cut-off 0.8 x the new Nyquist frequency, as MATLAB's `decimate`)."""
    if q == 1:
        return dict(signals)
    from scipy.signal import decimate as _sp_decimate

    return {k: _sp_decimate(np.asarray(s, float), q, ftype="iir", zero_phase=True)
            for k, s in signals.items()}


def load_emps(
    which: str = "estimation",
    *,
    cutoff_hz: float | None = DEFAULT_CUTOFF_HZ,
    decimate: int = 1,
    add_pulses: bool = False,
) -> Recording:
    """One EMPS run as a 1-DOF `Recording`.

    - `x` = `qm` (m); `force` = `gtau * vir` (N); `masses` unknown (None); `t` on the exact
      1 kHz grid (the files carry ~2e-8 s of storage jitter).
    - `v`, `a` derived from `qm` by `lowpass_derivatives` (Butterworth `cutoff_hz`, zero phase,
      then central differences) and listed in `derived`.
    - `decimate` > 1 applies `parallel_decimate` to x, v, a and force together (the benchmark
      uses 10: 100 Hz, 40 Hz pass band); with it `x` is the low-passed position. Caveat: the
      benchmark filters each regression column, so its Coulomb column is the decimated
      sgn(v) (a smooth step), not sgn of the decimated v; a fit that builds sgn(v) from this
      recording's `v` is worse (Coulomb model: 5.9 % instead of 4.0 % force error on the
      estimation run). `prepare` in `studies/emps_study.py` does the column-wise filtering.
    - `add_pulses` adds the validation file's `pulses_N` to the force. Off by default: the
      pulses are already inside `vir` (each pulse edge makes `gtau * vir` jump by ~5 V x gtau
      in one sample, and a free coefficient on `pulses_N` fits to ~0), so adding them counts
      them twice.

    **Arguments:** `which`: "estimation" (DATA_EMPS.mat) or "validation" (DATA_EMPS_PULSES.mat).
    """
    raw = emps_raw(which)
    n = raw["qm"].shape[0]
    dt = SAMPLE_TIME
    t = np.arange(n) * dt
    force = raw["gtau"] * raw["vir"]
    if add_pulses:
        if "pulses_N" not in raw:
            raise GMRInputError("load_emps: add_pulses=True needs the validation run")
        force = force + raw["pulses_N"]
    _, v, a = lowpass_derivatives(raw["qm"], dt, cutoff_hz)
    x = raw["qm"]
    decimate = int(decimate)
    if decimate < 1:
        raise GMRInputError(f"load_emps: decimate must be a positive integer, got {decimate}")
    if decimate > 1:
        sig = parallel_decimate({"x": x, "v": v, "a": a, "force": force}, decimate)
        x, v, a, force = sig["x"], sig["v"], sig["a"], sig["force"]
        t = np.arange(x.shape[0]) * (dt * decimate)
    rec = Recording(
        t=t, x=x[:, None], v=v[:, None], a=a[:, None], force=force[:, None],
        name=f"emps_{which}", derived=("v", "a"),
    )
    return validate(rec, f"EMPS {which}")
