"""Planners written in Python: registered by name, run by avp.run and avp.bench beside the
built-in planners, their mistakes reported by name."""

import json
import time

import numpy as np
import pytest

import avp
from conftest import SCENARIO
from test_runs import assert_same_table


class FollowAvpNbv(avp.ViewPlanner):
    """Picks what avp-nbv would pick, through the API."""

    def plan(self, request):
        return request.plan_with("avp-nbv")


class NearestOfAvpNbv(avp.ViewPlanner):
    """avp-nbv's candidates, nearest first (by joint-space cost), as poses."""

    def __init__(self):
        self.calls = 0

    def plan(self, request):
        self.calls += 1
        m = request.map
        assert m.voxels("occupied")["x"].size == m.occupied_voxels
        assert request.fused_views.shape == (request.view_index, 4, 4)
        assert request.prompt == "tomato" and request.target_class == "fruit"
        assert request.roi.shape == (2, 3) and request.joints.shape == (6,)
        ranked = sorted(request.plan_with("avp-nbv").ranked, key=lambda c: c.cost)
        return [c.pose for c in ranked[:5]]


avp.register_planner("py-follow-avp-nbv", FollowAvpNbv, description="avp-nbv through Python")
avp.register_planner("py-nearest", NearestOfAvpNbv)


def run(tmp_root, name, planner, **keys):
    return avp.run(tmp_root / name, scenario=SCENARIO, seed=1, planner=planner,
                   episode={"views": 3}, progress=False, **keys)


def test_a_python_planner_picking_what_avp_nbv_picks_is_avp_nbv(tmp_root):
    ours = run(tmp_root, "py-follow", "py-follow-avp-nbv")
    theirs = run(tmp_root, "cpp-avp-nbv", "avp-nbv")
    assert_same_table(ours.metrics, theirs.metrics)
    assert ours.record["final_metrics"] == theirs.record["final_metrics"]
    assert [s["X_WC"] for s in ours.record["steps"]] == [s["X_WC"] for s in theirs.record["steps"]]
    assert ours.record["config"]["planner"]["name"] == "py-follow-avp-nbv"


def test_a_python_planner_of_its_own_runs_and_is_deterministic(tmp_root):
    a = run(tmp_root, "nearest-a", "py-nearest")
    b = run(tmp_root, "nearest-b", "py-nearest")
    assert a.record["end"] == "budget-reached"
    assert len(a.metrics["view"]) == 3
    assert_same_table(a.metrics, b.metrics)
    assert "py-nearest" in [p["name"] for p in avp.planners()]


def test_python_planners_in_a_bench_beside_built_in_ones(tmp_root):
    b = avp.bench(tmp_root / "py-planner-bench", scenarios=[SCENARIO],
                  planners=["py-nearest", "predefined"], seeds=2, set={"episode.views": 2},
                  jobs=2, progress=False)
    assert b.info["episodes"] == 4 and b.info["failed"] == 0
    assert set(b.summary["planner"].tolist()) == {"py-nearest", "predefined"}


class Raises(avp.ViewPlanner):
    def plan(self, request):
        raise ZeroDivisionError("the planner divided by zero")


class AnswersNonsense(avp.ViewPlanner):
    def plan(self, request):
        return "the left one"


class KeepsTheRequest(avp.ViewPlanner):
    kept = []

    def plan(self, request):
        KeepsTheRequest.kept.append(request)
        return request.plan_with("predefined")


class Slow(avp.ViewPlanner):
    def plan(self, request):
        time.sleep(0.3)
        return request.plan_with("predefined")


avp.register_planner("py-raises", Raises)
avp.register_planner("py-nonsense", AnswersNonsense)
avp.register_planner("py-keeps", KeepsTheRequest)
avp.register_planner("py-slow", Slow, timeout_s=0.05)


