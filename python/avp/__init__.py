"""avp from Python: active vision for agricultural robots (docs/python.md).

Maps as numpy arrays, scenes rendered to numpy, the arm's kinematics, and episodes and benches run
with the command line's configuration keys, seeds and ground truth, into the folders it writes.

    import avp
    result = avp.run("out/py-run", scenario="tomato-full-occlusion", seed=3)
    result.metrics["f1"]            # per fused view, as metrics.csv holds it
    m = result.map                  # avp.Map of the run's final map
    m.voxels("labelled")            # columns: x, y, z, class, confidence, instance, ...
"""

from __future__ import annotations

import csv
import json
import math
import os
import sys
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Optional, Sequence, Union

import numpy as np

from . import _avp
from ._avp import (DEFAULT_SCENARIO, Arm, Camera, Candidate, Map, Message, Plan, PlanningRequest,
                   Recording, Scene, check_planner, planners, scenarios, segment)

__all__ = [
    "Arm",
    "BenchResult",
    "Camera",
    "Candidate",
    "DEFAULT_SCENARIO",
    "Map",
    "Message",
    "Plan",
    "PlanningRequest",
    "Recording",
    "RunResult",
    "Scene",
    "ViewPlanner",
    "bench",
    "check_planner",
    "effective_config",
    "planners",
    "read_table",
    "register_planner",
    "run",
    "scenarios",
    "segment",
]

PathLike = Union[str, "os.PathLike[str]"]
Config = Union[None, PathLike, Mapping[str, Any]]


# ---- Tables ------------------------------------------------------------------------------------


def _column(values: list[str]) -> np.ndarray:
    """One CSV column as the narrowest array that holds it: int64, float64 (an empty cell or
    "nan" is NaN), bool ("true"/"false"), or str."""
    try:
        return np.array([int(v) for v in values], dtype=np.int64)
    except ValueError:
        pass
    try:
        return np.array([float(v) if v != "" else math.nan for v in values], dtype=np.float64)
    except ValueError:
        pass
    if all(v in ("true", "false") for v in values):
        return np.array([v == "true" for v in values], dtype=bool)
    return np.array(values, dtype=str)


