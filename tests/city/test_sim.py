"""The transition rules of the paper on tiny hand-built graphs."""

from __future__ import annotations

import numpy as np
import pytest

from city.graph import City
from city.sim import PICKUP, FleetSim, Requests, decisions_hash
from tests.conftest import line_city


def reqs(*rows: tuple[int, int, int]) -> Requests:
    p, d, e = zip(*rows)
    return Requests.sorted(np.array(p), np.array(d), np.array(e))


def test_city_paths_on_a_line(line5: City) -> None:
    assert line5.dist[0, 4] == 4 and line5.dist[4, 0] == 4
    assert line5.next_hop[0, 4] == 1 and line5.next_hop[4, 0] == 3 and line5.next_hop[2, 2] == 2
    assert line5.dist_m[0, 4] == pytest.approx(400.0)


def test_city_matrices_are_row_major(line5: City) -> None:
    # The rollout's nearest-request scans read one node's distances as a contiguous row.
    assert line5.dist.flags.c_contiguous and line5.next_hop.flags.c_contiguous


def test_one_way_ring_routes_around() -> None:
    ring = line_city(4, two_way=False)
    assert ring.dist[1, 0] == 3
    assert [int(ring.next_hop[1, 0]), int(ring.next_hop[2, 0]), int(ring.next_hop[3, 0])] == [2, 3, 0]


def test_pickup_then_busy_then_free(line5: City) -> None:
    sim = FleetSim(line5, reqs((1, 4, 0)), np.array([1]))
    assert sim.step(np.array([PICKUP])) == 0
    assert sim.state.tau[0] == 3 and sim.state.pos[0] == 1 and sim.state.dest[0] == 4
    for expected_pos in (2, 3, 4):
        sim.step(sim.busy_controls())
        assert sim.state.pos[0] == expected_pos
    assert sim.state.tau[0] == 0 and sim.state.dest[0] == -1


def test_pickup_of_trip_within_one_intersection_takes_one_step(line5: City) -> None:
    sim = FleetSim(line5, reqs((2, 2, 0)), np.array([2]))
    sim.step(np.array([PICKUP]))
    assert sim.state.tau[0] == 1
    sim.step(sim.busy_controls())
    assert sim.state.tau[0] == 0 and sim.state.pos[0] == 2


def test_busy_taxi_must_follow_its_path(line5: City) -> None:
    sim = FleetSim(line5, reqs((1, 4, 0)), np.array([1]))
    sim.step(np.array([PICKUP]))
    with pytest.raises(ValueError, match=r"controls\[0\]: busy taxi must take next hop 2"):
        sim.step(np.array([0]))


def test_move_must_be_a_neighbour(line5: City) -> None:
    sim = FleetSim(line5, reqs((4, 0, 0)), np.array([0]))
    with pytest.raises(ValueError, match="not a neighbour"):
        sim.step(np.array([3]))


def test_conflicting_pickups_earlier_agent_wins(line5: City) -> None:
    sim = FleetSim(line5, reqs((2, 0, 0)), np.array([2, 2]))
    assert sim.step(np.array([PICKUP, PICKUP])) == 0
    assert sim.state.tau.tolist() == [2, 0]
    assert sim.state.picked_at.tolist() == [0]


def test_two_requests_two_pickers_oldest_first(line5: City) -> None:
    sim = FleetSim(line5, reqs((2, 0, 0), (2, 4, 1)), np.array([2, 2]))
    sim.step(np.array([2, 2]))
    sim.step(np.array([PICKUP, PICKUP]))
    assert sim.state.dest.tolist() == [0, 4]


def test_pickup_without_request_stays(line5: City) -> None:
    sim = FleetSim(line5, reqs((4, 0, 0)), np.array([1]))
    assert sim.step(np.array([PICKUP])) == 1
    assert sim.state.pos[0] == 1 and sim.state.tau[0] == 0


def test_request_not_visible_before_entry(line5: City) -> None:
    sim = FleetSim(line5, reqs((1, 3, 2)), np.array([1]))
    assert sim.step(np.array([PICKUP])) == 0  # not entered: nothing to pick, no cost
    assert sim.state.picked_at[0] == -1
    assert sim.observe().req_index.size == 0


def test_cost_counts_waiting_minutes_up_to_horizon(line5: City) -> None:
    # Request A (entry 0) is served at step 3 after driving 0->1->2->3; B (entry 1) is never served.
    sim = FleetSim(line5, reqs((3, 4, 0), (0, 1, 1)), np.array([0]))
    costs = [sim.step(np.array([c])) for c in (1, 2, 3)]
    costs.append(sim.step(np.array([PICKUP])))
    costs.append(sim.step(sim.busy_controls()))
    assert costs == [1, 2, 2, 1, 1]
    res = sim.result(costs, np.zeros((5, 1)), [0.0] * 5)
    assert res.total_cost == 7 and res.served == 1 and res.outstanding_end == 1
    # Total cost equals the sum over requests of minutes waited (B waited from 1 to 5).
    assert res.total_cost == (3 - 0) + (5 - 1)


def test_decisions_hash_changes_with_controls() -> None:
    a = np.zeros((3, 2), dtype=np.int32)
    b = a.copy()
    b[2, 1] = 1
    assert decisions_hash(a) == decisions_hash(a.copy()) != decisions_hash(b)


def test_requests_must_be_sorted() -> None:
    with pytest.raises(ValueError, match="sorted"):
        Requests(np.array([0, 1]), np.array([1, 0]), np.array([3, 1]))
