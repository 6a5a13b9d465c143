"""avp.run and avp.bench: the command line's folders, the same numbers."""

import json
import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import avp
from conftest import SCENARIO, VIEWS, run_cli

# Columns that hold wall-clock times: they differ between any two runs.
def timing(name):
    return name.endswith("_ms") or name.endswith("_s") or name.endswith("seconds")


def assert_same_table(a, b):
    assert list(a) == list(b)
    for name in a:
        if timing(name):
            continue
        if a[name].dtype.kind == "f":
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)
        else:
            assert a[name].tolist() == b[name].tolist(), name


def test_an_episode_from_python_equals_avp_run(avp_binary, tmp_root, episode):
    cli = tmp_root / "cli-run"
    run_cli(avp_binary, "run", "--scenario", SCENARIO, "--seed", 2, "--views", VIEWS, "--out", cli)
    assert_same_table(avp.read_table(cli / "metrics.csv"), episode.metrics)
    with open(cli / "record.json") as f:
        record = json.load(f)
    assert record["config"] == episode.record["config"]
    assert record["final_metrics"] == episode.record["final_metrics"]
    assert record["fruits"] == episode.record["fruits"]
    assert len(episode.metrics["view"]) == VIEWS
    assert 0.0 < episode.final["f1"] <= 1.0
    # The per-fruit table: one row per true fruit, as record.json lists them.
    assert len(episode.fruits["found"]) == len(record["fruits"]) > 0
    assert episode.fruits["found"].dtype == bool


def test_keys_sections_and_set_items_are_the_cli_keys(tmp_root):
    yaml = avp.effective_config(scenario=SCENARIO, seed=4, episode={"views": 5},
                                set={"map.grid.voxel_size_m": 0.01, "planner": "predefined"})
    assert f"scenario: {SCENARIO}" in yaml
    assert "seed: 4" in yaml and "views: 5" in yaml and "voxel_size_m: 0.01" in yaml
    assert "name: predefined" in yaml
    # A dict of the printed tree reads back.
    assert avp.effective_config({"seed": 4, "episode": {"views": 5}}, scenario=SCENARIO,
                                set={"map.grid.voxel_size_m": 0.01, "planner": "predefined"}) == yaml


def test_bad_configurations_raise_value_errors_naming_the_key(tmp_root):
    with pytest.raises(ValueError, match="no_such_key"):
        avp.effective_config(no_such_key=1)
    with pytest.raises(ValueError, match="tomatoo"):
        avp.effective_config(scenario="tomatoo")
    with pytest.raises(ValueError, match="views"):
        avp.effective_config(episode={"views": -3})
    with pytest.raises(FileNotFoundError, match="missing.yaml"):
        avp.run(tmp_root / "never", config=tmp_root / "missing.yaml")
    with pytest.raises(TypeError, match="config"):
        avp.effective_config(seed=object())


def test_a_folder_holding_results_is_refused_without_force(episode):
    with pytest.raises(RuntimeError, match="already holds the results.*--force"):
        avp.run(episode.folder, scenario=SCENARIO, seed=2, episode={"views": VIEWS},
                progress=False)


def test_progress_lines_are_the_clis(tmp_root):
    lines = []
    avp.run(tmp_root / "progress", scenario=SCENARIO, seed=1, episode={"views": 2},
            progress=lines.append)
    assert lines[0].startswith("view 1/2  eye (")
    assert "F1 " in lines[0] and "elapsed" in lines[1]
    assert "final F1" in lines[-1]


def test_an_exception_in_the_progress_function_ends_the_run_with_it(tmp_root):
    def boom(line):
        raise RuntimeError("progress function failed")

    with pytest.raises(RuntimeError, match="progress function failed"):
        avp.run(tmp_root / "boom", scenario=SCENARIO, seed=1, episode={"views": 2},
                progress=boom)


