"""A sweep's points integrated by a C kernel generated from the model ("native" batching, CPU).

The algorithm is the lanes one (`_lanes`): the same Runge-Kutta pair and tableau (diffrax's
Tsit5, Dopri5 or Dopri8), stop at the switch-off time, divergence box and result codes, with an
integral controller of its own (diffrax's `PIDController` with `pcoeff = 0, icoeff = 1`, except
that an accepted step may also shrink): a point's step count is within a few per cent of the
lanes path's and its final state well inside the tolerance. What differs is where it runs. XLA:CPU runs each stage of
a lanes step as separate vectorised loops over the lanes, and the state goes through memory
between them (`results/README.md`, issue 17); here one C function does whole step attempts
for a group of `LANES` points held in small arrays that stay in L1: every stage, the error norm
and the step-size decision are loops over the lanes that the C compiler vectorises (AVX2 or
AVX-512 where the machine has it: the kernel is built with `-march=native`), and a lane
whose point is done takes the next point of a queue that all threads share (one atomic
counter), so the threads stay busy until the grid is done.

The right-hand side is generated from the model's structure: each DOF's stiffness and
position-damping polynomials up to their highest nonzero degree (Horner), its nonzero
velocity-damping terms, the chain or independent topology and the tip or base load. The
coefficient values, masses, grid, tolerances and box are arguments, so new coefficients,
tolerances or grids reuse the same kernel; a new structure builds a new one (0.7-1.5 s with gcc
for 3-10 cells), kept on disk under the compilation cache folder, keyed by its source, the compiler and
the machine's CPU flags.

Used by `basin_map` when asked for (`SweepSettings(batching="native")`), on a CPU, for a
`GlobalModel` on a chain or independent DOFs in float64, in one process, when a C compiler is
found (`$CC`, then cc, gcc, clang); `GMR_NATIVE=0` turns it off. The default is the lanes path.
"""

import ctypes
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from .._model._model import GlobalModel
from .._solution import RESULTS
from .._topology import Chain, Independent
from ._lanes import _COS_TAYLOR, _ORDER, FACTOR_MAX, FACTOR_MIN, SAFETY, _tableau, solver_name

# points per group: two AVX-512 registers of float64 (four AVX2 ones). Measured on the 2-core
# AVX-512 machine, 1e4 points, 3 / 10 cells: 8 lanes 0.059 / 0.168 s, 16 lanes 0.058 / 0.163 s,
# 16 lanes with 512-bit vectors 0.053 / 0.142 s, 4 lanes 0.072 / 0.180 s
LANES = 16
# IEEE arithmetic (no -ffast-math): only errno and traps are given up, and a * b + c may fuse
_X86 = platform.machine().lower() in ("x86_64", "amd64", "i686", "i386")
FLAGS = ("-O3", "-march=native", *(("-mprefer-vector-width=512",) if _X86 else ()), "-fno-math-errno",
         "-fno-trapping-math", "-ffp-contract=fast", "-shared", "-fPIC")
PORTABLE_FLAGS = ("-O3", "-fno-math-errno", "-fno-trapping-math", "-shared", "-fPIC")
_lock = threading.Lock()
_loaded: dict = {}  # key -> loaded library, or the RuntimeError of its failed build (not retried)
BUILD_SECONDS = [0.0]  # C compile time of this process (the command line reports it with XLA's)


def _r(v: float) -> str:
    return repr(float(v))


def disabled() -> bool:
    """`GMR_NATIVE=0` (or false, no, off) turns the native kernel off."""
    return os.environ.get("GMR_NATIVE", "1").strip().lower() in ("0", "false", "no", "off")


def compiler() -> str | None:
    """The C compiler the native kernel is built with ($CC, cc, gcc, clang), None if there is
    none or `GMR_NATIVE=0`."""
    if disabled():
        return None
    for name in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def supports(model, settings) -> bool:
    """Whether the native kernel integrates this model under these settings (float64, a
    `GlobalModel` on a chain or independent DOFs; the explicit pairs Tsit5, Dopri5, Dopri8)."""
    return (isinstance(model, GlobalModel) and isinstance(model.topology, (Chain, Independent))
            and settings.precision == "float64" and solver_name(settings.solver) is not None
            and settings.load in ("tip", "base"))


