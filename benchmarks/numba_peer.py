"""The peer a performance-minded user would write for a basin sweep: a scalar Dormand-Prince 5(4)
in numba (benchmark-only dependency), compiled with the model's coefficients hard-coded.

- Right-hand side generated as Python source from a polynomial `GlobalModel` on a chain (every
  coefficient a literal, zero terms left out), tip half-sine load A sin(2 pi f t) for t <= 1/(2f).
- DOPRI5 with first-same-as-last, an integral step-size controller
  (h_new = h clip(0.9 err^-1/5, 0.2, 10), at most 0.9 after a rejection), error as the RMS of
  err / (atol + rtol max(|y|, |y_new|)), Hairer's starting step; the integration stops at the
  switch-off time 1/(2f) and restarts there (new first stage, the last step size kept).
- A point that leaves the divergence box (|x - centre| > box_spans span) stops there; a point
  over its step budget stops too (code 2; 1 = diverged, 0 = reached t1).
- `prange` over the grid's points (all cores).
"""

import math

import numpy as np
from numba import njit, prange

A21 = 1 / 5
A31, A32 = 3 / 40, 9 / 40
A41, A42, A43 = 44 / 45, -56 / 15, 32 / 9
A51, A52, A53, A54 = 19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729
A61, A62, A63, A64, A65 = 9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656
B1, B3, B4, B5, B6 = 35 / 384, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84
E1, E3, E4, E5, E6, E7 = (71 / 57600, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40)
C2, C3, C4, C5 = 1 / 5, 3 / 10, 4 / 5, 8 / 9


def rhs_source(model) -> str:
    """Source of `rhs(t, y, f, amp, t_off, out)` for a polynomial chain model: coefficients as
    literals (what a user's code generator would write)."""
    k = np.asarray(model.stiffness)
    b = np.asarray(model.velocity_damping)
    c = np.asarray(model.position_damping)
    m = np.asarray(model.masses)
    n = k.shape[0]
    lines = ["def rhs(t, y, f, amp, t_off, out):",
             "    p = amp * math.sin(2.0 * math.pi * f * t) if t <= t_off else 0.0"]
    for i in range(n):
        lines.append(f"    x{i} = y[{i}]")
        lines.append(f"    v{i} = y[{n + i}]")
    for i in range(n):
        terms = [f"{float(k[i, j])!r} * x{i}" + (f" ** {j}" if j > 1 else "") for j in range(1, k.shape[1]) if k[i, j] != 0]
        if k[i, 0] != 0:
            terms.append(repr(float(k[i, 0])))
        for j in range(b.shape[1]):
            if b[i, j] != 0:
                if j == 0:
                    terms.append(f"{float(b[i, j])!r} * math.copysign(1.0, v{i})")
                elif j % 2 == 1:
                    terms.append(f"{float(b[i, j])!r} * v{i}" + (f" ** {j}" if j > 1 else ""))
                else:
                    terms.append(f"{float(b[i, j])!r} * math.copysign(abs(v{i}) ** {j}, v{i})")
        for j in range(c.shape[1]):
            if c[i, j] != 0:
                terms.append(f"{float(c[i, j])!r} * v{i}" + (f" * x{i} ** {j}" if j else ""))
        lines.append(f"    g{i} = p - ({' + '.join(terms) if terms else '0.0'})")
    # chain: g_i = (load carried by cell i: the tip force) - F_i; a_i = (g_i - g_{i+1}) / m_i
    for i in range(n):
        nxt = f" - g{i + 1}" if i < n - 1 else ""
        lines.append(f"    a{i} = (g{i}{nxt}) / {float(m[i])!r}")
    for i in range(n):
        lines.append(f"    out[{i}] = v{i}")
        lines.append(f"    out[{n + i}] = a{i}" + (f" - a{i - 1}" if i > 0 else ""))
    return "\n".join(lines) + "\n"


