"""Sweeps run serially: records, resuming, the results folder, statistics and plots."""

import json

import numpy as np
import pytest

from agents.sweep import make_tasks, read_records, run_sweep, spec_from_dict, summarize_sweep
from agents.sweep.aggregate import COLUMNS, summary_markdown
from agents.sweep.plots import plot_sweep, success_curves
from agents.sweep.store import EPISODES_FILE

FLAT = "roughwalk/CompassGaitFlat-v0"
ROUGH = "roughwalk/CompassGaitRough-v0"
# 1.5 s episodes: the passive walker trips after one footstep, PD walks
SHORT = {"max_episode_steps": 300}


def small_spec(**changes):
    data = {
        "name": "small",
        "episodes": 3,
        "policies": ["passive", "pd"],
        "envs": [{"name": "rough", "id": ROUGH, "kwargs": SHORT, "sweep": {"difficulty": [1, 2]}}],
    }
    data.update(changes)
    return spec_from_dict(data)


def by_key(records):
    return sorted(records, key=lambda r: (r["cell"], r["seed"]))


@pytest.fixture(scope="module")
def small_sweep(tmp_path_factory):
    """The small grid run serially once: (folder, result)."""
    out = tmp_path_factory.mktemp("sweep") / "small"
    return out, run_sweep(small_spec(), out)


def test_records_and_summary(small_sweep):
    out, result = small_sweep
    assert (result.ran, result.skipped) == (12, 0)
    records = read_records(out / EPISODES_FILE)
    assert len(records) == 12
    assert {r["seed"] for r in records} == {1_001_000, 1_001_001, 1_001_002}
    r = next(r for r in records if r["cell"] == "pd/rough[difficulty=2]")
    assert r["env_kwargs"] == {"max_episode_steps": 300, "difficulty": 2}
    assert r["policy"] == "pd" and r["swept"] == {"difficulty": 2}
    cells = {c["cell"]: c for c in result.summary["cells"]}
    passive = cells["passive/rough[difficulty=1]"]
    assert passive["successes"] == 0 and passive["failure_reasons"] == {"trip": 3}
    assert passive["success_rate_ci"] == pytest.approx([0.0, 0.5615], abs=1e-4)
    pd = cells["pd/rough[difficulty=1]"]
    assert pd["success_rate"] == 1.0 and pd["failure_reasons"] == {}
    assert all("policy_error" in r for r in records)  # each episode says if its policy broke
    assert pd["policy_errors"] == passive["policy_errors"] == 0
    lo, hi = pd["mean_distance_ci"]
    assert lo <= pd["mean_distance"] <= hi
    # the cost of transport is total work over total m g distance, as evaluate reports it
    mine = [r for r in records if r["cell"] == "pd/rough[difficulty=1]"]
    work = sum(r["motor_work"] for r in mine)
    mgd = sum(r["total_mass"] * r["gravity"] * r["distance"] for r in mine)
    assert pd["cost_of_transport"] == pytest.approx(work / mgd)
    saved = json.loads((out / "summary.json").read_text())
    assert saved["cells"] == result.summary["cells"]
    csv_lines = (out / "summary.csv").read_text().splitlines()
    assert len(csv_lines) == 5 and "success_rate_low" in csv_lines[0]
    # the Markdown table: a header, its rule and one row per cell, in grid order
    md = (out / "summary.md").read_text().splitlines()
    assert len(md) == 6 and md[0] == "| " + " | ".join(COLUMNS) + " |"
    row = next(line for line in md if line.startswith("| passive | rough (difficulty=1) |"))
    assert "| 0 [0, 56] (0/3) |" in row and row.endswith("| trip 3 |")
    assert [p.name for p in result.plots] == ["success_rough_difficulty.png"]


def test_resume_runs_only_missing_episodes(small_sweep, tmp_path):
    src, _ = small_sweep
    out = tmp_path / "resumed"
    out.mkdir()
    lines = (src / EPISODES_FILE).read_text().splitlines(keepends=True)
    (out / "spec.json").write_text((src / "spec.json").read_text())
    # 5 finished episodes and one cut short by an interruption
    (out / EPISODES_FILE).write_text("".join(lines[:5]) + lines[5][:40])
    result = run_sweep(small_spec(), out, plot=False)
    assert (result.ran, result.skipped) == (7, 5)
    assert by_key(read_records(out / EPISODES_FILE)) == by_key(read_records(src / EPISODES_FILE))
    again = run_sweep(small_spec(), out, plot=False)
    assert (again.ran, again.skipped) == (0, 12)
    assert again.summary["cells"] == result.summary["cells"]


def test_another_spec_in_the_folder_is_refused_unless_overwrite(small_sweep, tmp_path):
    src, _ = small_sweep
    out = tmp_path / "other"
    out.mkdir()
    for name in ("spec.json", EPISODES_FILE):
        (out / name).write_text((src / name).read_text())
    other = small_spec(policies=["passive"], episodes=2)
    with pytest.raises(ValueError, match="holds the results of another sweep spec"):
        run_sweep(other, out)
    assert len(read_records(out / EPISODES_FILE)) == 12  # untouched
    result = run_sweep(other, out, overwrite=True, plot=False)
    assert (result.ran, result.skipped) == (4, 0)
    assert len(read_records(out / EPISODES_FILE)) == 4


