#!/usr/bin/env python3
"""The README and docs are tested (issue 32, point 8).

Every shell command in a fenced code block of README.md and docs/*.md is found and classified:

  RUN   an avp command (or jq, scripts/calibrate-gain, scripts/learn-gain, a for loop of avp
        commands) that needs no model, GPU, robot, ROS 2 peer, server or cluster: it is run, and
        must exit with 0 (or the
        code EXPECT_RC gives), and print the figures FIGURES quotes for it;
  SKIP  a command matched by the SKIP table below, which says why it cannot run here;
  FAIL  a command that is neither: every new command in the docs must be classified.

Commands run in document order (a `map info` needs the `map build` before it), one fresh scratch
folder per document holding copies of configs/, examples/ and scripts/, `build/apps/avp` and `avp`
(on PATH) pointing at the program given with --avp. Nothing is written into the repository.

Where commands come from: ```sh / ```bash / ```console blocks (every line a command, `\\`
continuations joined, `# comments` dropped, `for ... done` kept whole, `...` elisions ignored),
and plain ``` blocks (the `$ ` prompt lines, or else the lines that start with `avp` or
`build/apps/avp`; the other lines are output). A ```yaml block whose first line is `# NAME.yaml`
is written to the scratch folder as NAME.yaml, so the commands that read it find it.

To classify a new command: if it can run here, it runs by itself (an avp command); give it an
OVERRIDES entry when it takes more than a few seconds, a PREPARE entry when it reads a file the
docs only describe, FIGURES when the text quotes what it prints, EXPECT_RC when it is shown
failing. If it cannot run here, add a SKIP pattern with the reason. CLAIMS runs what the prose
says of a command without showing it ("avp-nbv on the same command finds all 18"). Tables are
keyed by (document file name, regex on the command, with `build/apps/avp` written `avp`).

Documents run two at a time (--jobs); the whole test takes about 1.5 min on 2 idle cores.

  python3 tests/docs_commands_test.py --avp build/apps/avp [--repo .] [--scratch DIR]
      [--only README.md] [--list] [--keep] [--jobs 2]
"""

import argparse
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor

# ---- What cannot run here: (regex on the command, reason). First match wins. ----
SKIP = [
    (r"^make (demo|test|bench|fuzz|sanitize)\b", "make target: minutes long, run by CI"),
    (r"^make\b", "make target: builds the project (this test runs a built avp)"),
    (r"^scripts/setup\b", "installs Debian packages (root)"),
    (r"^(cmake|ctest)\b", "configures or builds the project"),
    (r"^scripts/slurm/|\bsbatch\b", "needs a Slurm cluster (tests/slurm_bench_test.sh)"),
    (r"^scripts/bench\b|build/benchmarks/|^taskset\b", "a benchmark program (make bench)"),
    (r"^(rviz2|ros2)\b", "needs a ROS 2 install"),
    (r"\bavp (live|sim ros2)\b", "needs ROS 2 DDS peers (avp sim ros2 / a robot)"),
    (r"\b(ywes|lsam)\b|AVP_ZSL_MODEL", "needs exported model weights"),
    (r"remote://|grpc://|\bavp serve\b", "a network service (tests/remote_segmenter_e2e_test)"),
    (r"^xdg-open\b", "opens a browser"),
    (r"^(\.venv/bin/python|python3?|source \.venv|export PYTHONPATH)\b",
     "Python: the package's own tests run it (python/tests, ctest avp_python_test)"),
    (r"^python\b.*export_", "exports models with the upstream repository"),
    (r"\brobot\.mcap\b|\breplay bag/", "needs a robot's rosbag2 recording"),
]

# ---- What runs: an avp command, or these helpers. ----
RUNNABLE = r"^(avp\b|jq\b|scripts/calibrate-gain\b|scripts/learn-gain\b|for .*\bdo\b[\s\S]*\bavp\b)"

