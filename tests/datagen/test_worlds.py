"""The scenario kind's draws: kinds as configured, sizes in range and skewed small, redraws."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from service.core.problem import problem_from_request
from service.core.schemas import ScheduleRequest
from service.datagen import worlds
from service.datagen.config import ScenarioConfig
from service.datagen.worlds import draw_world, robot_count
from service.scenarios import KINDS, World, generate


@given(
    low=st.integers(2, 50),
    span=st.integers(0, 200),
    seed=st.integers(0, 2**32 - 1),
)
def test_robot_counts_stay_in_range(low: int, span: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    counts = [robot_count(rng, low, low + span) for _ in range(20)]
    assert all(low <= n <= low + span for n in counts)


def test_robot_counts_are_skewed_to_the_small_end() -> None:
    rng = np.random.default_rng(0)
    counts = np.array([robot_count(rng, 5, 100) for _ in range(4000)])
    # log-uniform: the median is near sqrt(5 * 101) = 22; every size still occurs
    assert 18 <= np.median(counts) <= 27 and counts.min() == 5 and counts.max() == 100


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    kinds=st.lists(st.sampled_from(sorted(KINDS)), min_size=1, max_size=3, unique=True),
    seed=st.integers(0, 2**32 - 1),
)
def test_only_configured_kinds_are_drawn(kinds: list[str], seed: int) -> None:
    drawn = draw_world(ScenarioConfig(kinds=tuple(kinds), robots=(5, 8)), seed)
    assert drawn.kind in kinds and 5 <= drawn.robots <= 8
    assert drawn.drawn.keys() == KINDS[drawn.kind].choices.keys()
    world = generate(drawn.kind, drawn.robots, drawn.seed)  # the record rebuilds its world
    assert all(world.params[name] == value for name, value in drawn.drawn.items())
    assert problem_from_request(drawn.request).n_conflicts > 0


def test_a_seed_gives_the_same_world() -> None:
    cfg = ScenarioConfig(robots=(5, 30))
    first, again = draw_world(cfg, 11), draw_world(cfg, 11)
    assert first.world_record() == again.world_record()
    assert first.request.model_dump() == again.request.model_dump()


def test_refused_worlds_are_redrawn_and_counted(monkeypatch: pytest.MonkeyPatch) -> None:
    # The service refuses the first two worlds drawn (as it does paths that leave no order).
    calls: list[int] = []
    real = worlds.derived_request

    def refusing(world: World) -> ScheduleRequest | None:
        calls.append(1)
        return None if len(calls) <= 2 else real(world)

    cfg = ScenarioConfig(kinds=("floor_dense",), robots=(20, 40))
    first = draw_world(cfg, 0)
    monkeypatch.setattr(worlds, "derived_request", refusing)
    drawn = draw_world(cfg, 0)
    assert (first.redraws, drawn.redraws) == (0, 2) and drawn.seed != first.seed
    calls.clear()
    assert draw_world(cfg, 0) == drawn
    calls.clear()
    with pytest.raises(RuntimeError, match="no usable world"):
        draw_world(ScenarioConfig(cfg.kinds, cfg.robots, max_redraws=2), 0)


def test_unknown_kinds_and_empty_ranges_are_refused() -> None:
    with pytest.raises(ValueError, match="unknown"):
        ScenarioConfig(kinds=("floor_lava",))
    with pytest.raises(ValueError, match="robots"):
        ScenarioConfig(robots=(10, 5))
