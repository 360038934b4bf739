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

GAP_LIMIT_S = 1.5
"""The longest A -> C depth gap allowed while B is away (the sim sends 5 a second, 0.2 s
apart). A fan-out held by B's dead link showed as 0.7 to 9 s here, and a router thread held by
a lingering close of B's link as 10 s, until routers closed their links without lingering."""


@pytest.fixture(scope="module")
def lab() -> Iterator[netlab.Lab]:
    with netlab.Lab(subnet=7) as made:
        yield made


@pytest.mark.timeout(240)
def test_a_host_that_drops_off_for_15_s_comes_back_and_stalls_nobody(lab: netlab.Lab) -> None:
    """After each of two 15 s outages of B, C gets detections again; A -> C depth never stops
    for over 1.5 s."""
    with netlab.pipeline(lab) as probe:
        for run in range(2):
            recovered_s, gap_s, at_s = netlab.outage(lab, probe, "b", down_s=15.0)
            assert recovered_s is not None, f"run {run}: no detection at C after B came back"
            assert gap_s < GAP_LIMIT_S, (
                f"run {run}: A -> C depth stopped {gap_s:.1f} s, {at_s:.1f} s into B's outage"
            )
