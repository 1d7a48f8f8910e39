"""NUTS's start and mass matrix: the scout, the Laplace approximation in NumPyro's coordinates, bound and ridge coordinates."""

from __future__ import annotations

from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist
import optimistix as optx

from ._model import _jitted_jacobian
from ._priors import Prior, RidgePrior, SoftplusPrior, _recast, bound_coordinates


def _scout(priors, mean_length, length, seed: int, n_scout: int = 64):
    """The best θ {name: value} of a seeded Latin hypercube over the priors, and its RMSE (m)."""
    from scipy.stats import qmc

    unit = qmc.LatinHypercube(d=len(priors), seed=seed).random(n_scout)
    cols = {}
    for k, p in enumerate(priors):
        u = unit[:, k]
        cols[p.name] = np.exp(np.log(p.low) + u * np.log(p.high / p.low)) if p.log else p.low + u * (p.high - p.low)
    mu = np.asarray(jax.jit(jax.vmap(mean_length))({n: jnp.asarray(v) for n, v in cols.items()}))
    rmse = np.sqrt(np.nanmean((mu - np.asarray(length)) ** 2, axis=1))
    rmse = np.where(np.all(np.isfinite(mu), axis=1), rmse, np.inf)
    best = int(np.argmin(rmse))
    if not np.isfinite(rmse[best]):
        raise RuntimeError("no point of the preconditioning scout simulated successfully")
    return {p.name: float(cols[p.name][best]) for p in priors}, float(rmse[best]), best, cols


def bound_start(make_model, priors, mean_length, length, mode: dict, inverse_mass):
    """(priors as sampled, start, inverse mass matrix) for NUTS through the model.

    ``mode`` is the posterior mode in NumPyro's coordinates ({site: value}, σ included). Priors whose mode
    lies against a bound are sampled in softplus coordinates instead (:func:`bound_coordinates`), and
    the start and mass matrix are found again in them (:func:`laplace_unconstrained`); then the other
    priors are sampled across the ridge they form with the pressed ones (:func:`ridge_coordinates`), and the
    start and mass matrix found once more. Where none is pressed, ``priors``, ``mode`` and ``inverse_mass``
    come back unchanged. ``make_model(mean, priors)``:
    the NumPyro model. On the public experiment under the Lockhart law (Y and n_L at their bounds),
    ``python benchmarks/nuts_direct.py --geometry`` measures what this changes (README, "Benchmarks").
    """
    sampled = bound_coordinates(priors, mode)
    if sampled == tuple(priors):
        return tuple(priors), mode, inverse_mass
    start = {
        ("u_" + p.site if isinstance(p, SoftplusPrior) else p.site): (
            p.start() if isinstance(p, SoftplusPrior) else mode[p.site]
        )
        for p in sampled
    }
    start.update({k: v for k, v in mode.items() if k not in {p.site for p in priors}})  # σ and the discrepancy's
    start, hess = laplace_unconstrained(lambda m: make_model(m, sampled), sampled, mean_length, length, start)
    ridged = ridge_coordinates(sampled, start, hess)
    if ridged == sampled:
        return sampled, start, jnp.asarray(_inverse_floored(hess))
    start = {
        **{"u_" + p.site: start["u_" + p.site] for p in ridged if isinstance(p, SoftplusPrior)},
        **{"v_" + p.site: 0.0 for p in ridged if isinstance(p, RidgePrior)},
        **{k: v for k, v in start.items() if not k.startswith("u_") and k not in {p.site for p in sampled}},
    }
    start, hess = laplace_unconstrained(lambda m: make_model(m, ridged), ridged, mean_length, length, start)
    return ridged, start, jnp.asarray(_inverse_floored(hess))


def ridge_coordinates(sampled: Sequence[Prior], start: dict, hess) -> tuple[Prior, ...]:
    """``sampled`` with every prior that is not pressed as a :class:`RidgePrior` across its ridge with the pressed
    (:class:`SoftplusPrior`) ones, the pressed ones first; unchanged where none is pressed or none is free.

    ``start`` {site: value} and ``hess`` (the potential's Hessian over the flattened sites, keys sorted as
    ``jax.flatten_util.ravel_pytree`` sorts them) come from :func:`laplace_unconstrained` in ``sampled``'s
    coordinates. The ridge is the Gaussian's conditional mean there, E[z_free | u] = z₀ − H_ff⁻¹ H_fu (u − u₀),
    each u-slope divided by ∂f_k/∂u_k at the mode to become a slope in the pressed prior's fraction f_k."""
    pressed = [p for p in sampled if isinstance(p, SoftplusPrior)]
    free = [p for p in sampled if not isinstance(p, (SoftplusPrior, RidgePrior))]
    if not pressed or not free:
        return tuple(sampled)
    index = {k: i for i, k in enumerate(sorted(start))}
    u_idx = [index["u_" + p.site] for p in pressed]
    f_idx = [index[p.site] for p in free]
    hess = np.asarray(hess)
    slopes_u = -np.linalg.solve(hess[np.ix_(f_idx, f_idx)], hess[np.ix_(f_idx, u_idx)])  # (free, pressed)
    u0 = [float(start["u_" + p.site]) for p in pressed]
    df_du = [float(jax.grad(p.fraction_at)(u)) for p, u in zip(pressed, u0)]
    f0 = [float(p.fraction_at(u)) for p, u in zip(pressed, u0)]
    out = list(pressed)
    for i, p in enumerate(free):
        z0 = float(dist.transforms.biject_to(p.distribution().support).inv(start[p.site]))
        along = tuple((q, float(slopes_u[i, k] / df_du[k])) for k, q in enumerate(pressed))
        offset = z0 - sum(b * f for (_, b), f in zip(along, f0))
        out.append(_recast(RidgePrior, p, along=along, offset=offset))
    return tuple(out)


