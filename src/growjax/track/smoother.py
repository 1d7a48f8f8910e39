"""The Rauch–Tung–Striebel smoother over a filtered record: the state at every sample given the whole record.

Backwards from the last sample, with the gain G_k = C_k (P⁻_{k+1})⁻¹ from each step's cross-covariance C_k of the
filtered state at t_k with the predicted one at t_{k+1} (the extended filter's P_k Fᵀ, the unscented filter's
sigma-point covariance, `growjax.track.Step`):

    m^s_k = m_k + G_k (m^s_{k+1} − m⁻_{k+1}),   P^s_k = P_k + G_k (P^s_{k+1} − P⁻_{k+1}) G_kᵀ.

The smoothed covariance is never larger than the filtered one (each sample's band narrows or stays).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from growjax.track.belief import symmetric

JITTER = (1e-12, 1e-18)  # relative to P⁻'s diagonal and absolute: a direction the model holds fixed leaves it singular


@jax.jit
def smooth(
    means: Float[Array, "T N"],
    covs: Float[Array, "T N N"],
    predicted_means: Float[Array, "T N"],
    predicted_covs: Float[Array, "T N N"],
    crosses: Float[Array, "T N N"],
) -> tuple[Float[Array, "T N"], Float[Array, "T N N"]]:
    """(smoothed means (T, N), covariances (T, N, N)) from the filtered ones at T samples.

    Args:
        means, covs: the filtered belief at each sample.
        predicted_means, predicted_covs: at row k, the prediction of sample k + 1 from sample k (the last row is
            not used).
        crosses: at row k, the covariance of the filtered state at sample k with that prediction.
    """

    def back(carry, inputs):
        m_next, p_next = carry
        m, p, m_pred, p_pred, cross = inputs
        jitter = JITTER[0] * jnp.diag(p_pred) + JITTER[1]
        gain = jnp.linalg.solve(p_pred + jnp.diag(jitter), cross.T).T  # C P⁻⁻¹ (P⁻ symmetric)
        m_s = m + gain @ (m_next - m_pred)
        p_s = symmetric(p + gain @ (p_next - p_pred) @ gain.T)
        return (m_s, p_s), (m_s, p_s)

    last = (means[-1], covs[-1])
    rows = (means[:-1], covs[:-1], predicted_means[:-1], predicted_covs[:-1], crosses[:-1])
    _, (m_s, p_s) = jax.lax.scan(back, last, rows, reverse=True)
    return jnp.concatenate([m_s, last[0][None]]), jnp.concatenate([p_s, last[1][None]])


__all__ = ["smooth"]
