"""Private ROS domains for tests: each call leases a ROS_DOMAIN_ID that no other process using
softcath_ros.graph holds (parallel pytest runs, `softcath characterise`, benchmarks); conftest.py
releases the leases a test took when it ends.

The domain leased is the one this process has not used yet and that was leased least recently by
anyone (a lease opens its lock file for writing). A domain used a moment ago was a live hazard:
Fast DDS keeps shared-memory ports, and a client made soon after on the same domain read what an
earlier test's (killed) node had sent there, took that ghost for the node it waited for, and got its
old answers or sent it the command meant for the new node."""
import os
import sys

from softcath_ros.core.errors import SoftcathError
from softcath_ros.graph import DOMAIN_RANGE, last_leased, graph_env, lease_domain

LEASES = []
USED: set[int] = set()


def private_domain() -> int:
    lo, hi = DOMAIN_RANGE
    for domain in sorted(range(lo, hi + 1), key=lambda d: (d in USED, last_leased(d))):
        try:
            lease = lease_domain((domain, domain))
        except SoftcathError:
            continue          # held by another process
        USED.add(domain)
        LEASES.append(lease)
        return domain
    raise SoftcathError(f"no free ROS_DOMAIN_ID in {lo}..{hi}: every one is leased")


# The parent-death signal (prctl PR_SET_PDEATHSIG) survives the exec: the node is killed when the test
# process dies; a parent gone before the signal was set ends the child at once.
_TIED = ("import ctypes, os, signal, sys; ctypes.CDLL(None).prctl(1, int(signal.SIGKILL), 0, 0, 0); "
         "os.getppid() == int(sys.argv[1]) or os._exit(1); os.execv(sys.argv[2], sys.argv[2:])")


def tied(argv) -> list[str]:
    """``argv`` (its program as a full path) run so that the process dies with this test process
    (Linux's parent-death signal; elsewhere unchanged). A run that is killed or times out leaves no
    node behind: such orphans, on a domain whose lease ended with their run, answered later runs'
    commands as their own node's."""
    return [sys.executable, "-c", _TIED, str(os.getpid()), *argv] if sys.platform.startswith("linux") else list(argv)


def private_env(**extra) -> dict:
    """os.environ on a fresh private domain (loopback only, unbuffered), plus ``extra``."""
    return {**graph_env(private_domain()), **extra}
