"""The residual model's hyperparameters and their priors: the discrepancy's amplitude ``a`` (m) and time scale
``ℓ`` (s), the sensor noise's sd ``σ`` (m) and correlation time ``τ`` (s)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

__all__ = [
    "AMPLITUDE_SCALE",
    "KINDS",
    "NOISE_SCALE",
    "NOISE_TIME_BOUNDS",
    "NOISE_TIME_LOG_SD",
    "NOISE_TIME_MEDIAN",
    "TIME_SCALE_LOG_SD",
    "TIME_SCALE_MEDIAN",
    "Hyper",
    "log_prior",
]

KINDS = ("matern32", "none")  # the discrepancy's kinds: a Matérn-3/2 process, or none (noise alone)

# Priors of the hyperparameters (fit: MAP; posterior: marginalised). See the docs' "Uncertainty" page.
AMPLITUDE_SCALE = 2e-3  # m, half-normal scale of a: model errors up to a few mm on a robot of 10–60 mm
TIME_SCALE_MEDIAN = 1.0  # s, log-normal median of ℓ: the drive's pulse period (1.3 s) to the whole run
TIME_SCALE_LOG_SD = 1.0  # 90 % of the prior's mass on 0.19–5.2 s
NOISE_SCALE = 1e-3  # m, half-normal scale of σ
NOISE_TIME_MEDIAN = 0.03  # s, log-normal median of τ: a tracker's noise spans a few video frames
NOISE_TIME_LOG_SD = 1.5  # 90 % of the prior's mass on 2.5 ms – 0.36 s, below the discrepancy's time scale
NOISE_TIME_BOUNDS = (1e-4, 10.0)  # s, the estimate's search range


class Hyper(eqx.Module):
    """Hyperparameters of the residual model (``amplitude = 0`` is noise alone).

    Attributes:
        amplitude: the discrepancy's amplitude ``a``, m.
        time_scale: the discrepancy's time scale ``ℓ``, s.
        noise: the sensor noise's sd ``σ``, m.
        noise_time: the noise's correlation time ``τ``, s (0: independent noise).
    """

    amplitude: jax.Array
    time_scale: jax.Array
    noise: jax.Array
    noise_time: jax.Array

    @classmethod
    def of(cls, amplitude, time_scale, noise, noise_time=0.0) -> Hyper:
        """The hyperparameters from numbers or arrays (m, s, m, s), as float arrays."""
        f = lambda x: jnp.asarray(x, float)
        return cls(f(amplitude), f(time_scale), f(noise), f(noise_time))

    def as_dict(self) -> dict:
        """{amplitude_m, time_scale_s, noise_m, noise_time_s} as floats (a summary's record)."""
        return {
            "amplitude_m": float(self.amplitude),
            "time_scale_s": float(self.time_scale),
            "noise_m": float(self.noise),
            "noise_time_s": float(self.noise_time),
        }


def log_prior(
    hyper: Hyper,
    amplitude_scale: float = AMPLITUDE_SCALE,
    noise_scale: float = NOISE_SCALE,
    time_scale_median: float = TIME_SCALE_MEDIAN,
    time_scale_log_sd: float = TIME_SCALE_LOG_SD,
):
    """Log density (up to a constant) of the hyperparameters' priors, in the log coordinates (ln a, ln ℓ, ln σ,
    ln τ): a ~ HalfNormal, ℓ ~ LogNormal, σ ~ HalfNormal, τ ~ LogNormal (the Jacobians of the logs included).

    Args:
        hyper: the hyperparameters (all positive).
        amplitude_scale, noise_scale: the half-normal scales of ``a`` and ``σ``, m.
        time_scale_median, time_scale_log_sd: the log-normal median (s) and log-sd of ``ℓ``.

    Returns:
        The log density, nats (a scalar, or the hyperparameters' batch shape).
    """
    a, ell, s, tau = hyper.amplitude, hyper.time_scale, hyper.noise, hyper.noise_time
    return (
        -0.5 * (a / amplitude_scale) ** 2
        + jnp.log(a)
        - 0.5 * ((jnp.log(ell) - jnp.log(time_scale_median)) / time_scale_log_sd) ** 2
        - 0.5 * (s / noise_scale) ** 2
        + jnp.log(s)
        - 0.5 * ((jnp.log(tau) - jnp.log(NOISE_TIME_MEDIAN)) / NOISE_TIME_LOG_SD) ** 2
    )