def _structure(model) -> dict:
    """What the generated source depends on (not the coefficient values)."""
    k = np.asarray(model.stiffness, float)
    c = np.asarray(model.position_damping, float)
    b = np.asarray(model.velocity_damping, float)

    def degree(row):
        nz = np.nonzero(row)[0]
        return int(nz[-1]) if nz.size else -1

    return dict(d=int(k.shape[0]), chain=isinstance(model.topology, Chain), nk=int(k.shape[1]),
                nb=int(b.shape[1]), nc=int(c.shape[1]), kdeg=[degree(r) for r in k],
                cdeg=[degree(r) for r in c], bterms=[np.nonzero(r)[0].tolist() for r in b],
                sign_eps=float(model.sign_eps))


def _field_lines(s: dict, load: str, t: str, y: str, out: str) -> list[str]:
    """C statements (inside the loop over lanes `l`) writing dy/dt of the state read by
    `y(j)` at time `t` into `out(j)`, for one lane: Eq. (25) half-sine on the tip or base."""
    d = s["d"]
    lines = [f"{{ double th = {t} <= TOFF[l] ? 6.283185307179586 * F[l] * {t} : 0.0;",
             "  double u = (th < 0.0 ? 0.0 : (th > 3.141592653589793 ? 3.141592653589793 : th)) - 1.5707963267948966;",
             "  double u2 = u * u, sn = " + _r(_COS_TAYLOR[0]) + ";"]
    for coef in _COS_TAYLOR[1:]:
        lines.append(f"  sn = sn * u2 + {_r(coef)};")
    lines.append(f"  double p = {t} <= TOFF[l] ? AMP[l] * sn : 0.0;")
    for i in range(d):
        x, v = y(i), y(d + i)
        lines.append(f"  double x{i} = {x}, v{i} = {v};")
        kd = s["kdeg"][i]
        fk = "0.0"
        if kd >= 0:
            fk = f"K[{i * s['nk'] + kd}]"
            for k in range(kd - 1, -1, -1):
                fk = f"({fk} * x{i} + K[{i * s['nk'] + k}])"
        terms = [fk]
        cd = s["cdeg"][i]
        if cd >= 0:
            fc = f"C[{i * s['nc'] + cd}]"
            for k in range(cd - 1, -1, -1):
                fc = f"({fc} * x{i} + C[{i * s['nc'] + k}])"
            terms.append(f"{fc} * v{i}")
        if s["bterms"][i]:
            eps = s["sign_eps"]
            sg = (f"(FLAG(v{i} > 0.0) - FLAG(v{i} < 0.0))" if eps == 0.0 else f"tanh(v{i} / {_r(eps)})")
            lines.append(f"  double s{i} = {sg}, av{i} = fabs(v{i});")
            for j in s["bterms"][i]:
                if j % 2 == 1 and eps == 0.0:  # sgn(v)|v|^j = v^j
                    terms.append(f"B[{i * s['nb'] + j}] * " + " * ".join([f"v{i}"] * j))
                else:
                    terms.append(f"B[{i * s['nb'] + j}] * s{i}" + "".join(f" * av{i}" for _ in range(j)))
        lines.append(f"  double f{i} = " + " + ".join(terms) + ";")
    tip = "p" if load == "tip" else "0.0"
    base = "p" if load == "base" else "0.0"
    for i in range(d):
        ld = tip if i == d - 1 else "0.0"
        if s["chain"]:
            nxt = f" + f{i + 1}" if i < d - 1 else ""
            lines.append(f"  double a{i} = ({ld} - f{i}{nxt}) / M[{i}];")
        else:
            lines.append(f"  double a{i} = ({ld} - f{i}) / M[{i}] - {base};")
    for i in range(d):
        lines.append(f"  {out(i)} = v{i};")
        if s["chain"]:
            prev = base if i == 0 else f"a{i - 1}"
            lines.append(f"  {out(d + i)} = a{i} - {prev};")
        else:
            lines.append(f"  {out(d + i)} = a{i};")
    lines.append("}")
    return lines


