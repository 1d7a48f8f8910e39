"""The statistical model of the measured length and the model's mean length it runs on."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist

from growjax.calibration import MODEL_ERROR_TIME
from growjax.calibration import discrepancy as dc
from growjax.model import params as gp
from growjax.posterior import emulator as em
from growjax.posterior.emulator import predicted_length, sample_times
from growjax.simulation.simulate import input_breaks, length_jacobian
from growjax.simulation.trajectory import OK

from ._priors import Prior


def growth_model(
    length=None,
    *,
    mean_length,
    priors: Sequence[Prior],
    noise_scale=1e-3,
    model_error=0.0,
    residuals: Residuals | None = None,
):
    """NumPyro model of the measured length (m)::

        θ_j ~ prior_j,   σ ~ HalfNormal(noise_scale),
        a ~ HalfNormal(2 mm),   ℓ ~ LogNormal(ln 1 s, 1),   τ ~ LogNormal(ln 30 ms, 1.5)   (with a discrepancy)
        L_obs = L_model(t; θ) + δ(t) + Σ_k g_k(t) b_k + d(t) + ε,   δ ~ GP(0, Matérn-3/2(a, ℓ)),
        b_k ~ N(0, u_k²),   d ~ GP(0, e_c² exp(−½(Δt/5 s)²)),   ε ~ GP(0, (σ² + e²) exp(−|Δt|/τ))
        (τ = 0, independent, without a discrepancy)

    ``mean_length(theta)`` is the model (or its emulator) at the measured times; ``e`` (m) is the
    emulator's RMS error (0 for the model itself). ``residuals`` (`Residuals`) sets the discrepancy,
    the rig's tolerances, the configuration's own error e_c (the drift d) and the samples scored; None:
    independent noise, every sample (δ, b and d absent). δ, b and d are marginalised exactly
    (`growjax.calibration.discrepancy`). A failed solve has zero likelihood.
    """
    theta = {}
    for p in priors:
        theta[p.name] = p.sample(theta)
    sigma = numpyro.sample("sigma", dist.HalfNormal(noise_scale))
    mu = mean_length(theta)
    ok = jnp.all(jnp.isfinite(mu))
    numpyro.factor("solver_ok", jnp.where(ok, 0.0, -jnp.inf))
    numpyro.deterministic("length_model", mu)
    scale = jnp.sqrt(sigma**2 + model_error**2)
    mu = jnp.where(jnp.isfinite(mu), mu, 0.0)
    if residuals is None:
        numpyro.sample("length", dist.Normal(mu, scale), obs=length)
        return
    if residuals.discrepancy == "matern32":
        amplitude = numpyro.sample("delta_amplitude", dist.HalfNormal(dc.AMPLITUDE_SCALE))
        time_scale = numpyro.sample(
            "delta_time_scale", dist.LogNormal(np.log(dc.TIME_SCALE_MEDIAN), dc.TIME_SCALE_LOG_SD)
        )
        noise_time = numpyro.sample("noise_time", dist.LogNormal(np.log(dc.NOISE_TIME_MEDIAN), dc.NOISE_TIME_LOG_SD))
    else:
        amplitude, time_scale, noise_time = jnp.zeros(()), jnp.ones(()), jnp.zeros(())
    hyper = dc.Hyper(amplitude, time_scale, scale, noise_time)
    if length is None:  # replicated data at every sample
        numpyro.sample("length", residuals.replicate(mu, hyper))
    else:  # the scored samples
        numpyro.sample("length", residuals.distribution(mu, hyper), obs=jnp.asarray(length)[residuals.index])


@dataclasses.dataclass(frozen=True, eq=False)
class Residuals:
    """What the likelihood of :func:`growth_model` holds besides the model: the discrepancy (``"matern32"`` or
    ``"none"``), the sample times (n,) s, the samples scored (n,) bool, the rig's tolerances: sensitivities
    (n, q) m per unit ln ψ, relative sds (q,), names, and ``centre`` (q,), the rig's errors ln(ψ/ψ₀) where the
    model and the sensitivities are taken (None: nominal), and ``model_error`` (m), the fitted configuration's own
    error against the reference. The rig's errors b from there have the prior N(−centre, u²) (their tolerance is
    about nominal), so the rig term's mean is −g·centre. The configuration's error is a slow drift of sd
    ``model_error`` (squared exponential over `growjax.calibration.MODEL_ERROR_TIME`, as the fit carries it),
    marginalised as a few more static terms of the filter (`growjax.calibration.discrepancy.drift_columns`). The
    filter runs over the scored samples alone (the likelihood of an interpolated record is that of its
    keyframes)."""

    discrepancy: str
    times: np.ndarray
    observed: np.ndarray
    sensitivity: np.ndarray | None = None
    tolerance: np.ndarray | None = None
    tolerance_names: tuple = ()
    centre: np.ndarray | None = None
    model_error: float = 0.0

    def columns(self, times=None, sensitivity=None) -> tuple:
        """(g (n, q + k) m, u (q + k,)) or (None, None): the rig's sensitivities (``sensitivity`` at ``times``, default
        this likelihood's) and the configuration's drift columns at ``times`` (default the samples' times), with the
        prior sds of their weights (the tolerances; 1 for the drift's)."""
        times = self.times if times is None else times
        g = self.sensitivity if sensitivity is None else sensitivity
        u = self.tolerance
        if self.model_error > 0:
            drift = dc.drift_columns(times, self.model_error, MODEL_ERROR_TIME)
            g = drift if g is None else np.concatenate([np.asarray(g), drift], axis=1)
            u = np.ones(drift.shape[1]) if u is None else np.concatenate([np.asarray(u), np.ones(drift.shape[1])])
        return (None, None) if g is None else (np.asarray(g), np.asarray(u))

    @property
    def index(self) -> np.ndarray:
        return np.flatnonzero(self.observed)

    def rig_mean(self, sensitivity=None) -> np.ndarray | float:
        """The rig term's prior mean, m: −g·centre at the samples of ``sensitivity`` (default this likelihood's);
        0 at nominal."""
        g = self.sensitivity if sensitivity is None else sensitivity
        if self.centre is None or g is None:
            return 0.0
        return -np.asarray(g) @ np.asarray(self.centre)

    def _terms(self, index):
        g, u = self.columns()
        g = None if g is None else jnp.asarray(g[index])
        u = None if u is None else jnp.asarray(u)
        mean = self.rig_mean()
        offset = jnp.asarray(mean[index] if np.ndim(mean) else mean)
        return jnp.asarray(np.asarray(self.times)[index]), g, u, offset

    def distribution(self, mu, hyper):
        """The scored samples' distribution (event shape: the number scored) around the model ``mu`` (n,)."""
        index = self.index
        t, g, u, offset = self._terms(index)
        return dc.distribution(mu[index] + offset, t, hyper, g, u)

    def replicate(self, mu, hyper):
        """Replicated data at every sample (event shape (n,)) around ``mu`` (n,)."""
        t, g, u, offset = self._terms(np.arange(len(self.times)))
        return dc.distribution(mu + offset, t, hyper, g, u)

    def conditional(self, y, mu, hyper):
        """Mean (n,) m and variance (n,) m² of the discrepancy and rig term at every sample given the data ``y``
        (n,) at the scored samples (:func:`growjax.calibration.discrepancy.smooth`)."""
        t, g, u, offset = self._terms(np.arange(len(self.times)))
        mean, var = dc.smooth(jnp.asarray(y) - mu - offset, t, hyper, g, u, jnp.asarray(self.observed))
        return mean + offset, var

    def pointwise(self, y, mu, hyper):
        """(n,) one-step-ahead log-densities of ``y`` at the scored samples, 0 elsewhere."""
        index = self.index
        terms = self.distribution(mu, hyper).pointwise(jnp.asarray(y)[index])
        return jnp.zeros(len(self.times)).at[index].set(terms)

    def hyper_sites(self, hyper: dc.Hyper) -> dict:
        """Start values {site: value} of the hyperparameters' sites."""
        if self.discrepancy != "matern32":
            return {}
        return {
            "delta_amplitude": max(float(hyper.amplitude), 1e-7),
            "delta_time_scale": float(hyper.time_scale),
            "noise_time": max(float(hyper.noise_time), 1e-4),
        }


class DirectMean:
    """``mean_length`` that runs the model: θ {name: value} → length (m) at ``times`` (NaN where the run failed),
    with :meth:`value_and_jacobian` from one solve that carries the sensitivities."""

    def __init__(self, base, inputs, config, times):
        self.base, self.inputs, self.config, self.times = base, inputs, config, jnp.asarray(times)

    def __call__(self, theta):
        return predicted_length(theta, self.base, self.inputs, self.config, self.times)

    def value_and_jacobian(self, names):
        """``v (d,) → (μ (m,), ∂μ/∂v (m, d))`` over θ = ``dict(zip(names, v))``
        (`growjax.simulation.simulate.length_jacobian`: a solve fewer than a forward-mode derivative of `__call__`;
        NaN where the run failed)."""
        names, base = tuple(names), self.base
        breaks = input_breaks(self.inputs, self.config)
        ts = sample_times(self.times, self.config)

        def params_of(v):
            return gp.replace(base, **dict(zip(names, v)))

        def value_and_jacobian(v):
            traj, jac = length_jacobian(params_of, v, self.inputs, self.config, ts, breaks)
            ok = traj.status == OK
            return jnp.where(ok, traj.length, jnp.nan), jnp.where(ok, jac, jnp.nan)

        return value_and_jacobian


def direct_mean(base, inputs, config, times) -> DirectMean:
    """``mean_length`` that runs the model: θ {name: value} → length (m) at ``times`` (:class:`DirectMean`)."""
    return DirectMean(base, inputs, config, times)


def emulated_mean(emulator: em.Emulator):
    """``mean_length`` from an emulator (θ {name: value} → length at the emulator's times)."""
    return lambda theta: emulator(jnp.stack([jnp.asarray(theta[n], float) for n in emulator.names]))


def build_emulator(priors: Sequence[Prior], base, inputs, config, times, seed: int = 0) -> em.Emulator:
    """Emulator over the prior box, validated at 64 seeded points."""
    emu = em.build([p.axis() for p in priors], base, inputs, config, times)
    return em.validate(emu, 64, seed)


def value_and_jacobian(mean_length, names):
    """``v (d,) → (μ (m,), ∂μ/∂v (m, d))`` for ``mean_length`` over θ = ``dict(zip(names, v))``: the model's own
    (:meth:`DirectMean.value_and_jacobian`, one solve) where it has one, else one forward-mode pass carrying d
    tangent directions (`growjax.calibration.linearise`)."""
    from growjax.calibration.least_squares import linearise

    names = tuple(names)
    if hasattr(mean_length, "value_and_jacobian"):
        return mean_length.value_and_jacobian(names)
    return lambda v: linearise(lambda w: mean_length(dict(zip(names, w))), v)


@functools.lru_cache(maxsize=8)
def _jitted_jacobian(mean_length, names):
    """``jax.jit`` of :func:`value_and_jacobian`, one per model: a second Laplace start (:func:`bound_start`)
    reuses the compiled Jacobian."""
    return jax.jit(value_and_jacobian(mean_length, names))


def with_model_tangents(mean_length, names):
    """``mean_length`` whose forward-mode derivative runs one tangent solve in θ's own d directions.

    ``jacfwd`` of NumPyro's potential pushes one tangent per unconstrained site through the model,
    the noise scale's (zero) included; here the model's Jacobian ∂μ/∂θ (d directions) is computed once
    and every tangent of θ is mapped through it.
    """
    names = tuple(names)
    jacobian = value_and_jacobian(mean_length, names)

    @jax.custom_jvp
    def mean_vector(v):
        return mean_length(dict(zip(names, v)))

    @mean_vector.defjvp
    def _tangent(primals, tangents):
        (v,), (dv,) = primals, tangents
        mu, jac = jacobian(v)
        return mu, jac @ dv

    return lambda theta: mean_vector(jnp.stack([jnp.asarray(theta[n], float) for n in names]))