# ---- Commands run changed: shrunk (too long for a test), or kept in the scratch folder: (doc or
# "*", regex, ("append", args) | ("sub", re, repl) | ("keep",), why); the first match applies. A
# changed command's FIGURES are checked only where flagged as not depending on the change.
# Episodes: 2 views instead of 8 (--set comes last, so it wins over --views and --config);
# benches: one seed, 2 views, and for the 7 scenarios of paper.yaml / 3 of robustness.yaml one
# scenario; both with a 160 x 120 camera (the D435 model at a quarter of its resolution) and 10 mm
# voxels: SMALL, a quarter of the time per view.
SMALL = ("--set camera.width=160 --set camera.height=120 --set camera.fx=154 --set camera.fy=154 "
         "--set camera.cx=79.5 --set camera.cy=59.5 --set map.grid.voxel_size_m=0.01")
SEEDS1 = "--seeds 1 --views 2 " + SMALL
ONE = "--scenarios tomato-single-cluster " + SEEDS1
VIEWS2 = "--set episode.views=2 " + SMALL
OVERRIDES = [
    ("README.md", r"tomato-unoriented-start --planner reference-nbv", ("keep",), "its figures"),
    ("experiments.md", r"run --config bad\.yaml", ("keep",), "its figures"),
    ("README.md", r"bench --scenarios tomato-full-occlusion,", ("sub", r"--seeds 5", SEEDS1), "20 episodes"),
    ("README.md", r"bench --config configs/experiments/paper\.yaml --out", ("append", ONE), "210 episodes"),
    ("README.md", r"robustness\.yaml --conditions", ("append", ONE), "120 episodes"),
    ("README.md", r"paper\.yaml --shard 2/4", ("append", ONE), "a quarter of 210 episodes"),
    ("README.md", r"--limit max_bench_episodes", ("append", "--shard 1/100000 --views 2 " + SMALL),
     "420000 episodes: the limit and the whole job list are checked, 1/100000 of it runs"),
    ("README.md", r"bench --scenarios my_plant\.yaml@paper", ("sub", r"--seeds 10", SEEDS1), "80 episodes"),
    ("experiments.md", r"bench --config configs/experiments/paper\.yaml (--out|--seeds 100 --shard)",
     ("sub", r"--seeds 100 |(?=--out)", ONE + " "), "210+ episodes"),
    ("experiments.md", r"bench --scenarios tomato-full-occlusion --planners avp-nbv,predefined",
     ("sub", r"--seeds 5", SEEDS1), "10 episodes"),
    ("experiments.md", r"^for p in", ("sub", r"--seeds 6", SEEDS1), "3 x 6 episodes"),
    ("experiments.md", r"--planner-option avp-nbv:w_diversity=1", ("append", ONE), "210 episodes"),
    ("experiments.md", r"plants/my_plant\.yaml@paper", ("sub", r"--seeds 10 --views 8", SEEDS1), "120 episodes"),
    ("experiments.md", r"tomato-multiple-clusters,plants/my_plant", ("sub", r"--seeds 5", SEEDS1), "30 episodes"),
    ("experiments.md", r"own-plant\.yaml", ("append", SEEDS1), "120 episodes"),
    ("experiments.md", r"robustness\.yaml --conditions", ("append", ONE), "90 episodes"),
    ("experiments.md", r"robustness\.yaml --out", ("append", ONE + " --planners avp-nbv,predefined "
                                                   "--planner-option avp-nbv:candidates.max_candidates=16"),
     "13 conditions x 90 episodes, ~2 h; its conditions set 6 and 12 views over the command line"),
    ("extending.md", r"^avp bench", ("sub", r"--seeds 5", SEEDS1), "10 episodes"),
    ("map-format.md", r"map export plant\.avpmap --out plant\.ot", ("append", "--force"),
     "plant.ot was made earlier for the 'map info plant.ot' shown before it"),
    ("own-plant.md", r"^avp bench --config own\.yaml", ("append", SEEDS1), "120 episodes"),
    ("own-plant.md", r"^avp bench --scenarios", ("sub", r"--seeds 10", SEEDS1), "120 episodes"),
    ("planning.md", r"gain-training\.yaml", ("append", "--seeds 1 --views 3 " + SMALL),
     "80 training episodes"),
    ("planning.md", r"^avp bench",
     ("sub", r"--seeds 5", "--seeds 1 --views 3 --scenarios tomato-single-cluster " + SMALL),
     "35 episodes with the regret probe"),
    ("recording.md", r"^avp bench", ("append", ONE), "210 recorded episodes"),
    ("recording.md", r"--record /data/", ("sub", r"/data/(\S+)", r"data/\1 " + VIEWS2),
     "writes outside the scratch folder; 8 views"),
    ("README.md", r"map build .*--views 8", ("sub", r"--views 8", "--views 3"), "8 views"),
    ("*", r"^avp run\b(?!.*(--print-config|\bhelp\b))", ("append", VIEWS2), "episodes of 8 views"),
]