def kernel_source(s: dict, load: str, solver: str, codes: dict) -> str:
    """C source of `gmr_sweep` for a model structure `s` (`_structure`): the lanes algorithm
    (`_lanes.lanes_final_states`) for `LANES` points at a time. Every per-lane quantity is a
    double (flags 0.0 / 1.0, indices and counts exact below 2^53), so that each loop over the
    lanes has one element type and the compiler vectorises it without a mask conversion."""
    d = s["d"]
    n2 = 2 * d
    c, a, b_sol, b_err, fsal = _tableau(solver)
    S = len(c)
    q = _ORDER[solver]
    cd = {k: f"{float(v)!r}" for k, v in codes.items()}
    o = [f"""#include <math.h>
#include <stdint.h>
#define L {LANES}
#define N2 {n2}
#define S {S}
#define FLAG(x) ((x) ? 1.0 : 0.0)
#define LANE _Pragma("GCC ivdep") for (int l = 0; l < L; l++)

int gmr_sweep(long n, const double* fs, const double* amps, const double* x0, const double* K,
              const double* B, const double* C, const double* M, const double* lo, const double* hi,
              double rtol, double atol, double settle, double dt0, double max_steps, long* next,
              double* x1, double* v1, int32_t* code, int32_t* steps) {{
  double Y[N2][L], KS[S][N2][L], YN[N2][L], KSTART[N2];
  double T[L], H[L], F[L], AMP[L], TOFF[L], T1[L], HH[L], STOP[L], NORM[L], FAC[L];
  double IDX[L], FIN[L], CL[L], STEPS[L], CODE[L];
  LANE {{ F[l] = 1.0; AMP[l] = 0.0; TOFF[l] = 1.0; T[l] = 0.0; H[l] = 0.0; T1[l] = 0.0; STEPS[l] = 0.0;
          CODE[l] = {cd['simulation_failed']}; IDX[l] = -1.0; FIN[l] = 1.0;
          for (int j = 0; j < N2; j++) Y[j][l] = j < {d} ? x0[j] : 0.0; }}
  /* the derivative at the start (rest in x0, load sin(0) = 0): the same for every point */
  {{ int l = 0;"""]
    o += ["    " + ln for ln in _field_lines(s, load, "0.0", lambda j: f"Y[{j}][l]", lambda j: f"KSTART[{j}]")]
    o.append(f"""  }}
  long running = 0;
  /* a free lane takes the next point of the queue that every thread shares */
#define REFILL(l) do {{ \
    long i_ = __atomic_fetch_add(next, 1, __ATOMIC_RELAXED); \
    if (i_ < n) {{ \
      IDX[l] = (double)i_; F[l] = fs[i_]; AMP[l] = amps[i_]; TOFF[l] = 0.5 / fs[i_]; \
      T1[l] = TOFF[l] + settle; T[l] = 0.0; STEPS[l] = 0.0; FIN[l] = 0.0; \
      H[l] = isnan(dt0) ? 1e-2 * (TOFF[l] < 1.0 ? TOFF[l] : 1.0) : dt0; \
      for (int j_ = 0; j_ < N2; j_++) {{ Y[j_][l] = j_ < {d} ? x0[j_] : 0.0; KS[0][j_][l] = KSTART[j_]; }} \
      running++; \
    }} else {{ IDX[l] = -1.0; FIN[l] = 1.0; }} \
  }} while (0)
  for (int l = 0; l < L; l++) REFILL(l);
  while (running > 0) {{
    /* the step: up to the lane's next stop (its switch-off time, then its t1) */
    LANE {{
      double t = T[l], hp = H[l];
      double stop = t < TOFF[l] ? TOFF[l] : T1[l];
      double clipped = FLAG(t + hp >= stop);
      HH[l] = clipped != 0.0 ? stop - t : hp;
      CL[l] = clipped; STOP[l] = stop;
    }}""")
    for i in range(1, S):
        o.append("    LANE {")
        o.append("      double h = HH[l], t = T[l];")
        for j in range(n2):
            acc = " + ".join(f"{_r(cj)} * KS[{m}][{j}][l]" for m, cj in enumerate(a[i - 1]) if cj != 0.0)
            o.append(f"      double z{j} = Y[{j}][l]" + (f" + h * ({acc})" if acc else "") + ";")
        # a stage at the stop itself belongs to the piece before it (the load's own value there)
        ti = "(CL[l] != 0.0 ? STOP[l] : t + h)" if c[i] == 1.0 else f"(t + {_r(c[i])} * h)"
        o.append(f"      double ti = {ti};")
        o += ["      " + ln for ln in _field_lines(s, load, "ti", lambda j: f"z{j}", lambda j, i=i: f"KS[{i}][{j}][l]")]
        o.append("    }")
    o.append("    LANE {")
    o.append("      double h = HH[l], acc = 0.0;")
    for j in range(n2):
        sol = " + ".join(f"{_r(bj)} * KS[{m}][{j}][l]" for m, bj in enumerate(b_sol) if bj != 0.0)
        err = " + ".join(f"{_r(ej)} * KS[{m}][{j}][l]" for m, ej in enumerate(b_err) if ej != 0.0)
        o.append(f"      {{ double y = Y[{j}][l], yn = y + h * ({sol}); YN[{j}][l] = yn;")
        o.append(f"        double e = h * ({err}), ay = fabs(y), ayn = fabs(yn);")
        o.append("        double r = e / (atol + rtol * (ay > ayn ? ay : ayn)); acc += r * r; }")
    o.append(f"      double nm = sqrt(acc / {n2}.0);")
    o.append("      NORM[l] = nm < INFINITY ? nm : INFINITY;  /* NaN -> inf */")
    o.append("    }")
    # libm's pow is not vectorised without -ffast-math: a loop of its own
    o.append(f"    for (int l = 0; l < L; l++) FAC[l] = NORM[l] == 0.0 ? {_r(FACTOR_MAX)} : "
             f"{_r(SAFETY)} * pow(NORM[l], {_r(-1.0 / q)});")
    if not fsal:  # the next first stage at (t + h, y_new): a stage of its own
        o.append("    double KN[N2][L];")
        o.append("    LANE {")
        o.append("      double tn = T[l] + HH[l];")
        o += ["      " + ln for ln in _field_lines(s, load, "tn", lambda j: f"YN[{j}][l]", lambda j: f"KN[{j}][l]")]
        o.append("    }")
    knew = (lambda j: f"KS[{S - 1}][{j}][l]") if fsal else (lambda j: f"KN[{j}][l]")
    o.append(f"""    LANE {{
      double active = FLAG(IDX[l] >= 0.0) * FLAG(FIN[l] == 0.0);
      double h = HH[l], hp = H[l], t = T[l], nm = NORM[l];
      double accept = active * FLAG(nm <= 1.0);
      double fac = FAC[l], top = accept != 0.0 ? {_r(FACTOR_MAX)} : {_r(SAFETY)};
      fac = fac < {_r(FACTOR_MIN)} ? {_r(FACTOR_MIN)} : (fac > top ? top : fac);
      double hn = h * fac;
      /* a step cut short by a stop does not shrink the next one */
      hn = accept * CL[l] * FLAG(hp > hn) != 0.0 ? hp : hn;
      double tn = accept != 0.0 ? (CL[l] != 0.0 ? STOP[l] : t + h) : t;
      double left = 0.0, fin = 1.0;""")
    for j in range(n2):
        o.append(f"      {{ double y = accept != 0.0 ? YN[{j}][l] : Y[{j}][l]; Y[{j}][l] = y; "
                 f"KS[0][{j}][l] = accept != 0.0 ? {knew(j)} : KS[0][{j}][l]; fin *= FLAG(y - y == 0.0);"
                 + (f" left += FLAG(y < lo[{j}]) + FLAG(y > hi[{j}]);" if j < d else "") + " }")
    o.append(f"""      double st = STEPS[l] + active;
      double bad = FLAG(fin == 0.0) + FLAG(t + hn <= t);
      double reached = FLAG(tn >= T1[l]);
      double cd = left != 0.0 ? {cd['diverged']} : (bad != 0.0 ? {cd['simulation_failed']} :
                  (reached != 0.0 ? {cd['successful']} : {cd['max_steps_reached']}));
      double done = active * FLAG(left + bad + reached + FLAG(st >= max_steps) != 0.0);
      T[l] = active != 0.0 ? tn : t; H[l] = active != 0.0 ? hn : hp; STEPS[l] = st;
      CODE[l] = done != 0.0 ? cd : CODE[l]; FIN[l] = FLAG(FIN[l] + done != 0.0);
    }}
    /* finished points write their answer, and their lanes take the next points */
    for (int l = 0; l < L; l++) {{
      if (FIN[l] != 0.0 && IDX[l] >= 0.0) {{
        long i_ = (long)IDX[l];
        for (int j = 0; j < {d}; j++) {{ x1[i_ * {d} + j] = Y[j][l]; v1[i_ * {d} + j] = Y[{d} + j][l]; }}
        code[i_] = (int32_t)CODE[l]; steps[i_] = (int32_t)STEPS[l];
        running--;
        REFILL(l);
      }}
    }}
  }}
  return 0;
}}

/* dy/dt of n states (n x N2, row-major) at times t: the kernel's right-hand side on its own (tests) */
void gmr_field(long n, const double* t, const double* y, const double* F, const double* AMP, const double* TOFF,
               const double* K, const double* B, const double* C, const double* M, double* out) {{
  for (long l = 0; l < n; l++)""")
    o += ["  " + ln for ln in _field_lines(s, load, "t[l]", lambda j: f"y[l * N2 + {j}]", lambda j: f"out[l * N2 + {j}]")]
    o.append("}")
    return "\n".join(o)