def test_ctrl_c_stops_the_episode_and_keeps_its_results(tmp_root):
    """A child Python process runs a long episode; SIGINT after its first view ends it with
    KeyboardInterrupt and a run folder whose record says 'interrupted'."""
    out = tmp_root / "interrupted"
    script = textwrap.dedent(f"""
        import sys, avp
        def line(text):
            print(text, flush=True)
        try:
            avp.run({str(out)!r}, scenario={SCENARIO!r}, seed=1, episode={{"views": 30}},
                    progress=line)
        except KeyboardInterrupt as e:
            print("KeyboardInterrupt:", e, flush=True)
            sys.exit(3)
        sys.exit(0)
    """)
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True,
                         env=os.environ.copy())
    first = p.stdout.readline()
    assert first.startswith("view 1/30"), first
    p.send_signal(signal.SIGINT)
    rest = p.stdout.read()
    assert p.wait(timeout=120) == 3, rest
    assert "interrupted" in rest
    with open(out / "record.json") as f:
        record = json.load(f)
    assert record["end"] == "interrupted"
    assert 1 <= len(record["steps"]) < 30


def test_a_bench_from_python_equals_avp_bench(avp_binary, tmp_root):
    cli = tmp_root / "cli-bench"
    run_cli(avp_binary, "bench", "--scenarios", SCENARIO, "--planners", "avp-nbv,predefined",
            "--seeds", 2, "--views", 2, "--jobs", 2, "--out", cli)
    py = avp.bench(tmp_root / "py-bench", scenarios=[SCENARIO], planners=["avp-nbv", "predefined"],
                   seeds=2, set={"episode.views": 2}, jobs=2, progress=False)
    assert py.info["episodes"] == 4 and py.info["failed"] == 0
    assert_same_table(avp.read_table(cli / "summary.csv"), py.summary)
    runs = py.runs()
    assert sorted(set(runs["planner"].tolist())) == ["avp-nbv", "predefined"]
    assert len(runs["seed"]) == 4
    one = py.run(SCENARIO, "predefined", 1)
    assert_same_table(one.metrics,
                      avp.read_table(cli / "runs" / SCENARIO / "predefined" / "seed-1" / "metrics.csv"))


def test_bench_arguments_are_checked(tmp_root):
    with pytest.raises(ValueError, match="seeds"):
        avp.bench(tmp_root / "b0", scenarios=[SCENARIO], planners=["random"], seeds=0)
    with pytest.raises(ValueError, match="nope"):
        avp.bench(tmp_root / "b1", scenarios=[SCENARIO], planners=["nope"], seeds=1)


def test_a_segmenter_that_fails_the_episode_fails_the_run_as_the_cli(tmp_root):
    """A segmentation service that is not there: the episode ends as segmenter-fault, its results
    written, and avp.run raises as `avp run` exits 1."""
    out = tmp_root / "no-service"
    with pytest.raises(RuntimeError, match="segmenter fault.*127.0.0.1:9"):
        avp.run(out, scenario=SCENARIO, seed=1, segmenter="remote://127.0.0.1:9/oracle",
                episode={"views": 2}, progress=False)
    with open(out / "record.json") as f:
        assert json.load(f)["end"] == "segmenter-fault"


def test_ctrl_c_stops_a_bench_and_resume_runs_the_rest(tmp_root):
    """SIGINT after a bench's first finished episode: KeyboardInterrupt, the running episode's
    folder failed, no new one started; avp.bench(..., resume=True) then runs what is left."""
    out = tmp_root / "interrupted-bench"
    args = dict(scenarios=[SCENARIO], planners=["predefined"], seeds=4,
                set={"episode.views": 4}, jobs=1)
    script = textwrap.dedent(f"""
        import sys, avp
        try:
            avp.bench({str(out)!r}, **{args!r})
        except KeyboardInterrupt as e:
            print("KeyboardInterrupt:", e, flush=True)
            sys.exit(3)
    """)
    env = dict(os.environ, CI="1")  # progress as lines
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=env)
    for line in p.stderr:
        if line.startswith("episodes 1/4"):
            break
    p.send_signal(signal.SIGINT)
    stdout, _ = p.communicate(timeout=120)
    assert p.returncode == 3, stdout
    assert "resume=True" in stdout
    resumed = avp.bench(out, resume=True, progress=False, **args)
    assert resumed.info["episodes"] == 4 and resumed.info["failed"] == 0
    assert resumed.info["resumed"] >= 1