# ---- Files the docs only describe, made before the first matching command: (doc, regex,
# shell commands, why). ----
EXAMPLE = "cp configs/scenes/example_plant.yaml configs/scenes/example_plant.obj configs/scenes/example_plant.mtl"
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PREPARE = [
    ("README.md", r"replay rosbag2_humble/",
     [f"avp run --scenario tomato-single-cluster --seed 1 --record --out rec_plain {VIEWS2}",
      f"python3 {REPO}/ros/bag/test/write_humble_db3.py --from-mcap rec_plain/episode.mcap "
      "rosbag2_humble"],
     "a Humble bag folder: a recording written in rosbag2's SQLite 3 storage"),
    ("README.md", r"scene check my_plant\.yaml", [f"{EXAMPLE} . && mv example_plant.yaml my_plant.yaml"],
     "my_plant.yaml: the shipped example plant"),
    ("README.md", r"their_fruit\.bt", ["avp map gt --scene my_plant.yaml --voxel-size 0.006 --out their_fruit.bt"],
     "their_fruit.bt: another system's ground truth, 6 mm"),
    ("README.md", r"bench merge out/p/1", [f"avp bench --config configs/experiments/paper.yaml --shard {k}/4 "
                                           f"{ONE} --out out/p/{k}" for k in (1, 3, 4)],
     "the other three shards"),
    ("experiments.md", r"run --config bad\.yaml",
     ["printf 'map: {grid: {voxel_size_m: 0.05}}\\nplanner: {options: {p_unknwn: 0.1}}\\n' > bad.yaml"],
     "bad.yaml as its comment describes it"),
    ("experiments.md", r"bench merge out/p/1", [f"avp bench --config configs/experiments/paper.yaml {ONE} "
                                                f"--shard {k}/4 --out out/p/{k}" for k in (2, 3)],
     "the shards the '...' stands for"),
    ("experiments.md", r"plants/my_plant\.yaml", [f"mkdir -p plants && {EXAMPLE} plants/ && "
                                                  "mv plants/example_plant.yaml plants/my_plant.yaml"],
     "plants/my_plant.yaml: the shipped example plant"),
    ("own-plant.md", r"my_tomato\.yaml", [f"{EXAMPLE} . && mv example_plant.yaml my_tomato.yaml"],
     "my_tomato.yaml: the shipped example plant (the worked example's COLLADA file is not shipped)"),
    ("own-plant.md", r"their_fruit\.bt", ["avp map gt --scene my_tomato.yaml --voxel-size 0.006 --out their_fruit.bt"],
     "their_fruit.bt: another system's ground truth, 6 mm"),
    ("scene-format.md", r"my_plant\.yaml", [f"{EXAMPLE} . && mv example_plant.yaml my_plant.yaml"],
     "my_plant.yaml: the shipped example plant"),
    ("recording.md", r"--record /data/", ["mkdir -p data"], "data/ for /data/"),
    ("map-format.md", r"map info plant\.ot", ["avp map export plant.avpmap --out plant.ot"],
     "plant.ot, which the text exports only after showing it"),
]

# ---- Exit codes other than 0: (doc, regex, code). ----
EXPECT_RC = [
    ("experiments.md", r"run --config bad\.yaml", 1),
]

