"""Monte Carlo experiments: seeded runs of one function over many configs, on Dask."""

from tangraph.experiments.runner import RESERVED_COLUMNS, rerun, run_many, run_rng, run_seed_sequence

__all__ = ["RESERVED_COLUMNS", "rerun", "run_many", "run_rng", "run_seed_sequence"]
