"""Benchmark plumbing: JSON structure, saving, CLI; never timing."""

from __future__ import annotations

import json

import pytest

from mocapkit.cli.main import main
from mocapkit.errors import ConfigError, UnknownNameError
from mocapkit.pipelines.bench import bench_kinematics, run_benchmarks, save_results


def test_kinematics_figures_structure():
    res = bench_kinematics(repeats=1, n_poses=50, n_jacobians=10)
    for key in ("fk_poses_per_s", "jacobians_per_s", "fk_poses_per_s_min", "jacobians_per_s_min"):
        assert isinstance(res[key], float) and res[key] > 0
    assert res["n_poses"] == 50 and res["n_jacobians"] == 10 and res["n_effectors"] == 5


def test_save_results_writes_one_json_per_benchmark(tmp_path):
    results = {"kinematics": bench_kinematics(repeats=1, n_poses=20, n_jacobians=5)}
    (path,) = save_results(results, tmp_path / "results")
    data = json.loads(path.read_text())
    assert path.name == "kinematics.json"
    assert data["kinematics"]["n_poses"] == 20 and "python" in data["machine"]


def test_cli_prints_json(capsys):
    assert main(["bench", "kinematics", "--json", "--repeats", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"kinematics"} and out["kinematics"]["jacobians_per_s"] > 0


def test_bad_arguments_raise():
    with pytest.raises(UnknownNameError, match="unknown benchmark 'fast'"):
        run_benchmarks("fast")
    with pytest.raises(ConfigError, match="--repeats: expected at least 1, found 0"):
        run_benchmarks("kinematics", repeats=0)
    with pytest.raises(ConfigError, match="bench_kinematics: expected repeats"):
        bench_kinematics(repeats=0)