# ---- Figures the text quotes: (doc, regex, [substrings of the output], checked when shrunk). ----
FIGURES = [
    ("README.md", r"^avp scenes", ["tomato-full-occlusion", "espalier-unoriented-start"], False),
    ("README.md", r"render --scenario tomato-full-occlusion --seed 3",
     [f"out/occl/{f}" for f in ("rgb.png", "depth.png", "instance.png", "class.png", "labels_preview.png",
                                "camera.json", "fruits.json")], False),
    ("README.md", r"help map build", ["--voxel-size", "--out"], False),
    ("README.md", r"map info out/occl\.avpmap", ["instances", "bounds", "memory"], False),
    ("README.md", r"map compare out/occl\.avpmap", ["precision", "F1", "TP", "FP", "FN"], False),
    ("README.md", r"tomato-unoriented-start --planner reference-nbv",
     ["final F1 0.000, fruits found 0/18", "no fruit found: ", "zero gain"], False),
    ("README.md", r"--seed 3 --planner avp-nbv --segmenter oracle --views 8 --out out/run",
     [f"out/run/{f}" for f in ("record.json", "metrics.csv", "map.avpmap", "map.ot", "fruit_voxels.ply",
                               "metrics.svg", "report.html")], True),
    ("README.md", r"--record --record-compression zstd --out out/rec", ["out/rec/episode.mcap"], True),
    ("README.md", r"replay out/rec/episode\.mcap",
     ["MCAP (indexed, zstd chunks)", "metrics identical to the recording's at all"], True),
    ("README.md", r"replay rosbag2_humble/", ["rosbag2 folder: 1 SQLite 3 file", "replayed 2 view(s)"],
     True),
    ("README.md", r"bench --scenarios tomato-full-occlusion,", ["out/b/summary.md"], True),
    ("experiments.md", r"--print-config$", ["scenario: tomato-full-occlusion", "seed: 3", "voxel_size_m: 0.005",
                                           "policy: bayesian", "views: 8", "carving: projective",
                                           "radii_m: [0.28, 0.4, 0.55]", "name: avp-nbv", "name: oracle"], False),
    ("experiments.md", r"run --config bad\.yaml",
     ["map.grid.voxel_size_m (0.05 m) must be in [0.002, 0.02]", "unknown avp-nbv option 'p_unknwn'"], False),
    ("evaluation.md", r"compare ring5\.avpmap --gt gt6\.bt", ["0.5725", "0.9598"], False),
    ("evaluation.md", r"compare ring5\.avpmap --gt gt5\.bt", ["0.8624", "0.9574"], False),
    ("map-format.md", r"map build .*--out plant\.avpmap",
     ["known 1403980, occupied 6369, labelled 1144, instances 7",
      "1116 fruit voxels in 7 instances (5 fruits in the scene)", "wrote plant.avpmap (5970501 bytes)"], False),
    ("map-format.md", r"map info plant\.avpmap",
     ["--views 6 --voxel-size 0.005 --policy bayesian --carving projective --arc-deg 120 --radius 0.449",
      "blocks       4182 of 8^3 voxels (29 with semantics)",
      "1403980 known: 1397611 free, 6369 occupied; 1144 labelled", "labels       fruit 1144 (1116 occupied)",
      "instances    7", "303  (0.692, 0.085, 0.806)      0.965"], False),
    ("map-format.md", r"map info plant\.ot",
     ["1625031 tree nodes", "1116 occupied voxels in a class colour", "5253 in avp's unlabelled grey",
      "1403980 known: 1397611 free, 6369 occupied; 1116 labelled"], False),
    ("map-format.md", r"--out plant\.bt",
     ["wrote plant.bt: 6369 occupied and 1397611 free voxels (86791 bytes)"], False),
    ("map-format.md", r"--out plant\.ot",  # run with --force, which changes nothing it prints
     ["wrote plant.ot: 6369 occupied and 1397611 free voxels, 1116 coloured by class (13000390 bytes)"], True),
    ("map-format.md", r"--out plant\.ply", ["wrote plant.ply: 1116 labelled voxels (27155 bytes)"], False),
    ("map-format.md", r"--out plant2\.avpmap",
     ["wrote plant2.avpmap: 6369 occupied and 1397611 free voxels, 1116 labelled (5969654 bytes)",
      "read plant.ot as OctoMap ColorOcTree .ot; not kept:"], False),
    ("map-format.md", r"--voxel-size 0\.006 --out gt\.bt",
     ["wrote gt.bt: 1455 fruit surface voxels of 5 fruits of 'tomato-single-cluster' at 6 mm (1109 bytes)"], False),
    ("map-format.md", r"compare plant\.ot --gt gt\.bt",
     ["1455 occupied voxels from 1448 leaves, 1 of them pruned", "predicted    1116 occupied voxels labelled fruit",
      "exact              626       490       626       829    0.5609    0.4302    0.4870",
      "+-1 voxel         1116         0      1118       337    1.0000    0.7684    0.8690",
      "(+1, +0, +0), gives exact F1 0.4240", "wrote cmp.json"], False),
    ("scene-format.md", r"scene export --scenario tomato-multiple-clusters --seed 3",
     ["my_scenes/tomato-multiple-clusters.yaml"], False),
    ("recording.md", r"tomato-multiple-clusters --views 8 --record", ["out/run/episode.mcap"], True),
    ("recording.md", r"replay out/run/episode\.mcap$", ["out/replay"], True),
]