def read_table(path: PathLike) -> dict[str, np.ndarray]:
    """A CSV file avp writes (metrics.csv, summary.csv, ...) as columns: a dict of 1-D numpy
    arrays in the file's column order, which pandas.DataFrame(...) takes as it is."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        raise ValueError(f"{os.fspath(path)}: empty file, expected a header line")
    header, body = rows[0], rows[1:]
    for n, row in enumerate(body, start=2):
        if len(row) != len(header):
            raise ValueError(
                f"{os.fspath(path)}:{n}: {len(row)} fields, the header has {len(header)}")
    return {name: _column([row[i] for row in body]) for i, name in enumerate(header)}


def _records_to_columns(records: Sequence[Mapping[str, Any]]) -> dict[str, np.ndarray]:
    """A list of flat JSON objects (record.json's "fruits") as columns; null is NaN."""
    names: list[str] = []
    for r in records:
        for k, v in r.items():
            if k not in names and not isinstance(v, (dict, list)):
                names.append(k)
    out: dict[str, np.ndarray] = {}
    for k in names:
        values = [r.get(k) for r in records]
        if all(isinstance(v, bool) for v in values):
            out[k] = np.array(values, dtype=bool)
        elif all(v is None or (isinstance(v, (int, float)) and not isinstance(v, bool))
                 for v in values):
            ints = all(isinstance(v, int) for v in values)
            out[k] = np.array([math.nan if v is None else v for v in values],
                              dtype=np.int64 if ints else np.float64)
        else:
            out[k] = np.array(["" if v is None else str(v) for v in values], dtype=str)
    return out


# ---- Configurations ----------------------------------------------------------------------------


def _text(value: Any) -> str:
    """A --set value as the command line writes it."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return ",".join(_text(v) for v in value)
    return str(value)


def _set_items(set: Optional[Union[Mapping[str, Any], Iterable[tuple[str, Any]]]]
               ) -> list[tuple[str, str]]:
    if set is None:
        return []
    items = set.items() if isinstance(set, Mapping) else set
    return [(str(k), _text(v)) for k, v in items]


def _config_args(config: Config, keys: Mapping[str, Any]) -> tuple[Optional[str], str]:
    """(a configuration file, a YAML/JSON text of the tree): `config` is a path or a dict (the
    tree `avp run --print-config` prints); `keys` are top-level keys of that tree applied over
    it (scenario="...", seed=3, episode={"views": 4})."""
    file: Optional[str] = None
    tree: dict[str, Any] = {}
    if isinstance(config, Mapping):
        tree = json.loads(json.dumps(config))  # a deep copy that only JSON types survive
    elif config is not None:
        file = os.fspath(config)
    for k, v in keys.items():
        if isinstance(v, os.PathLike):
            v = os.fspath(v)
        tree[k] = v
    try:
        text = json.dumps(tree) if tree else ""
    except TypeError as e:
        raise TypeError(f"config: {e}") from None
    return file, text


def effective_config(config: Config = None, *, set=None, **keys: Any) -> str:
    """The effective run configuration as YAML, validated, exactly as `avp run --print-config`
    prints it (every default, every key of the components' options)."""
    file, text = _config_args(config, keys)
    return _avp._effective_config(file, text, _set_items(set))


# ---- Episodes ----------------------------------------------------------------------------------


class RunResult:
    """One episode's run folder (docs/experiments.md), read back: record.json as `record`, the
    per-view metrics of metrics.csv as `metrics`, the per-fruit results as `fruits`, the final
    map as `map`."""

    def __init__(self, folder: PathLike, info: Optional[Mapping[str, Any]] = None):
        self.folder = Path(folder)
        self.info = dict(info or {})
        with open(self.folder / "record.json") as f:
            self.record: dict[str, Any] = json.load(f)
        self.metrics = read_table(self.folder / "metrics.csv")
        self.fruits = _records_to_columns(self.record.get("fruits") or [])
        self._map: Optional[Map] = None

    @property
    def final(self) -> dict[str, Any]:
        """The final view's metrics (record.json's "final_metrics")."""
        return dict(self.record.get("final_metrics") or {})

    @property
    def map(self) -> Map:
        """The episode's final map (map.avpmap; a bench's episodes keep none)."""
        if self._map is None:
            self._map = Map.load(self.folder / "map.avpmap")
        return self._map

    def __repr__(self) -> str:
        f = self.final
        return (f"<avp.RunResult {self.folder}: {len(self.metrics.get('view', []))} views, "
                f"F1 {f.get('f1', float('nan')):.3f}>")


def _print_line(line: str) -> None:
    print(line, flush=True)


def run(out: PathLike = "out/run", config: Config = None, *, force: bool = False,
        record: bool = False, record_compression: str = "", progress: Union[bool, Callable[[str], Any]] = True,
        set=None, **keys: Any) -> RunResult:
    """One simulated episode into the run folder `out`, as `avp run` writes it, read back.

    config: a run configuration file (YAML) or a dict of the same tree (`avp run
    --print-config`); keys: top-level keys over it (scenario, scene_file, arrangement, seed,
    threads, planner, segmenter, or a section as a dict: episode={"views": 4}); set: KEY=VALUE
    items over everything, as `--set` ({"map.grid.voxel_size_m": 0.01}). The same keys and checks
    as the CLI: a bad one raises ValueError naming it. progress: print each view's line (True),
    or a function that takes it. A folder holding results is refused unless force=True. Ctrl-C
    stops the episode after the step under way, writes its results and raises
    KeyboardInterrupt."""
    file, text = _config_args(config, keys)
    on_step = _print_line if progress is True else (progress or None)
    info = _avp._run(file, text, _set_items(set), os.fspath(out), force, record,
                     record_compression, on_step)
    result = RunResult(out, info)
    if progress:
        f = result.final
        line = (f"{info['scene']}: {info['end']} after {len(result.metrics.get('view', []))} "
                f"views in {info['seconds']:.1f} s; final F1 {f.get('f1', float('nan')):.3f}, "
                f"fruits found {f.get('fruits_found', 0):g}/{f.get('fruits_total', 0):g}")
        (on_step or _print_line)(line)
        for why in info["nothing_found"]:
            (on_step or _print_line)(f"no fruit found: {why}")
    return result


# ---- Benches -----------------------------------------------------------------------------------


class BenchResult:
    """A bench folder (docs/experiments.md), read back: summary.csv as `summary` (one row per
    scenario and planner, final-view means with 95 % intervals)."""

    def __init__(self, folder: PathLike, info: Optional[Mapping[str, Any]] = None):
        self.folder = Path(folder)
        self.info = dict(info or {})
        summary = self.folder / "summary.csv"
        self.summary = read_table(summary) if summary.exists() else {}

    def runs(self) -> dict[str, np.ndarray]:
        """Every episode's final row: scenario, planner, seed and the last line of its
        metrics.csv, as columns."""
        rows: list[dict[str, Any]] = []
        for metrics in sorted(self.folder.glob("runs/*/*/seed-*/metrics.csv")):
            table = read_table(metrics)
            if len(table.get("view", [])) == 0:
                continue
            row: dict[str, Any] = {
                "scenario": metrics.parent.parent.parent.name,
                "planner": metrics.parent.parent.name,
                "seed": int(metrics.parent.name.removeprefix("seed-")),
            }
            row.update({k: v[-1].item() for k, v in table.items()})
            rows.append(row)
        return _records_to_columns(rows)

    def run(self, scenario: str, planner: str, seed: int) -> RunResult:
        """One episode of the bench."""
        return RunResult(self.folder / "runs" / scenario / planner / f"seed-{seed}")

    def __repr__(self) -> str:
        return (f"<avp.BenchResult {self.folder}: {self.info.get('episodes', '?')} episodes, "
                f"{self.info.get('failed', '?')} failed>")


def bench(out: PathLike = "out/bench", config: Config = None, *,
          scenarios: Optional[Sequence[str]] = None, planners: Optional[Sequence[str]] = None,
          seeds: Union[None, int, Sequence[int]] = None, jobs: int = 0, force: bool = False,
          resume: bool = False, record: bool = False, record_compression: str = "",
          progress: bool = True, set=None,
          planner_options: Optional[Mapping[str, Mapping[str, Any]]] = None) -> BenchResult:
    """Scenarios x planners x seeds into the bench folder `out`, as `avp bench` writes it.

    config: a bench configuration file (configs/experiments/*.yaml) or a dict of the same tree;
    scenarios, planners, seeds (N: seeds 0..N-1, or a list) replace its lists; without a config,
    the lists not given are `avp bench`'s defaults. set: run-configuration keys over every
    episode ({"episode.views": 4}); planner_options: {planner: {key: value}}. jobs: episodes at
    once (0: one per core). Progress goes to stderr as the CLI's. Ctrl-C stops the bench (the
    episodes under way are marked failed) and raises KeyboardInterrupt; resume=True runs the
    rest."""
    file, text = _config_args(config, {})
    if isinstance(seeds, int) and not isinstance(seeds, bool):
        if seeds < 1:
            raise ValueError(f"seeds ({seeds}): a count must be at least 1")
        seeds = list(range(seeds))
    options = {p: {k: _text(v) for k, v in o.items()} for p, o in (planner_options or {}).items()}
    info = _avp._bench(file, text, None if scenarios is None else list(scenarios),
                       None if planners is None else list(planners),
                       None if seeds is None else [int(s) for s in seeds], _set_items(set),
                       options, os.fspath(out), jobs, force, resume, record, record_compression,
                       progress)
    return BenchResult(out, info)


# ---- Planners in Python ------------------------------------------------------------------------


class ViewPlanner:
    """The base of a next-best-view planner written in Python (docs/python.md).

    Subclass it, implement plan(request), and register it by name (avp.register_planner); it then
    runs in avp.run and avp.bench beside the built-in planners, under the same seeds, ground truth
    and metrics. plan(request) gets an avp.PlanningRequest (valid for the call only: the map as
    arrays, the arm, the current and start views, the views fused so far, the region of
    interest, the budget) and returns the views to try, best first:

    - an avp.Plan (e.g. request.plan_with("avp-nbv"), reordered or cut), or
    - a list of avp.Candidate, or of 4x4 camera poses (IK finds their joints), or
    - None or [] (no view: the episode ends as no-valid-candidate).

    The loop tries them in order until the arm reaches one. Views IK cannot reach, that collide,
    or that repeat a fused view are dropped. An exception ends the episode as planner-fault, its
    traceback in record.json; avp.run then raises RuntimeError and marks the folder failed.
    """

    def plan(self, request: PlanningRequest):
        raise NotImplementedError(f"{type(self).__name__}.plan(request) is not implemented")


def register_planner(name: str, factory: Callable[[], Any], *, description: str = "",
                     timeout_s: float = 60.0) -> None:
    """Makes `name` a planner of avp.run, avp.bench and avp.effective_config: factory() (a
    ViewPlanner subclass, or any callable returning an object with plan(request)) makes a fresh
    planner for every episode. A plan() call longer than timeout_s ends the episode as
    planner-fault. Registering a Python planner's name again replaces its factory; a built-in
    planner's name raises ValueError."""
    if not callable(factory):
        raise TypeError(f"factory: expected a class or a callable, got {type(factory).__name__}")
    _avp._register_planner(str(name), factory, str(description), float(timeout_s))
