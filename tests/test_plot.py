"""Figures (tangraph.plot): a TAP fix drawn with its regions, its covariance ellipse and the truth."""

from __future__ import annotations

from tangraph.matching.tap import TapConfig, tap_fix
from tests.matching.tap_cases import rough_map, survey_on


def test_plot_fix_draws_the_regions_and_the_ellipse(tmp_path):
    from matplotlib.figure import Figure

    from tangraph.plot import plot_fix

    m = rough_map(2)
    s = survey_on(m, noise=0.3, seed=2)
    fix = tap_fix(s, m, 9, 10, TapConfig(half_width=40.0, step=2.5))
    fig = Figure()
    ax = plot_fix(fix, fig.add_subplot(), truth=s.true_pose[9, :2])
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any(label.startswith("calibrated 95%") for label in labels)
    assert "95% covariance ellipse" in labels and "truth" in labels
    fig.savefig(tmp_path / "fix.png")
    assert (tmp_path / "fix.png").stat().st_size > 10_000