def test_damaged_records_are_an_error(tmp_path):
    path = tmp_path / EPISODES_FILE
    path.write_text('{"cell": "a", "seed": 1}\nnot json\n{"cell": "a", "seed": 2}\n')
    with pytest.raises(ValueError, match="line 2: not an episode record"):
        read_records(path)


def test_records_do_not_depend_on_task_size(small_sweep, tmp_path):
    _, result = small_sweep
    spec = small_spec(policies=["pd"], episodes=3)
    one = run_sweep(spec, tmp_path / "one", chunk=1, plot=False)
    assert len(make_tasks(spec.cells(), spec.seeds, set(), 1)) == 6
    cells = {c["cell"]: c for c in result.summary["cells"]}
    for c in one.summary["cells"]:
        assert c == cells[c["cell"]]


def test_bad_options_before_anything_is_written(tmp_path):
    with pytest.raises(ValueError, match="--workers and --address apply to --backend ray"):
        run_sweep(small_spec(), tmp_path / "x", workers=2)
    with pytest.raises(ValueError, match="--backend: unknown backend 'dask'"):
        run_sweep(small_spec(), tmp_path / "x", backend="dask")
    with pytest.raises(ValueError, match="--chunk: must be an integer >= 1, got 0"):
        run_sweep(small_spec(), tmp_path / "x", chunk=0)
    bad = small_spec(envs=[{"id": FLAT, "kwargs": {"bogus": 1}}])
    with pytest.raises(ValueError, match="bogus"):
        run_sweep(bad, tmp_path / "x")
    assert not (tmp_path / "x").exists()


def fake_records(cell, successes, n):
    return [
        {
            "cell": cell.key,
            "seed": 1_001_000 + k,
            "success": k < successes,
            "failure": None if k < successes else "trip",
            "footsteps": 10 + k,
            "distance": 1.0 + 0.1 * k,
            "speed": 0.2,
            "motor_work": 0.5,
            "total_mass": 4.8,
            "gravity": 9.81,
        }
        for k in range(n)
    ]


def test_across_training_seeds():
    envs = [{"name": n, "id": FLAT} for n in ("a", "b")]
    policies = [{"policy": "pd", "name": f"good s{i}", "group": "good"} for i in range(3)]
    policies += [{"policy": "passive", "name": f"bad s{i}", "group": "bad"} for i in range(3)]
    spec = spec_from_dict({"episodes": 20, "policies": policies, "envs": envs})
    records = []
    for c in spec.cells():
        good = c.group == "good"
        records += fake_records(c, 18 if good else 4 + len(records) % 3, 20)
    summary = summarize_sweep(spec.cells(), records)
    assert summary["cells"][0]["success_rate_ci"] == pytest.approx([0.699, 0.972], abs=1e-3)
    groups = {g["group"]: g for g in summary["across_seeds"]["groups"]}
    assert groups["good"]["iqm"] == pytest.approx(0.9)
    assert groups["good"]["iqm_ci"] == pytest.approx([0.9, 0.9])
    assert (groups["good"]["runs"], groups["good"]["tasks"]) == (3, 2)
    lo, hi = groups["bad"]["iqm_ci"]
    assert lo <= groups["bad"]["iqm"] <= hi < 0.9
    (pair,) = summary["across_seeds"]["improvement"]
    assert (pair["x"], pair["y"], pair["p_x_better"]) == ("good", "bad", 1.0)
    # the Markdown summary: 12 cells, then the groups' IQM and the pair's improvement
    md = summary_markdown(summary).splitlines()
    assert md[2].startswith("| good s0 | a | 90 [70, 97] (18/20) | ")
    assert "| good | 2 | 3 | 90 [90, 90] |" in md
    assert "| good | bad | 1.00 [1.00, 1.00] |" in md
    # no groups: no across-seeds part
    plain = spec_from_dict({"episodes": 20, "policies": ["pd"], "envs": envs})
    one = fake_records(plain.cells()[0], 5, 20)
    assert "across_seeds" not in summarize_sweep(plain.cells(), one)


def test_success_plot_has_one_curve_per_policy(tmp_path):
    spec = small_spec(envs=[{"name": "r", "id": ROUGH, "sweep": {"difficulty": [0.5, 2, 1]}}])
    records = []
    for i, c in enumerate(spec.cells()):
        records += fake_records(c, i, 5)
    cells = summarize_sweep(spec.cells(), records)["cells"]
    curves = success_curves(cells, "r", "difficulty")
    assert list(curves) == ["passive", "pd"]
    x, y, lo, hi = np.array(curves["pd"]).T
    assert x.tolist() == [0.5, 1, 2]  # sorted by the swept value
    assert y.tolist() == [0.6, 1.0, 0.8]
    assert np.all((lo <= y) & (y <= hi))
    (png,) = plot_sweep(cells, tmp_path)
    assert png.name == "success_r_difficulty.png" and png.stat().st_size > 10_000
