"""Every kind: valid robots at several sizes, determinism, and a property test."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from service.scenarios import KINDS, generate
from tests.scenarios.checks import assert_clear_of_obstacles, assert_valid_robots


@pytest.mark.parametrize("n_robots", [2, 10, 100])
@pytest.mark.parametrize("kind", sorted(KINDS))
def test_every_kind_yields_valid_clear_robots(kind: str, n_robots: int) -> None:
    world = generate(kind, n_robots, seed=n_robots)
    assert world.kind == kind
    assert_valid_robots(world, n_robots)
    assert_clear_of_obstacles(world)


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_a_seed_gives_the_same_world(kind: str) -> None:
    first = generate(kind, 20, seed=7)
    assert generate(kind, 20, seed=7).to_json() == first.to_json()
    assert generate(kind, 20, seed=8).to_json() != first.to_json()


def test_unknown_kind_is_named() -> None:
    with pytest.raises(KeyError, match="floor_lava"):
        generate("floor_lava", 5, seed=0)


@pytest.mark.parametrize("n_robots", [1, 251])
def test_robot_count_outside_2_to_250_is_refused(n_robots: int) -> None:
    with pytest.raises(ValueError, match="n_robots"):
        generate("wh_two_way", n_robots, seed=0)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    kind=st.sampled_from(sorted(KINDS)),
    seed=st.integers(min_value=0, max_value=2**32 - 1),
    n_robots=st.integers(min_value=2, max_value=40),
)
def test_any_kind_seed_and_size_is_valid(kind: str, seed: int, n_robots: int) -> None:
    world = generate(kind, n_robots, seed)
    assert_valid_robots(world, n_robots)
    assert_clear_of_obstacles(world)