def build(model, settle_time, rtol, atol, max_steps, box_lo, box_hi):
    """The compiled sweep `sweep(fs, amps, x0) -> (x1, v1, code, steps)` for this model."""
    ns = {"math": math}
    exec(rhs_source(model), ns)  # noqa: S102  (benchmark code generator)
    rhs = njit(cache=False, fastmath=False)(ns["rhs"])
    n = int(np.asarray(model.stiffness).shape[0])
    dim = 2 * n
    lo = np.asarray(box_lo, float)
    hi = np.asarray(box_hi, float)

    @njit(cache=False)
    def norm(err, y, y1):
        s = 0.0
        for i in range(dim):
            sc = atol + rtol * max(abs(y[i]), abs(y1[i]))
            s += (err[i] / sc) ** 2
        return math.sqrt(s / dim)

    @njit(cache=False)
    def initial_step(t, y, f, amp, t_off, k1, tmp, k2):
        # Hairer, Norsett & Wanner, Solving ODEs I, II.4
        d0 = 0.0
        d1 = 0.0
        for i in range(dim):
            sc = atol + rtol * abs(y[i])
            d0 += (y[i] / sc) ** 2
            d1 += (k1[i] / sc) ** 2
        d0 = math.sqrt(d0 / dim)
        d1 = math.sqrt(d1 / dim)
        h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
        for i in range(dim):
            tmp[i] = y[i] + h0 * k1[i]
        rhs(t + h0, tmp, f, amp, t_off, k2)
        d2 = 0.0
        for i in range(dim):
            sc = atol + rtol * abs(y[i])
            d2 += ((k2[i] - k1[i]) / sc) ** 2
        d2 = math.sqrt(d2 / dim) / h0
        if max(d1, d2) <= 1e-15:
            h1 = max(1e-6, h0 * 1e-3)
        else:
            h1 = (0.01 / max(d1, d2)) ** (1.0 / 5.0)
        return min(100 * h0, h1)

    @njit(cache=False)
    def solve_point(x0, f, amp):
        t_off = 0.5 / f
        t1 = t_off + settle_time
        y = np.empty(dim)
        for i in range(n):
            y[i] = x0[i]
            y[n + i] = 0.0
        k1 = np.empty(dim)
        k2 = np.empty(dim)
        k3 = np.empty(dim)
        k4 = np.empty(dim)
        k5 = np.empty(dim)
        k6 = np.empty(dim)
        k7 = np.empty(dim)
        tmp = np.empty(dim)
        y1 = np.empty(dim)
        err = np.empty(dim)
        t = 0.0
        steps = 0
        code = 0
        rhs(t, y, f, amp, t_off, k1)
        h = initial_step(t, y, f, amp, t_off, k1, tmp, k2)
        for piece in range(2):
            stop = t_off if piece == 0 else t1
            if piece == 1:  # restart at the switch-off: new first stage
                rhs(t, y, f, amp, t_off, k1)
            while t < stop:
                if steps >= max_steps:
                    return y, 2, steps
                last = t + h >= stop
                hh = stop - t if last else h
                for i in range(dim):
                    tmp[i] = y[i] + hh * A21 * k1[i]
                rhs(t + C2 * hh, tmp, f, amp, t_off, k2)
                for i in range(dim):
                    tmp[i] = y[i] + hh * (A31 * k1[i] + A32 * k2[i])
                rhs(t + C3 * hh, tmp, f, amp, t_off, k3)
                for i in range(dim):
                    tmp[i] = y[i] + hh * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i])
                rhs(t + C4 * hh, tmp, f, amp, t_off, k4)
                for i in range(dim):
                    tmp[i] = y[i] + hh * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i])
                rhs(t + C5 * hh, tmp, f, amp, t_off, k5)
                for i in range(dim):
                    tmp[i] = y[i] + hh * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i])
                t_end = stop if last else t + hh
                rhs(t_end if last else t + hh, tmp, f, amp, t_off, k6)
                for i in range(dim):
                    y1[i] = y[i] + hh * (B1 * k1[i] + B3 * k3[i] + B4 * k4[i] + B5 * k5[i] + B6 * k6[i])
                rhs(t_end, y1, f, amp, t_off, k7)
                for i in range(dim):
                    err[i] = hh * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i])
                e = norm(err, y, y1)
                steps += 1
                if not (e <= 1.0):  # rejected (NaN too)
                    fac = 0.2 if not (e == e) else max(0.2, min(0.9, 0.9 * e ** -0.2))
                    h = hh * fac
                    if t + h <= t:
                        return y, 3, steps
                    continue
                fac = 10.0 if e == 0.0 else max(0.2, min(10.0, 0.9 * e ** -0.2))
                h_new = hh * fac
                if last:  # a step cut short at a stop does not shrink the next one
                    h_new = max(h_new, h)
                h = h_new
                t = t_end
                for i in range(dim):
                    y[i] = y1[i]
                    k1[i] = k7[i]
                for i in range(n):
                    if y[i] < lo[i] or y[i] > hi[i]:
                        return y, 1, steps
        return y, code, steps

    @njit(parallel=True, cache=False)
    def sweep(fs, amps, x0):
        npts = fs.shape[0]
        x1 = np.empty((npts, n))
        v1 = np.empty((npts, n))
        code = np.empty(npts, np.int64)
        steps = np.empty(npts, np.int64)
        for p in prange(npts):
            y, c, s = solve_point(x0, fs[p], amps[p])
            for i in range(n):
                x1[p, i] = y[i]
                v1[p, i] = y[n + i]
            code[p] = c
            steps[p] = s
        return x1, v1, code, steps

    return sweep
