#!/usr/bin/python3
"""The learned gain end to end, small (ctest learned_gain_e2e): the data command on the training
family, scripts/learn-gain train on it, and an episode of avp-nbv ranking with the model it wrote;
the training script refuses data from a test scenario.

  learned_gain_e2e_test.py AVP_BINARY REPO_ROOT SCRATCH
"""

import json
import os
import shutil
import subprocess
import sys

avp, repo, scratch = sys.argv[1], sys.argv[2], sys.argv[3]
shutil.rmtree(scratch, ignore_errors=True)
os.makedirs(scratch)
learn = os.path.join(repo, "scripts", "learn-gain")


def run(*args, ok=True):
    p = subprocess.run(list(args), capture_output=True, text=True, cwd=scratch)
    if ok and p.returncode != 0:
        print(f"FAIL: {' '.join(args)} exited {p.returncode}\n{p.stdout}\n{p.stderr}")
        sys.exit(1)
    return p


def check(cond, what):
    if not cond:
        print("FAIL:", what)
        sys.exit(1)


def bench(name, scenario):
    config = os.path.join(scratch, f"{name}.yaml")
    with open(config, "w", encoding="utf-8") as f:
        f.write(f"""description: learned gain e2e ({name})
scenarios: [{scenario}]
planners: [avp-nbv]
seeds: {{first: 1000, count: 2}}
planner_options:
  avp-nbv: {{candidates.max_candidates: 48}}
run:
  oracle_regret: true
  oracle_regret_features: true
  segmenter: {{name: oracle}}
  episode: {{views: 3, integrator: {{carving: projective}}}}
  map: {{grid: {{voxel_size_m: 0.01}}}}
""")
    out = os.path.join(scratch, name)
    run(avp, "bench", "--config", config, "--out", out)
    return out


# The data command: every plan step's candidates with their feature rows and true gains.
data = bench("data", "generic-training")
records = []
for root, _, files in os.walk(os.path.join(data, "runs")):
    records += [os.path.join(root, f) for f in files if f == "record.json"]
check(len(records) == 2, f"two episodes: {records}")
with open(records[0], encoding="utf-8") as f:
    step = json.load(f)["oracle_regret"][0]
names = step["feature_names"]
check(len(step["scored"]) > 5, "scored candidates")
check(all(len(c["features"]) == len(names) for c in step["scored"]), "a row per candidate")
check(len(step["feature_hash"]) == 16, step.get("feature_hash"))

# Training on it writes a model with its manifest and its check rows.
model = os.path.join(scratch, "model.onnx")
p = run("/usr/bin/python3", learn, "train", data, "--out", model)
check("rows of" in p.stdout and os.path.getsize(model) > 1000, p.stdout)
with open(model + ".check.json", encoding="utf-8") as f:
    check(len(json.load(f)["rows"]) > 5, "check rows")
# Bit for bit: the same data, the same model.
again = os.path.join(scratch, "again.onnx")
run("/usr/bin/python3", learn, "train", data, "--out", again)
with open(model, "rb") as a, open(again, "rb") as b:
    check(a.read() == b.read(), "training twice gives the same model file")

# avp-nbv ranks with it: an episode runs, and no step fell back.
out = os.path.join(scratch, "run")
run(avp, "run", "--scenario", "tomato-single-cluster", "--views", "3", "--planner", "avp-nbv",
    "--planner-option", f"gain_model={model}", "--set", "map.grid.voxel_size_m=0.01",
    "--out", out)
with open(os.path.join(out, "record.json"), encoding="utf-8") as f:
    rec = json.load(f)
planned = [s for s in rec["steps"] if "plan" in s]
check(len(planned) == 2, f"two plans: {len(planned)}")
check(all("warnings" not in s["plan"] for s in planned), "no fallback")

# A model file that does not exist is refused before the episode, naming it.
p = run(avp, "run", "--views", "2", "--planner-option", "gain_model=/no/such.onnx", "--out",
        os.path.join(scratch, "bad"), ok=False)
check(p.returncode != 0 and "/no/such.onnx" in p.stdout + p.stderr, p.stdout + p.stderr)

# Data from a test scenario is refused by the training script.
test_data = bench("test-data", "tomato-single-cluster")
p = run("/usr/bin/python3", learn, "train", test_data, "--out", os.path.join(scratch, "x.onnx"),
        ok=False)
check(p.returncode == 2 and "not a training-only family" in p.stderr, p.stderr)
# ... and judged on (the held-out evaluation of a model trained on the training data).
p = run("/usr/bin/python3", learn, "evaluate", test_data, "--train", data)
check("| tomato-single-cluster |" in p.stdout, p.stdout)
print("learned gain e2e: ok")
