#!/usr/bin/env python3
"""bench_python: what the Python package adds to the C++ work it calls (docs/benchmarks.md,
docs/python.md), each measured against the C++ in the same run:

  python_planner_overhead_ms   per plan: the loop's plan time of a Python planner minus the time
                               its plan() body took (the request view, the GIL, the answer's
                               conversion and checks); target <= 5 ms
  map_to_numpy_ms              Map.voxels("occupied") of a 5 mm plant map after a whole episode
                               (median), beside its voxel count; target <= 20 ms
  render_to_numpy_ratio        Scene.render() wall time over the ray casting alone (render_ms),
                               median; target <= 1.10

    PYTHONPATH=build/python python3 benchmarks/bench_python.py [--avp_json FILE] [--quick]
"""

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import avp


class CachedPlan(avp.ViewPlanner):
    """Answers every plan after the first with the first plan's answer (avp-nbv's), so that its
    body costs next to nothing; records the body's time."""

    body_ms = []

    def __init__(self):
        self.cached = None

    def plan(self, request):
        t0 = time.perf_counter()
        if self.cached is None:
            self.cached = request.plan_with("avp-nbv")
            return self.cached
        out = self.cached
        CachedPlan.body_ms.append((time.perf_counter() - t0) * 1e3)
        return out


def planner_overhead(folder, views):
    avp.register_planner("bench-cached-plan", CachedPlan)
    CachedPlan.body_ms.clear()
    r = avp.run(folder / "planner", scenario="tomato-multiple-clusters", seed=0,
                planner="bench-cached-plan", episode={"views": views}, progress=False)
    plan_ms = [v for v in r.metrics["plan_ms"][2:] if v == v]  # the plans after the first
    n = min(len(plan_ms), len(CachedPlan.body_ms))
    overhead = [plan_ms[i] - CachedPlan.body_ms[i] for i in range(n)]
    return statistics.median(overhead), statistics.median(CachedPlan.body_ms[:n]), n


def map_to_numpy(folder, views, repeats):
    r = avp.run(folder / "map", scenario="tomato-multiple-clusters", seed=0,
                episode={"views": views}, progress=False)
    m = r.map
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        v = m.voxels("occupied")
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times), len(v["x"]), m.voxel_size_m, m.known_voxels


def render_to_numpy(repeats):
    scene = avp.Scene("tomato-multiple-clusters", seed=0)
    scene.render(noise=False)  # builds the BVH once
    ratios, walls, casts = [], [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        frame = scene.render(noise=False)
        wall = (time.perf_counter() - t0) * 1e3
        walls.append(wall)
        casts.append(frame["render_ms"])
        ratios.append(wall / frame["render_ms"])
    return statistics.median(ratios), statistics.median(walls), statistics.median(casts)


def record(name, value, unit, reference, reference_value, target, meets, ratio=None):
    return {"name": name, "value": float(value), "unit": unit, "reference": reference,
            "reference_value": float(reference_value),
            "ratio": None if ratio is None else float(ratio), "target": target,
            "meets_target": bool(meets)}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--avp_json", help="write the records here (scripts/bench)")
    parser.add_argument("--quick", action="store_true", help="fewer views and repeats")
    args = parser.parse_args(argv)
    views = 4 if args.quick else 8
    repeats = 5 if args.quick else 20
    with tempfile.TemporaryDirectory(prefix="bench_python-") as d:
        folder = Path(d)
        overhead, body, plans = planner_overhead(folder, views)
        map_ms, voxels, voxel_size, known = map_to_numpy(folder, views, repeats)
    ratio, wall_ms, cast_ms = render_to_numpy(repeats)
    records = [
        record("python_planner_overhead_ms", overhead, "ms", "plan() body (ms)", body, "<= 5 ms",
               overhead <= 5.0),
        record("map_to_numpy_ms", map_ms, "ms", f"occupied voxels ({voxel_size * 1e3:g} mm map, "
               f"{known} known)", voxels, "<= 20 ms", map_ms <= 20.0),
        record("render_to_numpy_ratio", wall_ms, "ms", "ray casting alone (ms)", cast_ms,
               "<= 1.10x", ratio <= 1.10, ratio=ratio),
    ]
    print(f"Python planner: {overhead:.2f} ms per plan beyond its plan() body ({body:.3f} ms), "
          f"median of {plans} plans")
    print(f"map to numpy: {map_ms:.2f} ms for {voxels} occupied voxels of a "
          f"{voxel_size * 1e3:g} mm map ({known} known)")
    print(f"render to numpy: {wall_ms:.1f} ms wall, {cast_ms:.1f} ms ray casting: {ratio:.3f}x")
    for r in records:
        print(f"  {r['name']}: {r['value']:.3f} {r['unit']} (target {r['target']}: "
              f"{'met' if r['meets_target'] else 'NOT met'})")
    if args.avp_json:
        Path(args.avp_json).write_text(json.dumps(records, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
