"""The stress suite's hypothesis budget: ``ci`` (default) or ``exhaustive``, chosen by ``EIGS_STRESS``.

``ci``: few examples per test, no deadline, derandomized (the same examples on every run, so CI is reproducible
and a failure reproduces locally). ``exhaustive`` (``EIGS_STRESS=exhaustive``): 50× the examples, random
generation (a new search each run), for a long local or nightly search. A test states its CI budget with
``@stress(n)``; the profiles are registered with hypothesis as ``eigs-stress-ci`` and ``eigs-stress-exhaustive``
and applied per test, so loading this module never changes the settings of hypothesis tests elsewhere.
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

PROFILE = os.environ.get("EIGS_STRESS", "ci").strip().lower() or "ci"
if PROFILE not in ("ci", "exhaustive"):
    raise ValueError(f"EIGS_STRESS must be 'ci' or 'exhaustive', got {PROFILE!r}")
EXHAUSTIVE_FACTOR = 50

settings.register_profile(
    "eigs-stress-ci",
    deadline=None,
    derandomize=True,
    database=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
settings.register_profile(
    "eigs-stress-exhaustive",
    deadline=None,
    derandomize=False,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
_PARENT = settings.get_profile(f"eigs-stress-{PROFILE}")


def stress(ci_examples: int) -> settings:
    """Settings decorator: ``ci_examples`` examples in the ``ci`` profile, 50× that in ``exhaustive``."""
    n = ci_examples if PROFILE == "ci" else ci_examples * EXHAUSTIVE_FACTOR
    return settings(_PARENT, max_examples=n)
