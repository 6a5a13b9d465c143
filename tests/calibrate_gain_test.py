#!/usr/bin/env python3
"""scripts/calibrate-gain on made-up bench folders: the fit finds the part that ranks like the
truth, and bad records are refused naming the file (run by ctest: calibrate_gain_script)."""

import json
import os
import subprocess
import sys
import tempfile

SCRIPT = sys.argv[1]
TERMS = ["target_entropy", "predicted_target", "unknown_near_target", "unknown_roi"]


def record(folder, scenario, seed, body):
    d = os.path.join(folder, "runs", scenario, "avp-nbv", f"seed-{seed}")
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, "record.json"), "w", encoding="utf-8") as f:
        f.write(body if isinstance(body, str) else json.dumps(body))
    return os.path.join(d, "record.json")


def run(*args):
    p = subprocess.run([sys.executable, SCRIPT, *args], capture_output=True, text=True)
    return p.returncode, p.stdout + p.stderr


def check(cond, what):
    if not cond:
        print("FAIL:", what)
        sys.exit(1)


with tempfile.TemporaryDirectory() as tmp:
    bench = os.path.join(tmp, "bench")
    # The truth ranks like predicted_target; unknown_roi is large and ranks the other way, so
    # today's weights (all 1) rank the candidates backwards.
    for s, scenario in enumerate(["plant-a", "plant-b", "plant-c"]):
        for seed in range(2):
            scored = []
            for i in range(12):
                truth = float(i + s + seed)
                terms = {"target_entropy": 0.0, "predicted_target": truth,
                         "unknown_near_target": 0.0, "unknown_roi": 1000.0 - 10.0 * i}
                gain = sum(terms.values())
                scored.append({"gain": gain, "utility": gain / 1100.0, "true_gain": truth,
                               "gain_terms": terms})
            record(bench, scenario, seed, {"scenario": scenario, "seed": seed,
                                           "oracle_regret": [{"step": 0, "scored": scored}]})
    rc, out = run(bench)
    check(rc == 0, f"the fit runs: {out}")
    check("6 plans, 72 candidates, 3 scenarios" in out, out)
    fitted = next(line for line in out.splitlines() if line.startswith("factors fitted"))
    # With unknown_roi turned down against predicted_target the fit ranks exactly like the truth.
    check("mean rank corr. 1.000" in fitted, fitted)
    rows = [line for line in out.splitlines() if line.startswith("| plant-")]
    check(len(rows) == 3, f"one row per scenario: {out}")
    for line in rows:
        cells = [c.strip() for c in line.split("|")]
        check(cells[3].startswith("-1.000"), f"today ranks backwards: {line}")
        check(cells[4].startswith("1.000 / 0.000"), f"held out ranks right: {line}")
        check(cells[7].startswith("1.000 / 0.000"), f"fitted alone ranks right: {line}")

    bad = os.path.join(tmp, "bad")
    path = record(bad, "plant", 0, '{"scenario": ')
    rc, out = run(bad)
    check(rc != 0 and path in out and "cannot be read as JSON" in out, out)
    body = {"scenario": "plant", "seed": 0, "oracle_regret": [{"step": 0, "scored": [
        {"gain": 1, "utility": "x", "true_gain": 1, "gain_terms": {t: 1 for t in TERMS}}]}]}
    record(bad, "plant", 0, body)
    rc, out = run(bad)
    check(rc != 0 and "utility is 'x', not a finite number" in out, out)
    body["oracle_regret"][0]["scored"][0]["utility"] = 1
    del body["oracle_regret"][0]["scored"][0]["gain_terms"]["unknown_roi"]
    record(bad, "plant", 0, body)
    rc, out = run(bad)
    check(rc != 0 and "no gain_terms" in out, out)
    rc, out = run(os.path.join(tmp, "nothing"))
    check(rc != 0 and "not an avp bench folder" in out, out)
print("calibrate-gain: ok")
