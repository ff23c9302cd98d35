"""The covariance of a local fit whose target holds a differentiated signal (paper Eq. 8).

Where the accelerations are estimated (Savitzky-Golay from x or v), the target's noise is not
white: it is the sensor noise passed through the differentiation filter, y_noise = sum_c h_c * e_c
(one filter per differentiated column; a chain cell carries every outer mass), plus the white
noise of the measured channels (base acceleration, force). Almost all of that noise lies far
above the band of the vibration, where no library column has power, so the ordinary
least-squares covariance sigma² (Θ'Θ)^-1, which takes it as white, overstates the uncertainty
by far (shallow arch, x only, 30 dB, 8 seeds: the local F'' standard error 5.4-7.8 against its
scatter 0.30-0.38, so F'' was screened out; the ratio for F' 9-11).

The sandwich with the noise's own structure,

    Cov = B (sum_c s_c² Z_c' Z_c + s_w² Θ'W²Θ) B,   B = (Θ'WΘ)^-1,   Z_c = H_c' W Θ,

with s_c², s_w² the channels' noise variances read from their spectra's high-frequency floors
(`_reconstruct/_noise.py`), matched the scatter over seeds (arch: F'' 0.32, 0.39 against 0.30,
0.38; F' 0.43, 0.67 % against 0.53, 0.75 %; magnetic bistable F'' 0.47, 0.21 against 0.30,
0.18). Where the residual is larger than the noise the model predicts (model error, a channel
noisier than its floor), the covariance is scaled up by the ratio (never down).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ._stls import support_inverse


class TargetNoise(eqx.Module):
    """The noise of a regression target: sum over components c of `taps[c]` (odd length,
    centred: y_noise[t] = sum_j taps[c, j] e_c[t + j - T // 2]) applied to white noise of
    variance `variances[c]`, plus white noise of variance `white`."""

    taps: Float[Array, "components taps"]
    variances: Float[Array, " components"]
    white: Float[Array, ""]

    def variance(self) -> Float[Array, ""]:
        """The target noise's variance per sample."""
        return jnp.sum(self.variances * jnp.sum(self.taps**2, axis=1)) + self.white


def structured_covariance(
    theta: Float[Array, "samples terms"],
    y: Float[Array, " samples"],
    weights: Float[Array, " samples"],
    coef: Float[Array, " terms"],
    support: Bool[Array, " terms"],
    noise: TargetNoise,
) -> tuple[Float[Array, "terms terms"], Float[Array, ""]]:
    """The weighted least-squares covariance of `coef` on `support` under `noise` (module
    docstring), zeros off the support; and the ratio of the residual variance to the noise's
    (the factor applied where it exceeds 1)."""
    norms = jnp.sqrt(jnp.sum(weights[:, None] * theta**2, axis=0))
    norms = jnp.where(support & (norms > 0), norms, 1.0)
    th = jnp.where(support[None, :], theta / norms[None, :], 0.0)
    wt = weights[:, None] * th
    b = support_inverse(th.T @ wt, support)

    def filtered(taps):  # H' W Θ, column by column
        return jax.vmap(lambda col: jnp.convolve(col, taps, mode="same"), in_axes=1, out_axes=1)(wt)

    z = jax.vmap(filtered)(noise.taps)  # (components, samples, terms)
    meat = jnp.einsum("c,cnp,cnq->pq", noise.variances, z, z) + noise.white * (wt.T @ wt)
    resid = y - theta @ coef
    n = jnp.sum(weights > 0)
    dof = jnp.maximum(n - jnp.sum(support), 1)
    ratio = (jnp.sum(weights * resid**2) / dof) / jnp.maximum(noise.variance(), 1e-300)
    cov = jnp.maximum(ratio, 1.0) * (b @ meat @ b)
    return cov / (norms[:, None] * norms[None, :]), ratio


