"""The examples of examples/python run as a user runs them, and write their plots."""

import os
import subprocess
import sys
from pathlib import Path


EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "python"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def test_the_bench_script_writes_its_plot(tmp_root):
    out = tmp_root / "example-bench"
    p = subprocess.run([sys.executable, str(EXAMPLES / "plot_bench.py"), "--out", str(out),
                        "--seeds", "2", "--views", "2"],
                       capture_output=True, text=True, env=os.environ.copy())
    assert p.returncode == 0, p.stdout + p.stderr
    assert "final F1" in p.stdout and "novelty" in p.stdout
    png = out / "per_view.png"
    assert png.read_bytes()[:8] == PNG_MAGIC and png.stat().st_size > 10000


def test_the_notebook_runs_from_top_to_bottom(tmp_root):
    import nbclient  # python3-nbclient, python3-nbformat, python3-ipykernel (scripts/setup)
    import nbformat

    nb = nbformat.read(EXAMPLES / "plot_bench.ipynb", as_version=4)
    workdir = tmp_root / "notebook"
    workdir.mkdir()
    (workdir / "out").mkdir()
    client = nbclient.NotebookClient(nb, timeout=300, kernel_name="python3",
                                     resources={"metadata": {"path": str(workdir)}})
    client.execute()
    png = workdir / "out" / "notebook-bench" / "per_view.png"
    assert png.read_bytes()[:8] == PNG_MAGIC
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]


def test_the_benchmark_runs_and_writes_its_records(tmp_root):
    """bench_python --quick (the figures are make bench's; here only that it runs)."""
    bench = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_python.py"
    out = tmp_root / "bench_python.json"
    p = subprocess.run([sys.executable, str(bench), "--quick", "--avp_json", str(out)],
                       capture_output=True, text=True, env=os.environ.copy())
    assert p.returncode == 0, p.stdout + p.stderr
    import json
    names = [r["name"] for r in json.loads(out.read_text())]
    assert names == ["python_planner_overhead_ms", "map_to_numpy_ms", "render_to_numpy_ratio"]
