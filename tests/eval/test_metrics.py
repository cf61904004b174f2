"""Track metrics (tangraph.eval.metrics): the position NEES, a track's RMSE and errors, the ANEES
band, and the bound's RMSE with a track's RMSE over it."""

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.eval import (
    CramerRaoBound,
    anees_band,
    bound_rmse,
    metrics_with_bound,
    position_nees,
    track_metrics,
)
from tangraph.track import Track


def _track(pose, cov=None):
    pose = np.asarray(pose, float)
    return Track(time=np.arange(len(pose), dtype=float), pose=pose, covariance=cov)


def test_position_nees_matches_the_direct_solve_and_is_nan_where_unknown():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(5, 2, 2))
    cov = np.full((5, 3, 3), np.nan)
    cov[:, :2, :2] = a @ np.swapaxes(a, 1, 2) + 0.1 * np.eye(2)
    cov[3, :2, :2] = np.nan  # unknown
    cov[4, :2, :2] = [[1.0, 1.0], [1.0, 1.0]]  # singular
    pose = rng.normal(size=(5, 3))
    got = position_nees(_track(pose, cov), np.zeros((5, 3)))
    for k in range(3):
        e = pose[k, :2]
        assert got[k] == pytest.approx(e @ np.linalg.solve(cov[k, :2, :2], e), rel=1e-12)
    assert np.isnan(got[3]) and np.isnan(got[4])


def test_track_metrics_on_a_known_error():
    truth = np.zeros((4, 3))
    pose = np.array([[3.0, 4.0, 0], [0, 0, 0], [0, 0, 0], [0, 1.0, 0]])
    m = track_metrics(_track(pose), truth)
    assert m["rmse"] == pytest.approx(np.sqrt((25 + 1) / 4))
    assert m["final_error"] == 1.0 and m["max_error"] == 5.0 and np.isnan(m["anees"])
    assert track_metrics(_track(pose), truth, skip=1)["max_error"] == 1.0
    with pytest.raises(TangraphError, match="skip=4"):
        track_metrics(_track(pose), truth, skip=4)
    with pytest.raises(TangraphError, match="shape"):
        track_metrics(_track(pose), np.zeros((3, 3)))


def test_anees_band_covers_an_honest_covariance_at_its_probability():
    # 4000 seeded repetitions of an ANEES over 20 honest 2-D errors: the band must hold 95 % of them
    # within three Monte Carlo standard errors (sqrt(0.95 * 0.05 / 4000) = 0.0034).
    rng = np.random.default_rng(7)
    lo, hi = anees_band(20)
    cov = np.array([[4.0, 1.5], [1.5, 2.0]])
    errors = rng.multivariate_normal([0, 0], cov, size=(4000, 20))
    nees = np.einsum("rka,ab,rkb->rk", errors, np.linalg.inv(cov), errors)
    inside = np.mean((nees.mean(axis=1) >= lo) & (nees.mean(axis=1) <= hi))
    assert abs(inside - 0.95) < 3 * np.sqrt(0.95 * 0.05 / 4000)
    assert lo < 2 < hi
    with pytest.raises(TangraphError):
        anees_band(0)


def test_bound_rmse_and_the_ratio_to_a_track_rmse():
    cov = np.array([np.diag([8.0, 1.0]), np.diag([2.0, 2.0])])
    bound = CramerRaoBound(cov, np.eye(2), 0.1, "smoother", n_soundings=5)
    assert bound_rmse(bound) == pytest.approx(np.sqrt(6.5))
    assert bound_rmse(bound, skip=1) == pytest.approx(2.0)
    np.testing.assert_allclose(bound.drms, [3.0, 2.0])
    out = metrics_with_bound({"rmse": 4.0, "anees": 1.0}, bound, skip=1)
    assert out == {"rmse": 4.0, "anees": 1.0, "pcrb": 2.0, "rmse_over_pcrb": 2.0}
    with pytest.raises(TangraphError, match="skip=2"):
        bound_rmse(bound, skip=2)
    with pytest.raises(TangraphError, match="rmse"):
        metrics_with_bound({"anees": 1.0}, bound)
    assert not bound.position_cov.flags.writeable


def test_robust_spread_is_a_gaussians_std_and_holds_against_a_few_outliers():
    from tangraph.eval.metrics import robust_spread

    x = np.random.default_rng(3).normal(0.5, 2.0, 100_000)
    # the MAD's std error for a Gaussian: about 1.67 sigma / sqrt(n); 5 of them
    tolerance = 5 * 1.67 * 2.0 / np.sqrt(x.size)
    assert abs(robust_spread(x) - 2.0) < tolerance
    assert abs(robust_spread(x - 0.5, about=0.0) - 2.0) < tolerance
    assert robust_spread(x, about=0.0) > robust_spread(x)  # about 0, off the median, is wider
    x[:1000] = 1e6  # 1 % wild values move it by about 1 %
    assert abs(robust_spread(x) - 2.0) < 0.03 * 2.0 + tolerance
    assert np.isnan(robust_spread([]))
