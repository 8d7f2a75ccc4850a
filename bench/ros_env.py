"""The ROS environment every benchmark runs in: DDS on loopback, a domain of its own."""

import os


def confine_ros(default_domain_id: int) -> dict[str, str]:
    """Set (unless the caller did) LOCALHOST discovery and a domain id; return the env."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", str(default_domain_id))
    return dict(os.environ)