# ---- What the prose says of a command without showing it: (doc, run after regex, command,
# [substrings], exit code). ----
CLAIMS = [
    ("README.md", r"tomato-unoriented-start --planner reference-nbv",  # "avp-nbv ... finds all 18"
     "avp run --scenario tomato-unoriented-start --planner avp-nbv --out out/ref-avp-nbv",
     ["fruits found 18/18"], 0),
    ("README.md", r"help map build",  # "a misspelt name gets the nearest one"
     "avp help map biuld", ["did you mean 'build'?"], 2),
    ("experiments.md", r"run --config out/again\.json",  # "the same metrics.csv, apart from the *_ms columns"
     "python3 -c 'import csv; f = lambda p: [{k: v for k, v in r.items() if not k.endswith(\"_ms\")} "
     "for r in csv.DictReader(open(p))]; print(f(\"out/run/metrics.csv\") == f(\"out/again/metrics.csv\"))'",
     ["True"], 0),
]

# ---- Used when jq is not installed (scripts/setup does not install it). ----
JQ_FALLBACK = ("python3 -c 'import json,sys; print(json.dumps(json.load(open(sys.argv[1]))[sys.argv[2]]))' "
               "{file} {key} > {out}")

SHELL_LANGS = {"sh", "bash", "shell", "console", "zsh"}
AVP_LINE = re.compile(r"^(?:[A-Z_][A-Z0-9_]*=\S+\s+)*(?:\./)?(?:build/apps/)?avp(?=\s|$)")


def norm(cmd):
    """The command as the tables see it: build/apps/avp written avp."""
    return re.sub(r"(^|[\s;&|(])(?:\./)?build/apps/avp\b", r"\1avp", cmd)


def strip_comment(line):
    """Drops a shell comment: '#' at the start or after a blank, outside quotes."""
    quote = None
    for i, c in enumerate(line):
        if quote:
            quote = None if c == quote else quote
        elif c in "'\"":
            quote = c
        elif c == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i].rstrip()
    return line.rstrip()


def fenced_blocks(text):
    """Yields (first line number, language, [(line number, text)]) for each fenced block."""
    lines = text.split("\n")
    i = 0
    while i < len(lines):
        m = re.match(r"^(\s*)(`{3,})\s*([\w+-]*)\s*$", lines[i])
        if not m:
            i += 1
            continue
        indent, fence, lang = m.groups()
        body, j = [], i + 1
        while j < len(lines) and not re.match(r"^\s*" + fence + r"\s*$", lines[j]):
            body.append((j + 1, lines[j][len(indent):] if lines[j].startswith(indent) else lines[j].lstrip()))
            j += 1
        yield i + 1, lang.lower(), body
        i = j + 1


