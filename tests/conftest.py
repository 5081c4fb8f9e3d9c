"""Fixtures shared by every test. Shared functions and constants are in tests/helpers/."""

from __future__ import annotations

import pytest

from eskin_industrial import load_profile
from tests.helpers.leaks import no_leaks  # noqa: F401  (autouse: fails a test that leaks)
from tests.helpers.paths import PROFILES


@pytest.fixture(scope="session")
def paper_profile():
    return load_profile(PROFILES / "paper-5x5.toml")


@pytest.fixture(scope="session")
def hand_profile():
    return load_profile(PROFILES / "hand-4x5.toml")
