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


def test_table_shows_stage_figures():
    from mocapkit.pipelines.bench import format_table

    text = format_table({"hybrid": {"fps": 120.5, "stages_ms": {"ik": 1.25, "io": 2.0}}})
    lines = text.splitlines()
    assert lines[0] == "hybrid" and "fps" in lines[1] and "120.500" in lines[1]
    assert lines[2].strip() == "stages_ms"
    assert lines[3].split() == ["ik", "1.250"] and lines[4].split() == ["io", "2.000"]


def test_hybrid_bench_refuses_zero_repeats():
    from mocapkit.pipelines.bench import bench_hybrid

    with pytest.raises(ConfigError, match="bench_hybrid: expected repeats >= 1, found 0"):
        bench_hybrid(repeats=0)


def test_hybrid_bench_says_when_it_falls_back_to_the_builtin_motions(tmp_path):
    from mocapkit.errors import InputWarning
    from mocapkit.pipelines.bench import BUILTIN_BENCH_CLIPS, bench_sessions

    for spec, (start, seconds) in BUILTIN_BENCH_CLIPS.items():  # cached: nothing rendered
        folder = tmp_path / f"{spec.split(':')[-1]}_{start:g}+{seconds:g}s_640x480"
        folder.mkdir()
        (folder / "session.json").write_text("{}")
    with pytest.warns(InputWarning, match=r"no-mocap: expected the clips 13_26\.bvh.*built-in"):
        sessions = bench_sessions(tmp_path, mocap_dir=tmp_path / "no-mocap")
    assert [s.name for s in sessions] == ["table-tennis_0+4s_640x480", "wave_0+4s_640x480"]