def commands_in_block(lang, body):
    """[(line number, command)] of one block, with continuations and for loops joined."""
    lines = [t.strip() for _, t in body if t.strip()]
    prompt = any(t.startswith("$ ") for t in lines)
    if lang not in SHELL_LANGS and not (lang == "" and lines and (prompt or AVP_LINE.match(lines[0]))):
        return []  # not shell, or a plain block of output or a diagram
    out, cur, start, depth, cont = [], "", 0, 0, False
    for ln, raw in body:
        text = raw.strip()
        if not cur:
            if prompt:
                if not text.startswith("$ "):
                    continue  # output of the command before
                text = text[2:]
            elif lang not in SHELL_LANGS and not AVP_LINE.match(text):
                continue  # output or a placeholder in a plain block
            if text in ("...", "…") or not strip_comment(text):
                continue
            start = ln
        text = strip_comment(text)
        joined = cont
        cont = text.endswith("\\")
        text = text[:-1].rstrip() if cont else text
        sep = " " if joined or not depth else "\n"  # a line of a for loop's body, or a continuation
        words = re.findall(r"\w+", text)
        depth += sum(w in ("do", "then") for w in words) - sum(w in ("done", "fi") for w in words)
        cur = cur + sep + text if cur else text
        if not cont and depth <= 0:
            out.append((start, cur.strip()))
            cur, depth = "", 0
    return out


def matches(table, doc, cmd):
    return [row for row in table if row[0] in (doc, "*") and re.search(row[1], norm(cmd))]


def classify(cmd):
    n = norm(cmd)
    for pattern, reason in SKIP:
        if re.search(pattern, n):
            return "SKIP", reason
    if re.search(RUNNABLE, n):
        return "RUN", ""
    return "FAIL", "unclassified: add it to RUN or SKIP in tests/docs_commands_test.py"


def apply_override(doc, cmd):
    """(the command to run, a note) for a shrunk command, else (cmd, '')."""
    for _, _, (kind, *args), why in matches(OVERRIDES, doc, cmd):
        if kind == "keep":
            return cmd, ""
        if kind == "append":
            return cmd + " " + args[0], f"override ({why}): + {args[0]}".replace(SMALL, "SMALL")
        new = re.sub(args[0], args[1], cmd, count=1)
        if new != cmd:
            return new, f"override ({why}): {args[0]!r} -> {args[1]!r}".replace(SMALL, "SMALL")
    return cmd, ""


def setup_scratch(scratch, repo, avp, doc_text):
    if os.path.exists(scratch):
        shutil.rmtree(scratch)
    for d in ("configs", "examples", "scripts"):
        if os.path.isdir(os.path.join(repo, d)):
            shutil.copytree(os.path.join(repo, d), os.path.join(scratch, d), symlinks=True)
    for d in (".bin", "build/apps"):
        os.makedirs(os.path.join(scratch, d), exist_ok=True)
        os.symlink(avp, os.path.join(scratch, d, "avp"))
    for _, lang, body in fenced_blocks(doc_text):  # ```yaml blocks headed '# NAME.yaml'
        m = body and lang in ("yaml", "yml") and re.match(r"^#\s*([\w.-]+\.ya?ml)\b", body[0][1])
        if m:
            with open(os.path.join(scratch, m.group(1)), "w", encoding="utf-8") as f:
                f.write("\n".join(t for _, t in body) + "\n")


def cpu_seconds():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def shell(cmd, cwd, env, timeout):
    """(exit code, output, (wall s, CPU s)) of `bash -c cmd`; killed (124) after timeout s."""
    t0, killed = time.monotonic(), []
    with tempfile.TemporaryFile() as f:
        p = subprocess.Popen(["bash", "-c", "set -e\n" + cmd], cwd=cwd, env=env, stdout=f,
                             stderr=subprocess.STDOUT, start_new_session=True)
        def kill():  # the command's process group: bash and what it started
            killed.append(True)
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        timer = threading.Timer(timeout, kill)
        timer.start()
        _, status, usage = os.wait4(p.pid, 0)  # this command's own CPU time, also with --jobs 2
        timer.cancel()
        p.returncode = rc = 124 if killed else os.waitstatus_to_exitcode(status)
        f.seek(0)
        out = f.read().decode(errors="replace") + (f"\n[killed after {timeout} s]" if killed else "")
    return rc, out, (time.monotonic() - t0, usage.ru_utime + usage.ru_stime)


