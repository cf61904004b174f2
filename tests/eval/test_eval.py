"""The eval package (tangraph.eval): its flat names, each the one of the module that defines it."""


def test_the_package_keeps_its_flat_names():
    import tangraph.eval
    from tangraph.eval import crb, metrics

    assert tangraph.eval.track_metrics is metrics.track_metrics
    assert tangraph.eval.posterior_crb is crb.posterior_crb
    assert {"anees_band", "format_figure", "position_nees", "track_metrics", "posterior_crb",
            "CramerRaoBound", "bound_rmse", "metrics_with_bound"} <= set(tangraph.eval.__all__)
