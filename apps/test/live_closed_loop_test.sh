#!/usr/bin/env bash
# Closed loop over DDS: `avp sim ros2` and `avp live` in two processes choose the same views and
# score the same per-step metrics as `avp run` in one process, for the same scenario, seed,
# planner and segmenter (the oracle, through the simulator's label topics), with straight moves
# and with collision-free motion (the same planned paths). Loopback only, on a domain of its own. Usage: live_closed_loop_test.sh AVP WORKDIR
set -euo pipefail
AVP=$1
WORK=$2
rm -rf "$WORK" && mkdir -p "$WORK"
export AVP_ROS2_LOOPBACK=1
export ROS_DOMAIN_ID=$((200 + $$ % 30))
SCENARIO=tomato-single-cluster
BASE=(--scenario "$SCENARIO" --seed 3 --planner avp-nbv --segmenter oracle --threads 2)
COMMON=("${BASE[@]}" --views 4)

SIM=
cleanup() { kill "$SIM" 2>/dev/null || true; wait "$SIM" 2>/dev/null || true; }

# One closed loop: MODE (straight: the arm goes straight to each view's joints; planned:
# collision-free motion, each move one JointTrajectory that avp sim ros2 follows point by point;
# moving: straight timed moves in real time, the camera's frames on the way fused as avp run
# renders them, over reliable topics so that none is lost), then EXTRA run flags.
closed_loop() {
  local mode=$1
  shift
  local dir="$WORK/$mode"
  mkdir -p "$dir"
  "$AVP" run "${COMMON[@]}" "$@" --out "$dir/run" > "$dir/run.log"

  local sim_time=(--sim-option time_scale=0)
  local wire=()
  if [ "$mode" = moving ]; then
    # Half speed, and room for 60 frames waiting: a loaded test machine must not drop one.
    sim_time=(--sim-option time_scale=2 --sim-option best_effort=false)
    wire=(--live-option camera.best_effort=false --live-option camera.queue=60)
  fi
  "$AVP" sim ros2 "${COMMON[@]}" "$@" "${sim_time[@]}" --sim-option camera_rate_hz=10 \
    --duration 240 > "$dir/sim.log" 2>&1 &
  SIM=$!
  trap cleanup EXIT

  local status=0
  timeout 200 "$AVP" live "${COMMON[@]}" "$@" --out "$dir/live" "${wire[@]}" \
    --live-option camera.labels_prefix=/avp/sim --live-option rviz.enabled=true \
    --live-option arm.min_duration_s=0 --live-option arm.max_joint_speed_rad_s=100 \
    --live-option camera.frame_timeout_s=20 --live-option arm.state_timeout_s=20 \
    > "$dir/live.log" 2>&1 || status=$?
  cleanup
  trap - EXIT
  if [ "$status" -ne 0 ]; then
    echo "avp live ($mode) failed ($status):"; cat "$dir/live.log"; echo "--- sim:"
    cat "$dir/sim.log"
    exit 1
  fi

  python3 - "$mode" "$dir/run/record.json" "$dir/live/record.json" <<'PY'
import json, math, sys
mode = sys.argv[1]
run, live = (json.load(open(p)) for p in sys.argv[2:4])
assert live["avp"] == "avp live", live["avp"]
assert live["end"] == run["end"] == "budget-reached", (run["end"], live["end"], live["end_reason"])
assert len(run["steps"]) == len(live["steps"]) == 4, (len(run["steps"]), len(live["steps"]))
def close(a, b, tol):
    return a is None and b is None or abs(a - b) <= tol
for r, l in zip(run["steps"], live["steps"]):
    v = r["view"]
    # The same view: the arm's pose (forward kinematics of the joints it reported).
    assert json.dumps(r["X_WC"]) == json.dumps(l["X_WC"]), (v, r["X_WC"], l["X_WC"])
    assert r["masks"] == l["masks"], (v, r["masks"], l["masks"])
    for k, a in r["metrics"].items():
        b = l["metrics"][k]
        assert close(a, b, 1e-9), f"view {v}: metric {k}: run {a}, live {b}"
    assert (r["known_voxels"], r["target_voxels"]) == (l["known_voxels"], l["target_voxels"]), v
    if "plan" in r:
        assert r["plan"]["chosen_rank"] == l["plan"]["chosen_rank"], v
        assert r["plan"]["generated"] == l["plan"]["generated"], v
        rm, lm = r["plan"]["motion"], l["plan"]["motion"]
        assert rm["planned"] == lm["planned"] == (mode == "planned"), (v, rm, lm)
        if mode == "moving":
            # The same frames on the way, fused into the same map (known voxels above).
            rf, lf = r["plan"]["motion_frames"], l["plan"]["motion_frames"]
            assert rf["expected"] == lf["expected"] > 10, (v, rf, lf)
            assert rf["fused"] == lf["fused"] == rf["expected"], (v, rf, lf)
            assert rf["segmented"] == lf["segmented"] == rf["fused"], (v, rf, lf)
            assert lf["dropped"] == 0 and lf["failed"] == 0, (v, lf)
            assert (rf["known_delta"], rf["target_delta"]) == (lf["known_delta"], lf["target_delta"]), (v, rf, lf)
        if mode == "planned":
            # The same path, executed over DDS; only the simulator knows the contacts.
            assert rm["camera_path"] == lm["camera_path"], v
            assert rm["contacts"]["total"] == 0, (v, rm["contacts"])
            assert lm["contacts"] is None, (v, lm["contacts"])
print("closed loop (%s): 4 views, identical poses and metrics; final F1 %.4f, fruits %s/%s" %
      (mode, live["final_metrics"]["f1"], live["final_metrics"]["fruits_found"],
       live["final_metrics"]["fruits_total"]))
# The live record counts what came over the wire: 3 moves (and the planned return home).
w = live["live"]
assert w["camera"]["pairs_used"] == 4, w["camera"]
assert w["arm"]["goals_sent"] == (4 if mode == "planned" else 3), w["arm"]
moving = sum(s["plan"]["motion_frames"]["fused"] for s in live["steps"] if "plan" in s and
             "motion_frames" in s["plan"])
assert w["camera"]["moving_pairs"] == moving, (w["camera"], moving)
assert w["camera"]["moving_dropped"] == 0, w["camera"]
if mode == "moving":
    print("moving: %d frames fused on the way, as avp run" % moving)
assert w["rviz_messages"] > 0, w
PY
}