class Row:
    def __init__(self, doc, line, cmd, status, note="", secs=(0.0, 0.0), output="", claim=False):
        self.doc, self.line, self.cmd, self.status = doc, line, cmd, status
        self.note, self.secs, self.output, self.claim = note, secs, output, claim


def run_command(doc, line, cmd, scratch, env, args, prepared):
    """Runs one RUN command (its PREPARE steps first) and checks its exit code and figures."""
    for _, _, steps, why in matches(PREPARE, doc, cmd):
        key = (doc, why)
        if key in prepared:
            continue
        prepared.add(key)
        for step in steps:
            rc, out, _ = shell(step, scratch, env, args.timeout)
            if rc != 0:
                return Row(doc, line, cmd, "FAIL", f"prepare ({why}) failed: {step}", output=out)
    run, note = apply_override(doc, cmd)
    m = re.match(r"^jq \.(\w+) (\S+) > (\S+)$", run)
    if m and not shutil.which("jq"):
        run, note = JQ_FALLBACK.format(key=m.group(1), file=m.group(2), out=m.group(3)), "jq not installed: python3"
    rc, out, secs = shell(run, scratch, env, args.timeout)
    want = next((r[2] for r in matches(EXPECT_RC, doc, cmd)), 0)
    problems = [] if rc == want else [f"exit code {rc}, expected {want}"]
    figures = [f for row in matches(FIGURES, doc, cmd) if row[3] or not note for f in row[2]]
    problems += [f"missing {f!r}" for f in figures if f not in out]
    notes = [note] if note else []
    if figures and not problems:
        notes.append(f"{len(figures)} figure(s) found")
    if want:
        notes.append(f"exit code {want} as documented")
    return Row(doc, line, cmd, "FAIL" if problems else "PASS", "; ".join(problems + notes), secs, out)


def run_document(doc, path, args):
    """The rows of one document's commands, run in order in its own scratch folder."""
    with open(path, encoding="utf-8") as f:
        text = f.read()
    cmds = [(ln, c) for _, lang, body in fenced_blocks(text) for ln, c in commands_in_block(lang, body)]
    rows = []
    if not cmds:
        return rows
    scratch = os.path.join(args.scratch, re.sub(r"\W", "_", doc))
    runs = any(classify(c)[0] == "RUN" for _, c in cmds) and not args.list
    if runs:
        setup_scratch(scratch, args.repo, args.avp, text)
    env = dict(os.environ, PATH=os.path.join(scratch, ".bin") + os.pathsep + os.environ.get("PATH", ""),
               CI="1", NO_COLOR="1")
    prepared = set()
    for ln, cmd in cmds:
        status, reason = classify(cmd)
        if status != "RUN" or args.list:
            rows.append(Row(doc, ln, cmd, status, reason))
            continue
        rows.append(run_command(doc, ln, cmd, scratch, env, args, prepared))
        print_row(rows[-1], verbose=True)
        for _, _, claim, figures, want in matches(CLAIMS, doc, cmd):
            rc, out, secs = shell(claim, scratch, env, args.timeout)
            missing = [f"missing {f!r}" for f in figures if f not in out]
            problems = ([f"exit code {rc}, expected {want}"] if rc != want else []) + missing
            rows.append(Row(doc, ln, claim, "FAIL" if problems else "PASS",
                            "; ".join(problems) or "what the prose says (no command in the docs)", secs, out,
                            claim=True))
            print_row(rows[-1], verbose=True)
    if runs and not args.keep and all(r.status != "FAIL" for r in rows):
        shutil.rmtree(scratch, ignore_errors=True)
    return rows


