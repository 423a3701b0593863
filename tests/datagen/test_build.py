"""Building datasets: deterministic by seed, resumable, held-out kinds absent, old formats kept."""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from service.datagen.build import (
    agree_where_proven,
    build_dataset,
    datasets_agree,
    main,
    solve_problem,
)
from service.datagen.config import DatasetConfig, config_dict
from service.datagen.executors import Executor
from service.learning.data import iter_problems, load_manifest, shard_path
from service.learning.generate import GeneratorConfig
from tests.datagen.conftest import HELD_OUT, TINY
from tests.imports import imported_modules


def test_a_seed_gives_the_same_dataset(tiny_dataset: Path, tmp_path: Path) -> None:
    again = build_dataset(TINY, tmp_path / "again", executor=Executor("local", workers=2))
    assert datasets_agree(tmp_path / "again", tiny_dataset)
    assert again["sha256"] == load_manifest(tiny_dataset)["sha256"]  # TINY proves every label
    other = build_dataset(replace(TINY, seed=1), tmp_path / "other", workers=1)
    assert other["sha256"] != again["sha256"]


def test_an_interrupted_build_resumes_to_the_same_bytes(tiny_dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "resumed"
    shutil.copytree(tiny_dataset, out)
    manifest = load_manifest(out)
    shard_path(out, 1).unlink()  # killed while shard 1 was being written:
    shard_path(out, 1).with_suffix(".tmp").write_text('{"index": 2, "trunc')
    (out / "manifest.json").write_text(json.dumps({**manifest, "complete": False}))
    kept = shard_path(out, 0).stat().st_mtime_ns
    resumed = build_dataset(TINY, out, workers=1)
    assert resumed == manifest
    assert shard_path(out, 0).stat().st_mtime_ns == kept  # done shards are not redone
    assert not shard_path(out, 1).with_suffix(".tmp").exists()


def test_a_dataset_of_other_settings_is_refused(tiny_dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "copy"
    shutil.copytree(tiny_dataset, out)
    with pytest.raises(SystemExit, match="other settings"):
        build_dataset(replace(TINY, top=3), out, workers=1)


def test_held_out_kinds_never_appear_and_are_counted(tiny_dataset: Path) -> None:
    records = list(iter_problems(tiny_dataset))
    kinds = [r["world"]["kind"] for r in records]
    assert set(kinds) <= set(TINY.scenario.kinds) and not set(kinds) & set(HELD_OUT)
    counts = load_manifest(tiny_dataset)["counts"]
    assert sum(counts["kinds"].values()) == TINY.problems
    assert counts["kinds"] == {k: kinds.count(k) for k in sorted(set(kinds))}
    assert counts["redraws"] == sum(r["world"]["redraws"] for r in records)
    assert counts["proven"] == dict.fromkeys(TINY.objectives, 1.0)


def test_the_published_kinds_keep_their_format() -> None:
    cfg = DatasetConfig(problems=1, top=2, generator=GeneratorConfig(max_robots=3))
    record = solve_problem(cfg, 0)
    assert list(record) == ["index", "seed", "request", "targets"]
    for targets in record["targets"].values():
        assert all(list(t) == ["a_first", "following", "cost", "optimal"] for t in targets)
    assert "scenario" not in config_dict(cfg)  # older manifests still match and resume


def test_the_command_line_holds_kinds_out(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "cli"
    main(
        ["--out", str(out), "--kind", "scenario", "--problems", "2", "--top", "1"]
        + ["--robots", "5", "6", "--objectives", "avg_completion", "--workers", "1"]
        + ["--hold-out", *HELD_OUT]
    )
    config = load_manifest(out)["config"]
    assert config["scenario"]["robots"] == [5, 6]
    assert not set(config["scenario"]["kinds"]) & set(HELD_OUT)
    assert json.loads(capsys.readouterr().out.splitlines()[-1])["problems"] == 2
    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path / "x"), "--kinds", "wh_one_way"])  # not the scenario kind
    assert not os.path.exists(tmp_path / "x")


def test_building_locally_does_not_need_ray() -> None:
    assert imported_modules("service.datagen.build", "ray") == []


def test_builds_agree_where_both_proved_a_label() -> None:
    record = solve_problem(TINY, 0)
    objective = TINY.objectives[0]
    proven, cut = (
        record["targets"][objective][0],
        {
            **record["targets"][objective][0],
            "optimal": False,
            "cost": 1e9,
        },
    )

    def with_targets(*targets: dict) -> dict:
        return {**record, "targets": {**record["targets"], objective: list(targets)}}

    assert agree_where_proven(with_targets(proven, proven), with_targets(proven))
    assert agree_where_proven(with_targets(proven, cut), with_targets(proven, proven))
    assert agree_where_proven(with_targets(cut), with_targets(proven))
    assert not agree_where_proven(with_targets({**proven, "cost": 0.0}), with_targets(proven))
    assert not agree_where_proven({**record, "seed": 1}, record)
