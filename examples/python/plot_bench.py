#!/usr/bin/env python3
"""Benches a planner written in Python against avp-nbv and predefined, and plots F1 and fruits
found per view (docs/python.md).

    .venv/bin/python examples/python/plot_bench.py --out out/py-bench --seeds 3

The Python planner ("novelty", below) takes avp-nbv's candidates and re-ranks them by their gain
times (1 + how far their viewing direction turns from every view fused so far). It runs in
`avp bench`'s protocol beside the built-in planners (the same seeds, ground truth and metrics as
the command line) through avp.bench; the script reads summary.csv back as arrays and draws the
mean over the seeds per view with its 95 % interval, one line per planner, to OUT/per_view.png.
"""

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display needed
import matplotlib.pyplot as plt
from matplotlib.ticker import MaxNLocator
import numpy as np

import avp


class NoveltyPlanner(avp.ViewPlanner):
    """avp-nbv's candidates re-ranked by gain x (1 + angular novelty): the angle between a
    candidate's optical axis and the nearest fused view's, over pi."""

    def plan(self, request):
        plan = request.plan_with("avp-nbv")
        fused_axes = request.fused_views[:, :3, 2]  # the optical axes (z) of the fused views

        def score(candidate):
            axis = candidate.pose[:3, 2]
            novelty = np.arccos(np.clip(fused_axes @ axis, -1.0, 1.0)).min() / np.pi
            return candidate.gain * (1.0 + novelty)

        ranked = plan.ranked
        for c in ranked:
            c.utility = score(c)
        plan.ranked = sorted(ranked, key=lambda c: c.utility, reverse=True)
        return plan


avp.register_planner("novelty", NoveltyPlanner, description="avp-nbv re-ranked by view novelty")


def per_view(summary, scenario, planner, metric):
    """summary.csv's rows of one scenario, planner and metric: per view, the mean over the seeds
    and its 95 % interval (the same numbers `avp bench` prints)."""
    rows = ((summary["scenario"] == scenario) & (summary["planner"] == planner)
            & (summary["metric"] == metric))
    order = np.argsort(summary["view"][rows])
    return (summary["view"][rows][order], summary["mean"][rows][order],
            summary["ci_lo"][rows][order], summary["ci_hi"][rows][order])


def plot(bench, scenarios, planners, seeds, path):
    """F1 and fruits found per view, one line per planner, the 95 % interval shaded."""
    fig, axes = plt.subplots(len(scenarios), 2, figsize=(10, 3.2 * len(scenarios)),
                             squeeze=False)
    for row, scenario in enumerate(scenarios):
        for col, (column, label) in enumerate([("f1", "F1 (exact)"),
                                               ("fruits_found", "fruits found")]):
            ax = axes[row][col]
            for planner in planners:
                views, mean, lo, hi = per_view(bench.summary, scenario, planner, column)
                ax.plot(views, mean, marker="o", label=planner)
                ax.fill_between(views, lo, hi, alpha=0.2)
            ax.set_xlabel("view")
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            ax.set_ylabel(label)
            ax.set_title(f"{scenario}, {len(seeds)} seeds")
            ax.grid(alpha=0.3)
    axes[0][0].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/py-bench", help="bench folder")
    parser.add_argument("--scenarios", default="tomato-single-cluster")
    parser.add_argument("--planners", default="novelty,avp-nbv,predefined")
    parser.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1")
    parser.add_argument("--views", type=int, default=4, help="fused views per episode")
    parser.add_argument("--force", action="store_true", help="replace an earlier bench in --out")
    args = parser.parse_args(argv)
    scenarios = args.scenarios.split(",")
    planners = args.planners.split(",")
    seeds = list(range(args.seeds))
    bench = avp.bench(args.out, scenarios=scenarios, planners=planners, seeds=seeds,
                      set={"episode.views": args.views}, force=args.force)
    print(bench)
    for scenario in scenarios:
        for planner in planners:
            _, mean, lo, hi = per_view(bench.summary, scenario, planner, "f1")
            print(f"  {scenario:28s} {planner:14s} final F1 {mean[-1]:.3f} [{lo[-1]:.3f}, "
                  f"{hi[-1]:.3f}]")
    path = Path(args.out) / "per_view.png"
    plot(bench, scenarios, planners, seeds, path)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