def _cpu_tag() -> str:
    """The machine's CPU flags (a kernel built with -march=native runs on this kind of CPU only)."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith(("flags", "Features")):
                    return line
    except OSError:
        pass
    return platform.processor() + platform.machine()


def _cache_dir() -> Path:
    """`$GMR_CACHE_DIR/gmr_native` (default `~/.cache/gmr_jax/xla/gmr_native`), or a folder of
    the system's temporary directory when the cache is off."""
    from .._config import default_cache_dir

    base = default_cache_dir()
    if base is None:
        return Path(tempfile.gettempdir()) / f"gmr_native_{os.getuid() if hasattr(os, 'getuid') else 0}"
    return Path(base) / "gmr_native"


def _compile(cc: str, flags: tuple, source: str, lib_path: Path) -> str | None:
    """Compile `source` to `lib_path` (atomically: a concurrent process sees all or nothing);
    the compiler's message on failure, None on success."""
    with tempfile.TemporaryDirectory(dir=lib_path.parent) as tmp:
        src = Path(tmp) / "sweep.c"
        src.write_text(source)
        out = Path(tmp) / "sweep.so"
        t0 = time.perf_counter()
        try:
            p = subprocess.run([cc, *flags, "-o", str(out), str(src), "-lm"], capture_output=True, text=True,
                               timeout=300)
        except (OSError, subprocess.SubprocessError) as err:
            return f"{cc} did not run: {err}"
        finally:
            BUILD_SECONDS[0] += time.perf_counter() - t0
        if p.returncode != 0:
            return f"{cc} {' '.join(flags)} failed: {p.stderr[-1500:]}"
        os.replace(out, lib_path)
    return None