def precondition(
    model,
    priors,
    mean_length,
    length,
    seed=0,
    n_scout: int = 64,
    optimise: bool = True,
    make_model=None,
    extra_init: dict | None = None,
):
    """Start point and inverse mass matrix for NUTS.

    The data fix Y to ~0.2 % of its prior width while ext and n stay at their priors, a
    scale ratio of ~200 in the unconstrained space: without preconditioning NUTS builds
    trees of hundreds of leapfrog steps. The start is the best of a seeded Latin hypercube
    over the priors (σ at its RMS residual). Then, if ``make_model`` is given (``mean → model``,
    the same statistical model around another ``mean_length``), the posterior mode and the Hessian
    of the potential there in NumPyro's unconstrained coordinates (:func:`laplace_unconstrained`:
    Gauss–Newton in θ, the transforms and priors exact; one forward-mode Jacobian of the model per
    step); else, if ``optimise``, the mode by BFGS (cheap on an emulator) and a central-difference
    Hessian. The inverse mass matrix is the inverse Hessian, eigenvalues floored at the logistic
    prior's curvature so that flat directions get the prior's scale.
    """
    from jax.flatten_util import ravel_pytree
    from numpyro.infer.util import initialize_model

    best_theta, rmse, _, _ = _scout(priors, mean_length, length, seed, n_scout)
    init = {p.site: best_theta[p.name] for p in priors}
    init["sigma"] = max(rmse, 1e-6)
    init.update(extra_init or {})
    if make_model is not None:
        init, hess = laplace_unconstrained(make_model, priors, mean_length, length, init)
        return init, jnp.asarray(_inverse_floored(hess))
    info = initialize_model(
        jax.random.PRNGKey(seed),
        model,
        model_args=(jnp.asarray(length),),
        init_strategy=numpyro.infer.init_to_value(values=init),
        forward_mode_differentiation=not optimise,
        validate_grad=False,
    )
    z0, unravel = ravel_pytree(info.param_info.z)
    potential = jax.jit(lambda z: info.potential_fn(unravel(z)))
    if optimise:
        sol = optx.minimise(lambda z, _: potential(z), optx.BFGS(rtol=1e-8, atol=1e-8), z0, max_steps=500, throw=False)
        if np.isfinite(float(potential(sol.value))) and float(potential(sol.value)) < float(potential(z0)):
            z0 = sol.value
            init = {k: float(v) for k, v in info.postprocess_fn(unravel(z0)).items() if k in init}
    return init, jnp.asarray(_inverse_floored(_fd_hessian(jax.jit(jax.vmap(potential)), np.asarray(z0))))


PRIOR_CURVATURE_FLOOR = 0.3  # logistic prior's curvature ≈ 0.5 at its centre


def _inverse_floored(hess):
    """Inverse of a symmetric Hessian (d, d) with its eigenvalues floored at :data:`PRIOR_CURVATURE_FLOOR`."""
    evals, evecs = np.linalg.eigh(np.asarray(hess))
    return (evecs / np.maximum(evals, PRIOR_CURVATURE_FLOOR)) @ evecs.T


LAPLACE_MAX_STEPS = 40
LAPLACE_DECREMENT = 1e-2  # nats: stop once Newton predicts less (~0.1 posterior sd from the mode)
LAPLACE_STALL = 3  # or once this many steps in a row fail to lower it: the model's own noise is reached


