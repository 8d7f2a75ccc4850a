"""The ROS environment every benchmark runs in: DDS on loopback, a domain of its own.

The test suite takes domains 1 to 80 (tests/conftest.py), one per test; a benchmark
run beside it must never share one, or its messages reach a test's nodes. Benchmarks
take 81 to 98 (each its own number), the demo 99 (Makefile): all at most 101, whose
ports stay below Linux's ephemeral range.
"""

import os

BENCH_DOMAINS = range(81, 99)


def confine_ros(domain_id: int) -> dict[str, str]:
    """Set (unless the caller did) LOCALHOST discovery and ``domain_id`` (one of
    BENCH_DOMAINS); return the env."""
    if domain_id not in BENCH_DOMAINS:
        raise ValueError(f"a benchmark's domain is one of 81..98, got {domain_id}")
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", str(domain_id))
    return dict(os.environ)