# avp live plans its moves by default (a real arm); avp run and avp sim ros2 move straight unless
# told otherwise: each loop names its motion, so that all three agree.
motion_enabled() { awk '/^motion:/ { m = 1; next } m && /^  enabled:/ { print $2; exit }'; }
[ "$("$AVP" live --print-config | motion_enabled)" = true ] ||
  { echo "avp live does not plan its moves by default"; exit 1; }
[ "$("$AVP" live --set motion.enabled=false --print-config | motion_enabled)" = false ] ||
  { echo "avp live ignored motion.enabled=false"; exit 1; }
[ "$("$AVP" run --print-config | motion_enabled)" = false ] ||
  { echo "avp run plans its moves by default"; exit 1; }

closed_loop straight --set motion.enabled=false
closed_loop planned --set motion.enabled=true
closed_loop moving --fuse-while-moving --set episode.motion_fusion.max_pending=60 \
  --set motion.enabled=false

# Ctrl-C after the first view: the episode ends as interrupted, with its folder written (avp live
# with its default, planned moves, which avp sim ros2 follows point by point).
"$AVP" sim ros2 "${BASE[@]}" --sim-option time_scale=0 --sim-option camera_rate_hz=10 \
  --duration 240 > "$WORK/sim2.log" 2>&1 &
SIM=$!
trap cleanup EXIT
"$AVP" live "${BASE[@]}" --views 8 --out "$WORK/interrupted" \
  --live-option camera.labels_prefix=/avp/sim --live-option rviz.enabled=false \
  --live-option arm.min_duration_s=0 --live-option arm.max_joint_speed_rad_s=100 \
  --live-option camera.frame_timeout_s=20 > "$WORK/interrupted.log" 2>&1 &
LIVE=$!
for _ in $(seq 1 600); do
  grep -q "^view 1/8" "$WORK/interrupted.log" && break
  sleep 0.1
done
kill -INT "$LIVE" || { echo "avp live ended before its first view:"; cat "$WORK/interrupted.log"; exit 1; }
wait "$LIVE" || { echo "interrupted avp live exited $?"; cat "$WORK/interrupted.log"; exit 1; }
python3 - "$WORK/interrupted" <<'PY'
import json, os, sys
d = sys.argv[1]
r = json.load(open(os.path.join(d, "record.json")))
assert r["end"] == "interrupted", (r["end"], r["end_reason"])
assert 1 <= r["views_fused"] < 8, r["views_fused"]
for f in ("metrics.csv", "map.ot", "fruit_voxels.ply", "metrics.svg"):
    assert os.path.getsize(os.path.join(d, f)) > 0, f
rows = open(os.path.join(d, "metrics.csv")).read().strip().splitlines()
assert len(rows) == 1 + r["views_fused"], (len(rows), r["views_fused"])
print("interrupted after %d views: %s" % (r["views_fused"], r["end_reason"]))
PY
cleanup
trap - EXIT

