"""Private ROS domains for tests: each call leases a ROS_DOMAIN_ID that no other process using
softcath_ros.graph holds (parallel pytest runs, `softcath characterise`, benchmarks); conftest.py
releases the leases a test took when it ends."""
from softcath_ros.graph import graph_env, lease_domain

LEASES = []


def private_domain() -> int:
    lease = lease_domain()
    LEASES.append(lease)
    return lease.domain


def private_env(**extra) -> dict:
    """os.environ on a fresh private domain (loopback only, unbuffered), plus ``extra``."""
    return {**graph_env(private_domain()), **extra}