def test_an_exception_in_a_planner_fails_the_run_with_its_traceback(tmp_root):
    with pytest.raises(RuntimeError) as e:
        run(tmp_root, "raises", "py-raises")
    message = str(e.value)
    assert "planner fault" in message and "ZeroDivisionError: the planner divided by zero" in message
    assert "Traceback" in message and "test_planners.py" in message
    folder = tmp_root / "raises"
    with open(folder / "record.json") as f:
        record = json.load(f)
    assert record["end"] == "planner-fault"
    assert "ZeroDivisionError" in record["end_reason"]
    with open(folder / "avp-state.json") as f:
        assert json.load(f)["state"] == "failed"
    assert len(avp.read_table(folder / "metrics.csv")["view"]) == 1  # the start view, kept


def test_a_wrong_answer_and_a_slow_planner_are_planner_faults(tmp_root):
    with pytest.raises(RuntimeError, match="answered wrongly.*plan\\(\\) returned str"):
        run(tmp_root, "nonsense", "py-nonsense")
    with pytest.raises(RuntimeError, match="took .* s, over its 0.05 s"):
        run(tmp_root, "slow", "py-slow")


class CallsAnUnknownPlanner(avp.ViewPlanner):
    def plan(self, request):
        return request.plan_with("nope")


def test_a_built_in_planner_by_a_wrong_name_is_named(tmp_root):
    avp.register_planner("py-calls-nope", CallsAnUnknownPlanner)
    with pytest.raises(RuntimeError, match="unknown planner 'nope'"):
        run(tmp_root, "calls-nope", "py-calls-nope")


def test_a_request_kept_after_the_call_refuses_to_be_used(tmp_root):
    run(tmp_root, "keeps", "py-keeps")
    request = KeepsTheRequest.kept[0]
    with pytest.raises(RuntimeError, match="one plan\\(\\) call"):
        request.view_index
    with pytest.raises(RuntimeError, match="one plan\\(\\) call"):
        request.plan_with("avp-nbv")


def test_registration_errors():
    with pytest.raises(ValueError, match="avp-nbv.*built-in"):
        avp.register_planner("avp-nbv", FollowAvpNbv)
    with pytest.raises(TypeError, match="factory"):
        avp.register_planner("py-x", 3)
    with pytest.raises(ValueError, match="timeout_s"):
        avp.register_planner("py-y", FollowAvpNbv, timeout_s=0)


def test_candidates_and_plans_from_python():
    pose = np.eye(4)
    c = avp.Candidate(pose, gain=2.0, utility=1.5)
    assert c.gain == 2.0 and not c.reachable and c.joints.size == 0
    p = avp.Plan([c], stop=True, stop_reason="enough")
    assert p.stop and len(p.ranked) == 1
    with pytest.raises(ValueError, match="pose"):
        avp.Candidate(np.zeros((4, 4)))


class RisingUtilities(avp.ViewPlanner):
    def plan(self, request):
        ranked = request.plan_with("avp-nbv").ranked[:2]
        ranked[1].utility = ranked[0].utility + 1.0
        return ranked


class Unseeded(avp.ViewPlanner):
    """Chooses by its own state, not by the request: the same request, another answer."""

    def __init__(self):
        self.calls = 0

    def plan(self, request):
        self.calls += 1
        ranked = request.plan_with("avp-nbv").ranked
        return [ranked[self.calls % len(ranked)]]


avp.register_planner("py-rising", RisingUtilities)
avp.register_planner("py-unseeded", Unseeded)


def test_the_planner_contract_holds_for_python_planners_and_names_what_breaks_it():
    assert avp.check_planner("py-follow-avp-nbv") == []
    assert avp.check_planner("py-nearest") == []
    assert avp.check_planner("avp-nbv") == []
    rising = avp.check_planner("py-rising")
    assert any("utility" in v and "do not rise" in v for v in rising), rising
    unseeded = avp.check_planner("py-unseeded")
    assert any("differs between two plans with the same seed" in v for v in unseeded), unseeded
    raises = avp.check_planner("py-raises")
    assert any("ZeroDivisionError" in v for v in raises), raises
    with pytest.raises(ValueError, match="ground truth"):
        avp.check_planner("oracle-nbv")