def print_row(r, verbose=False):
    cmd = norm(r.cmd).replace("do\n", "do ").replace("\n", "; ")
    cmd = cmd if len(cmd) <= 110 else cmd[:107] + "..."
    secs = f"{r.secs[0]:5.1f}s {r.secs[1]:5.1f}s" if any(r.secs) else " " * 13
    text = f"{r.status:4}  {secs}  {r.doc}:{r.line}  {cmd}" + (f"\n{'':21}-> {r.note}" if r.note else "")
    if verbose and r.status == "FAIL" and r.output:
        text += "\n" + "\n".join(f"{'':21}| {l}" for l in r.output.rstrip().split("\n")[-15:])
    with PRINT_LOCK:
        print(text, flush=True)


PRINT_LOCK = threading.Lock()


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--avp", default=None, help="the avp program (default: REPO/build/apps/avp)")
    ap.add_argument("--repo", default=os.path.dirname(here), help="the repository (README.md, docs/)")
    ap.add_argument("--scratch", default=None, help="scratch folder (default: a temporary one)")
    ap.add_argument("--only", action="append", help="only this document (README.md, experiments.md...)")
    ap.add_argument("--list", action="store_true", help="classify the commands, run nothing")
    ap.add_argument("--keep", action="store_true", help="keep the scratch folders")
    ap.add_argument("--timeout", type=int, default=120, help="seconds per command")
    ap.add_argument("--jobs", type=int, default=2, help="documents at once (default 2)")
    args = ap.parse_args()
    args.repo = os.path.abspath(args.repo)
    args.avp = os.path.abspath(args.avp or os.path.join(args.repo, "build", "apps", "avp"))
    if not args.list and not os.access(args.avp, os.X_OK):
        sys.exit(f"docs_commands: no avp program at {args.avp}")
    tmp = None
    if args.scratch is None:
        tmp = args.scratch = tempfile.mkdtemp(prefix="avp-docs-")
    os.makedirs(args.scratch, exist_ok=True)
    args.scratch = os.path.abspath(args.scratch)
    docs = ["README.md"] + sorted(f for f in os.listdir(os.path.join(args.repo, "docs")) if f.endswith(".md"))
    t0, cpu0, rows = time.monotonic(), cpu_seconds(), []
    print(f"docs_commands: {args.avp}, scratch {args.scratch}\n  (times: wall, CPU; SMALL = {SMALL})", flush=True)
    docs = [d for d in docs if not args.only or d in args.only]
    paths = [os.path.join(args.repo, d if d == "README.md" else "docs/" + d) for d in docs]
    with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:  # documents at once, each in order
        # The longest documents first; the table keeps the order of the docs.
        order = sorted(range(len(docs)), key=lambda i: docs[i] not in ("README.md", "experiments.md"))
        futures = {i: pool.submit(run_document, docs[i], paths[i], args) for i in order}
        for i in range(len(docs)):
            rows += futures[i].result()
    total, cpu = time.monotonic() - t0, cpu_seconds() - cpu0
    if tmp and not args.keep:
        shutil.rmtree(tmp, ignore_errors=True)

    print("\n==== every command ====")
    for r in rows:
        print_row(r)
    count = lambda s: sum(r.status == s for r in rows)
    claims = sum(r.claim for r in rows)
    print(f"\n{len(rows) - claims} commands in the docs, {claims} claims of the prose: {count('PASS')} passed, "
          f"{count('FAIL')} failed, {count('SKIP')} skipped" + (f", {count('RUN')} to run" if args.list else "")
          + f"; {total:.1f} s ({cpu:.1f} s of CPU)")
    reasons = {}
    for r in rows:
        if r.status == "SKIP":
            reasons[r.note] = reasons.get(r.note, 0) + 1
    for reason, n in sorted(reasons.items(), key=lambda kv: -kv[1]):
        print(f"  skipped {n:3}  {reason}")
    for r in rows:
        if r.status == "FAIL":
            print(f"FAILED: {r.doc}:{r.line}: {norm(r.cmd)}: {r.note}")
    return 1 if count("FAIL") else 0


if __name__ == "__main__":
    sys.exit(main())