def build(source: str) -> ctypes.CDLL:
    """The library of `source` (`gmr_sweep`, `gmr_field`), compiled once per source, compiler,
    flags and CPU (kept on disk, `_cache_dir`) and loaded once per process: with the tuned flags
    (`FLAGS`), else the portable ones (`PORTABLE_FLAGS`, a compiler that does not take
    `-march=native`). A failed compile is a `RuntimeError` carrying the compiler's message."""
    cc = compiler()
    if cc is None:
        raise RuntimeError("no C compiler")
    key = hashlib.sha256("\0".join([source, cc, _cpu_tag()]).encode()).hexdigest()[:24]
    with _lock:
        if key in _loaded:
            if isinstance(_loaded[key], Exception):
                raise _loaded[key]
            return _loaded[key]
        folder = _cache_dir()
        folder.mkdir(parents=True, exist_ok=True)
        errors = []
        for flags in (FLAGS, PORTABLE_FLAGS):
            lib_path = folder / f"sweep_{key}_{hashlib.sha256(' '.join(flags).encode()).hexdigest()[:8]}.so"
            if lib_path.exists() or (err := _compile(cc, flags, source, lib_path)) is None:
                break
            errors.append(err)
        else:
            _loaded[key] = RuntimeError("\n".join(errors))
            raise _loaded[key]
        lib = ctypes.CDLL(str(lib_path))
        dp = ctypes.POINTER(ctypes.c_double)
        lib.gmr_field.argtypes = [ctypes.c_long] + [dp] * 10
        lib.gmr_field.restype = None
        lib.gmr_sweep.argtypes = [ctypes.c_long, dp, dp, dp, dp, dp, dp, dp, dp, dp, ctypes.c_double,
                                  ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double,
                                  ctypes.POINTER(ctypes.c_long), dp, dp, ctypes.POINTER(ctypes.c_int32),
                                  ctypes.POINTER(ctypes.c_int32)]
        lib.gmr_sweep.restype = ctypes.c_int
        _loaded[key] = lib
        return lib


