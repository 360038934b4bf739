"""Three hosts in network namespaces, a router each: one host's link down 15 s, twice.

Sim on A, locator on B, a subscriber on C. Every outage of B's link must end in detections
at C again, and the depth pictures A sends C must keep coming while B is away, but for one
known stall (below). Needs root and ``ip netns``; skipped with the reason otherwise. The
namespaces are removed even on failure.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from benchmarks import netlab

REASON = netlab.can_run()
pytestmark = pytest.mark.skipif(REASON is not None, reason=REASON or "")

# Zenoh 1.10 sets SO_LINGER 10 s on every TCP link, so when a router's lease (3 s) closes its
# link to a host that is gone, close() waits up to 10 s for the unacknowledged FIN, on one of
# the router's runtime threads. In about 1 outage in 15 that thread is one the A -> C path
# needs (seen blocked in sk_stream_wait_close: C's only "net" thread), and A -> C stops for
# 10.2-10.6 s from 3-4 s into the outage (README, "Several hosts"). Any other gap over 1.5 s
# fails: the benchmark's gaps are 0.2 to 1.0 s on a loaded machine but for the linger stall.
LINGER_STALL_S = (9.8, 11.5)
LINGER_STALL_FROM_S = (2.0, 6.0)


def known_linger_stall(gap_s: float, at_s: float) -> bool:
    """True for the one stall explained above: its length and when it begins."""
    return (
        LINGER_STALL_S[0] <= gap_s <= LINGER_STALL_S[1]
        and LINGER_STALL_FROM_S[0] <= at_s <= LINGER_STALL_FROM_S[1]
    )


@pytest.fixture(scope="module")
def lab() -> Iterator[netlab.Lab]:
    with netlab.Lab(subnet=7) as made:
        yield made


@pytest.mark.timeout(240)
def test_a_host_that_drops_off_for_15_s_comes_back_and_stalls_nobody(lab: netlab.Lab) -> None:
    """After each of two 15 s outages of B, C gets detections again; A -> C depth never stops
    for over 1.5 s, but for the known 10 s TCP linger stall."""
    with netlab.pipeline(lab) as probe:
        for run in range(2):
            recovered_s, gap_s, at_s = netlab.outage(lab, probe, "b", down_s=15.0)
            assert recovered_s is not None, f"run {run}: no detection at C after B came back"
            # The sim sends 5 a second (0.2 s apart). A fan-out held by B's dead link showed
            # as 0.7 to 9 s here.
            assert gap_s < 1.5 or known_linger_stall(gap_s, at_s), (
                f"run {run}: A -> C depth stopped {gap_s:.1f} s, {at_s:.1f} s into B's outage"
            )
