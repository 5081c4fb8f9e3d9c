"""Shared settings of the fuzz tests (tests/bus/test_fuzz_*.py, tests/outputs/plc/test_fuzz_plc.py).

Every fuzz test runs the same examples on every run (``derandomize``, no example
database), so a failure in CI reproduces locally; budgets are small enough that all
fuzz files together take well under half a minute.
"""

from __future__ import annotations

from hypothesis import HealthCheck, settings


def fuzz(max_examples: int) -> settings:
    """Reproducible hypothesis settings with a given budget."""
    return settings(
        max_examples=max_examples,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )
