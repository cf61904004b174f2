"""A linear-Gaussian run on a sloped seabed (bilinear interpolation is exact on it) and its exact
answers: the Kalman filter, and its mixture over an unknown speed scale; shared by the PF and PMF tests."""

from __future__ import annotations

import numpy as np

from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel
from tangraph.survey import Survey

GRADIENT = np.array([0.05, -0.02])  # depth = 500 + g . (north, east): bilinear is exact on it


def sloped_seabed():
    north = np.arange(-5000.0, 5001.0, 50.0)
    east = np.arange(-5000.0, 5001.0, 50.0)
    nn, ee = np.meshgrid(north, east, indexing="ij")
    return BathymetryMap(north=north, east=east, depth=500 + GRADIENT[0] * nn + GRADIENT[1] * ee)


def linear_gaussian_run(seed, *, k=30, q=2.0, sigma=1.0, p0=30.0, tide_sd=0.0, scale=0.0):
    """Truth moves by known steps plus N(0, q^2) per axis; one vertical sounding per ping with
    N(0, sigma^2) noise; DR = the known steps times ``1 + scale`` from the true start (so the DR
    increments are exact up to the scale, and the process noise is what the filters model)."""
    rng = np.random.default_rng(seed)
    steps = np.column_stack([np.full(k - 1, 20.0), np.full(k - 1, 5.0)])
    start = rng.normal(0.0, p0, 2)
    truth = np.vstack([start, start + np.cumsum(steps + q * rng.standard_normal((k - 1, 2)), axis=0)])
    dr = np.vstack([[0.0, 0.0], np.cumsum((1.0 + scale) * steps, axis=0)])
    tide = tide_sd * rng.standard_normal()
    depth = 500 + truth @ GRADIENT + tide + sigma * rng.standard_normal(k)
    survey = Survey(
        time=np.arange(k, dtype=float),
        dr_pose=np.column_stack([dr, np.zeros(k)]),
        vehicle_depth=np.full(k, 10.0),
        beam_forward=np.zeros((k, 1)),
        beam_starboard=np.zeros((k, 1)),
        beam_depth=depth[:, None],
        true_pose=np.column_stack([truth, np.zeros(k)]),
    )
    return survey


def kalman(survey, *, q, sigma, p0, tide_sd=0.0, scale=0.0):
    """The exact filter on (north, east, tide) for a known DVL scale ``k = scale``:
    x_k = x_{k-1} + u_k / (1 + k) + w, z_k = 500 + g . x_k + t + v. Returns the final position
    mean and covariance and the log marginal likelihood of the soundings."""
    x = np.append(survey.dr_pose[0, :2], 0.0)
    p = np.diag([p0**2, p0**2, tide_sd**2])
    h = np.append(GRADIENT, 1.0)[None, :]
    log_evidence = 0.0
    for k in range(survey.n_pings):
        if k > 0:
            x[:2] = x[:2] + (survey.dr_pose[k, :2] - survey.dr_pose[k - 1, :2]) / (1.0 + scale)
            p = p + np.diag([q**2, q**2, 0.0])
        s = (h @ p @ h.T).item() + sigma**2
        innovation = (survey.beam_depth[k, 0] - 500 - h @ x).item()
        log_evidence += -0.5 * (innovation**2 / s + np.log(2 * np.pi * s))
        gain = p @ h.T / s
        x = x + (gain * innovation).ravel()
        p = (np.eye(3) - gain @ h) @ p
    return x[:2], p[:2, :2], log_evidence


def kalman_mixture(survey, *, q, sigma, p0, scale_sd, nodes=80):
    """The exact posterior with an unknown scale ``k ~ N(0, scale_sd^2)``: given ``k`` the model is
    linear-Gaussian (:func:`kalman`), so the posterior is the mixture over Gauss-Hermite nodes of
    ``k`` of the Kalman posteriors, weighted by prior weight times evidence. Returns the position
    mean and covariance and the mean and std of ``k``."""
    z, prior = np.polynomial.hermite_e.hermegauss(nodes)
    ks = scale_sd * z
    runs = [kalman(survey, q=q, sigma=sigma, p0=p0, scale=k) for k in ks]
    log_w = np.log(prior) + np.array([r[2] for r in runs])
    w = np.exp(log_w - log_w.max())
    w /= w.sum()
    means = np.array([r[0] for r in runs])
    mean = w @ means
    d = means - mean
    cov = np.einsum("i,ijk->jk", w, np.array([r[1] for r in runs])) + (d * w[:, None]).T @ d
    k_mean = w @ ks
    return mean, cov, k_mean, float(np.sqrt(w @ (ks - k_mean) ** 2))


def linear_model(*, q, sigma, p0, tide_sd=0.0, scale_sd=0.0):
    """The filters' navigation model of :func:`linear_gaussian_run` (one ping a second: the speed
    noise is the process noise per ping; no heading error: its prior is negligible; the stated
    errors trusted, as the Kalman filter does: no misfit scale)."""
    return NavigationModel(
        misfit_dof=0.0,
        speed_noise=q,
        speed_scale_std=scale_sd if scale_sd > 0 else 1e-12,
        heading_bias_std=1e-12,
        initial_position_std=p0,
        sounding_std=sigma,
        tide_std=tide_sd,
    )
