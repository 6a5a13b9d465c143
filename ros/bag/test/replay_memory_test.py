#!/usr/bin/env python3
"""A robot's bag replays in bounded memory, whatever its size (issue 33).

Writes two synthetic RealSense bags with make_robot_bag (320 x 240 at 30 Hz: 60 frames, about
23 MB, and 600 frames, about 230 MB) and replays each with `avp replay` under
`--limit max_file_bytes=50000000` (a 50 MB cap on any file avp reads whole: the big bag is more
than four times it). Each replay's peak resident memory comes from os.wait4. The big bag must
replay (the cap does not apply to a streamed bag), reading every message and fusing the last
second's one view in both, and its peak may exceed the small bag's by at most 16 MB although it is
200 MB larger: memory does not grow with the bag (measured: 126.0 and 126.9 MB).
Usage: replay_memory_test.py --avp AVP --make-bag MAKE_ROBOT_BAG --out DIR
"""

import argparse
import os
import shutil
import subprocess
import sys


def run_measured(argv):
    """Runs argv; returns (exit code, output, peak RSS in MB)."""
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    out = proc.stdout.read().decode(errors="replace")
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return proc.returncode, out, usage.ru_maxrss / 1024.0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--avp", required=True)
    ap.add_argument("--make-bag", required=True)
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    shutil.rmtree(a.out, ignore_errors=True)
    os.makedirs(a.out)
    cap = 50_000_000
    peaks = {}
    sizes = {}
    for name, frames in (("small", 60), ("big", 600)):
        bag = os.path.join(a.out, f"{name}.mcap")
        subprocess.run([a.make_bag, "--out", bag, "--frames", str(frames), "--width", "320",
                        "--height", "240"], check=True, stdout=subprocess.DEVNULL)
        sizes[name] = os.path.getsize(bag)
        # Every message is read; one view is fused, the last second's (the same map size).
        start_s = frames / 30.0 - 0.1
        code, out, peak = run_measured(
            [a.avp, "--limit", f"max_file_bytes={cap}", "replay", bag, "--segmenter", "color",
             "--set", f"replay.start_s={start_s}", "--out", os.path.join(a.out, name)])
        if code != 0:
            print(f"FAIL {name}: avp replay exited {code}:\n{out}")
            return 1
        if f"frames: {frames} colour/depth pairs, 1 fused" not in out:
            print(f"FAIL {name}: expected {frames} pairs and 1 view fused:\n{out}")
            return 1
        peaks[name] = peak
        print(f"{name}: {sizes[name] / 1e6:.0f} MB bag, peak RSS {peak:.0f} MB")
    if sizes["big"] < 4 * cap:
        print(f"FAIL: the big bag ({sizes['big']} bytes) is not 4 x the cap ({cap})")
        return 1
    growth = peaks["big"] - peaks["small"]
    print(f"peak RSS grows by {growth:.1f} MB for {(sizes['big'] - sizes['small']) / 1e6:.0f} MB "
          "more bag")
    if growth > 16.0:
        print("FAIL: memory grows with the bag")
        return 1
    print("replay_memory: ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