def laplace_unconstrained(make_model, priors, mean_length, length, init: dict):
    """Posterior mode and Hessian (d, d) of the potential over the flattened sites in NumPyro's unconstrained
    coordinates; the mode as {site: constrained value}. ``make_model(mean_length)``: the NumPyro model around a
    given mean. ``init``: {site: constrained value}.

    NUTS samples z = T⁻¹(θ) (logit of each bounded prior, log σ). Near a prior's bound (the public
    experiment's Y and n_L under the Lockhart law lie at theirs) the posterior in z is not the
    Gaussian of a fit in θ: the transform's Jacobian shapes it. Each step linearises the model in θ
    around the current point, μ(θ) ≈ μ₀ + J(θ − θ₀) (one forward-mode Jacobian), and takes a damped
    Newton step on the resulting potential, exact in everything else (priors, transforms, σ); a step the
    true potential does not confirm raises the damping. At the fixed point the gradient is the true one and
    the Hessian is Gauss–Newton in θ, exact in the transforms. Not :func:`growjax.calibration.least_squares.levenberg_marquardt`:
    the potential is no sum of squares plus a prior, its normaliser n·ln σ (with a discrepancy also ½ ln det
    of its covariance) has no residual form (on the tests' 200-sample saturating problem the potential at the
    mode is −1278 nats: n·ln σ −1573, the squared residuals +100).
    """
    from jax.flatten_util import ravel_pytree
    from numpyro.infer.util import constrain_fn, potential_energy, unconstrain_fn

    names = tuple(p.name for p in priors)
    sites = tuple(p.site for p in priors)
    y = jnp.asarray(length)

    def linear_model(data, mu0, jac, v0):
        make_model(lambda th: mu0 + jac @ (jnp.stack([jnp.asarray(th[n], float) for n in names]) - v0))(data)

    d = len(names)
    placeholder = (y, jnp.zeros_like(y), jnp.zeros((y.size, d)), jnp.zeros(d))  # the transforms alone
    zf, unravel = ravel_pytree(unconstrain_fn(linear_model, placeholder, {}, init))

    def potential(z, mu0, jac, v0):
        return potential_energy(linear_model, (y, mu0, jac, v0), {}, unravel(z))

    def constrained(z):  # deterministic sites included: a prior may record θ as one (Prior.sample)
        return constrain_fn(linear_model, placeholder, {}, unravel(z), return_deterministic=True)

    def theta_of(z):
        values = constrained(z)
        return jnp.stack([values[s] for s in sites])

    value = jax.jit(potential)
    grad_hess = jax.jit(lambda *a: (jax.grad(potential)(*a), jax.hessian(potential)(*a)))
    jacobian = _jitted_jacobian(mean_length, names)
    theta = jax.jit(theta_of)

    def linearised_at(z):
        v = theta(jnp.asarray(z))
        mu0, jac = jacobian(v)
        return mu0, jac, v

    z = np.asarray(zf)
    args = linearised_at(z)
    f = float(value(jnp.asarray(z), *args))
    if not np.isfinite(f):
        raise RuntimeError("the model failed at the start of the Laplace approximation")
    damping, rejected = 1e-3, 0
    for _ in range(LAPLACE_MAX_STEPS):
        g, h = (np.asarray(a) for a in grad_hess(jnp.asarray(z), *args))
        evals, evecs = np.linalg.eigh(h)
        h_pos = (evecs * np.maximum(evals, 1e-8 * max(evals[-1], 1e-300))) @ evecs.T
        if 0.5 * g @ np.linalg.solve(h_pos, g) < LAPLACE_DECREMENT:  # Newton decrement: at the mode
            break
        step = -np.linalg.solve(h_pos + damping * np.diag(np.diag(h_pos)), g)
        predicted = f - float(value(jnp.asarray(z + step), *args))
        if not predicted > 0.0:  # too far even for the linearised model: shorten without running the model
            damping = 4.0 * max(damping, 1e-3)
            continue
        args_new = linearised_at(z + step)
        f_new = float(value(jnp.asarray(z + step), *args_new))
        ratio = (f - f_new) / predicted
        if np.isfinite(f_new) and ratio > 0.1:
            z, args, f, rejected = z + step, args_new, f_new, 0
            damping *= max(1.0 / 3.0, 1.0 - (2.0 * ratio - 1.0) ** 3)
        else:
            damping, rejected = 4.0 * max(damping, 1e-3), rejected + 1
            if rejected == LAPLACE_STALL:
                break
    hess = np.asarray(grad_hess(jnp.asarray(z), *args)[1])
    mode = {k: float(x) for k, x in jax.jit(constrained)(jnp.asarray(z)).items() if k in init}
    return mode, hess


def _fd_hessian(batched_potential, z0, step: float = 1e-3):
    """Central-difference Hessian (d, d) from one batched call of the potential on the stencil (cheap to compile)."""
    d = z0.size
    eye = np.eye(d) * step
    points = [z0]
    for i in range(d):
        points += [z0 + eye[i], z0 - eye[i]]
        for j in range(i + 1, d):
            points += [z0 + eye[i] + eye[j], z0 + eye[i] - eye[j], z0 - eye[i] + eye[j], z0 - eye[i] - eye[j]]
    u = np.asarray(batched_potential(jnp.asarray(np.stack(points))))
    hess = np.zeros((d, d))
    k = 1
    for i in range(d):
        hess[i, i] = (u[k] - 2.0 * u[0] + u[k + 1]) / step**2
        k += 2
        for j in range(i + 1, d):
            hess[i, j] = hess[j, i] = (u[k] - u[k + 1] - u[k + 2] + u[k + 3]) / (4.0 * step**2)
            k += 4
    return hess