def _codes() -> dict:
    return {k: int(getattr(RESULTS, k)._value) for k in ("successful", "diverged", "max_steps_reached",
                                                          "simulation_failed")}


_by_structure: dict = {}  # (structure, load, pair) -> library: the source is not regenerated per call


def kernel(model, settings) -> ctypes.CDLL:
    """The built kernel for this model's structure, load and Runge-Kutta pair (`build`)."""
    s = _structure(model)
    pair = solver_name(settings.solver)
    key = repr((s, settings.load, pair, compiler()))
    if key not in _by_structure:
        _by_structure[key] = build(kernel_source(s, settings.load, pair, _codes()))
    return _by_structure[key]


def threads() -> int:
    """The CPUs this process may use (the native sweep's threads)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def native_final_states(model, settings, x0, fs, amps, centre, span, n_threads: int | None = None):
    """Final states of N half-sine actuations (fs[k], amps[k]) by the generated kernel, on
    `n_threads` threads (default: `threads()`, the CPUs this process may use). Same returns as
    `lanes_final_states`: `x1`, `v1` (N, dof), `code` (N,), `steps` (N,), NumPy."""
    fn = kernel(model, settings).gmr_sweep
    d = int(np.shape(model.stiffness)[0])
    codes = _codes()
    f64 = lambda a: np.ascontiguousarray(np.asarray(a, dtype=np.float64))  # noqa: E731
    fs, amps, x0 = f64(fs).ravel(), f64(amps).ravel(), f64(x0)
    K, B, C, M = (f64(model.stiffness), f64(model.velocity_damping), f64(model.position_damping),
                  f64(model.masses))
    box = float(settings.box_spans)
    centre, span = f64(centre), f64(span)
    lo, hi = f64(centre - box * span), f64(centre + box * span)
    n = fs.size
    x1, v1 = np.zeros((n, d)), np.zeros((n, d))
    code = np.full(n, codes["simulation_failed"], np.int32)
    steps = np.zeros(n, np.int32)
    counter = (ctypes.c_long * 1)(0)
    integ = settings.integrator
    dt0 = float("nan") if integ.dt0 is None else float(integ.dt0)
    dp = lambda a: a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))  # noqa: E731
    args = (ctypes.c_long(n), dp(fs), dp(amps), dp(x0), dp(K), dp(B), dp(C), dp(M), dp(lo), dp(hi),
            float(integ.rtol), float(integ.atol), float(settings.settle_time), dt0, float(integ.max_steps), counter,
            dp(x1), dp(v1), code.ctypes.data_as(ctypes.POINTER(ctypes.c_int32)),
            steps.ctypes.data_as(ctypes.POINTER(ctypes.c_int32)))
    nt = max(1, min(n_threads or threads(), -(-n // LANES)))
    if nt == 1:
        fn(*args)
    else:
        with ThreadPoolExecutor(nt) as pool:
            list(pool.map(lambda _: fn(*args), range(nt)))
    return x1, v1, code, steps
