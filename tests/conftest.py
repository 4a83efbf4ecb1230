"""Shared helpers: every statistical tolerance comes from the estimator's sampling error."""

import numpy as np
import pytest

from cmosnoise import load_config

#: number of standard errors a statistic may stray before a test fails.
#: 5 sigma: a correct implementation fails about once in 1.7 million runs.
Z = 5.0


def quiet_config(**sections):
    """A configuration with every stage off except those given (dict per section)."""
    base = {
        "prnu": {"enabled": False},
        "crosstalk": {"enabled": False},
        "shot_noise": {"enabled": False},
        "dark_current": {"enabled": False},
        "source_follower": {"enabled": False},
        "row_noise": {"enabled": False},
        "column_noise": {"enabled": False},
    }
    for k, v in sections.items():
        base[k] = {**base.get(k, {}), **v}
    return load_config(extra=base)


def assert_close(measured, expected, se, what=""):
    """|measured - expected| <= Z standard errors."""
    assert abs(measured - expected) <= Z * se, (
        f"{what}: measured {measured:.6g}, expected {expected:.6g}, "
        f"differs by {abs(measured - expected) / se:.1f} standard errors (allowed {Z})"
    )


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
