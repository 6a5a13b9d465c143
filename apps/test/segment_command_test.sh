#!/usr/bin/env bash
# `avp segment` end to end on the ywes stub models (zsl/test/stubs/make_stubs.py): a 1024x768 image
# of colour (200, 50, 10) with the prompt "a, b" lights the stub detector's planted anchors a_0 and
# a_1 (the CLIP stub embeds "a" as e_0 and "b" as e_1). instances.json must hold exactly those two
# instances, with the un-letterboxed boxes and the stub SAM masks derived in zsl/test/ywes_test.cpp:
#   a: box (211.2, 0)-(313.6, 44.8), mask columns 212..311 x rows 0..43 less the 2 bottom corners
#   b: box (192, 294.4)-(345.6, 499.2), mask columns 192..343 x rows 296..499 less its 4 corners
# and overlay.png must exist. A missing model directory must fail with a message naming it.
#
# usage: segment_command_test.sh AVP_BINARY STUB_DIR WORK_DIR
set -euo pipefail

avp="$1"
stubs="$2"
work="$3"
python=/usr/bin/python3
rm -rf "$work"
mkdir -p "$work"

fail() {
  echo "segment_command_test: $*" >&2
  exit 1
}

# A binary PPM (OpenCV reads it like any other image).
"$python" - "$work/image.ppm" <<'EOF'
import sys
w, h = 1024, 768
with open(sys.argv[1], "wb") as f:
    f.write(b"P6\n%d %d\n255\n" % (w, h))
    f.write(bytes([200, 50, 10]) * (w * h))
EOF

"$avp" segment --image "$work/image.ppm" --prompt "a, b" --backend "ywes://$stubs/ywes" \
  --out "$work/out" >"$work/stdout.txt" 2>"$work/stderr.txt" ||
  { cat "$work/stdout.txt" "$work/stderr.txt" >&2; fail "avp segment failed"; }
cat "$work/stdout.txt"
[ -s "$work/out/overlay.png" ] || fail "no overlay.png"
grep -q "#0 a  score 0.70" "$work/stdout.txt" || fail "no summary line for instance a"
grep -q "timings (ms): tokenize" "$work/stdout.txt" || fail "no timings line"

"$python" - "$work/out/instances.json" <<'EOF'
import json, sys

doc = json.load(open(sys.argv[1]))
def check(cond, what):
    if not cond:
        sys.exit("segment_command_test: " + what + "\n" + json.dumps(doc, indent=1)[:2000])

check(doc["backend"] == "ywes", "backend")
check(doc["prompt"] == "a, b", "prompt")
check(doc["image"]["width"] == 1024 and doc["image"]["height"] == 768, "image size")
stages = [t["stage"] for t in doc["timings"]]
check(stages == ["tokenize", "text", "letterbox", "detector", "nms", "sam_encoder",
                 "sam_decoder", "masks"], "stages %s" % stages)
inst = doc["instances"]
check(len(inst) == 2, "two instances")
expected = {
    "a": ([211.2, 0.0, 313.6, 44.8], 100 * 44 - 2),
    "b": ([192.0, 294.4, 345.6, 499.2], 152 * 204 - 4),
}
for i in inst:
    box, area = expected[i["label"]]
    check(all(abs(g - w) < 1e-3 for g, w in zip(i["box"], box)), "box of " + i["label"])
    check(i["area"] == area, "area of %s: %d, expected %d" % (i["label"], i["area"], area))
    check(i["class"] == "fruit", "class")
    check(abs(i["score"] - 0.7) < 1e-3, "score")
    check(i["mask_score"] == 0.875, "mask_score")
    rle = i["rle"]
    check(rle["size"] == [768, 1024], "rle size")
    check(sum(rle["counts"]) == 1024 * 768, "rle counts sum")
    check(sum(rle["counts"][1::2]) == area, "rle foreground")
    check(len(i["polygons"]) == 1 and len(i["polygons"][0]) >= 4, "one polygon")
    xs = [p[0] for p in i["polygons"][0]]
    ys = [p[1] for p in i["polygons"][0]]
    x0 = {"a": 212, "b": 192}[i["label"]]
    x1 = {"a": 311, "b": 343}[i["label"]]
    check(min(xs) == x0 and max(xs) == x1, "polygon x extent %s" % [min(xs), max(xs)])
    y0 = {"a": 0, "b": 296}[i["label"]]
    y1 = {"a": 43, "b": 499}[i["label"]]
    check(min(ys) == y0 and max(ys) == y1, "polygon y extent %s" % [min(ys), max(ys)])
print("segment_command_test: instances.json OK")
EOF

# --models with a directory that does not exist: an error naming it, exit status 1.
if "$avp" segment --image "$work/image.ppm" --backend ywes --models "$work/no-models" \
  --out "$work/out2" >"$work/bad.txt" 2>&1; then
  fail "a missing model directory succeeded"
fi
grep -q "$work/no-models" "$work/bad.txt" || { cat "$work/bad.txt" >&2; fail "error does not name the directory"; }
# The networks on a model server: `avp serve models` serves the stub directory's networks over
# KServe v2 on loopback, and `avp segment --model-server` gives the very same instances.json (all
# but the timings) as in process, with dynamic batching on (of the stubs only the text encoder
# has a batch axis: its request goes through the batcher); killed with SIGTERM, the server stops,
# removes its port file and reports what it batched.
"$avp" serve models --model-dir "$stubs/ywes" --port 0 --port-file "$work/port" --threads 8 \
  --max-batch 4 --batch-delay-us 500 >"$work/serve.txt" 2>&1 &
server=$!
trap 'kill $server 2>/dev/null || true' EXIT
for _ in $(seq 1 100); do [ -s "$work/port" ] && break; sleep 0.1; done
[ -s "$work/port" ] || { cat "$work/serve.txt" >&2; fail "avp serve models wrote no port file"; }
port=$(cat "$work/port")
grep -q "model 'detector': READY" "$work/serve.txt" || { cat "$work/serve.txt" >&2; fail "no detector"; }
grep -q "model 'text': READY (CPUExecutionProvider, batched: up to 4 rows, waiting at most 500 us)" \
  "$work/serve.txt" || { cat "$work/serve.txt" >&2; fail "the text model is not batched"; }
grep -q "model 'detector': READY (CPUExecutionProvider, not batched: input 'images' has a fixed" \
  "$work/serve.txt" || { cat "$work/serve.txt" >&2; fail "the detector's batching is not reported"; }
"$avp" segment --image "$work/image.ppm" --prompt "a, b" --backend "ywes://$stubs/ywes" \
  --model-server "grpc://127.0.0.1:$port" --out "$work/remote" >"$work/remote.txt" 2>&1 ||
  { cat "$work/remote.txt" "$work/serve.txt" >&2; fail "avp segment --model-server failed"; }
"$python" - "$work/out/instances.json" "$work/remote/instances.json" <<'EOF2'
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
for d in (a, b):
    d.pop("timings", None)
    d.pop("total_ms", None)
if a != b:
    sys.exit("segment_command_test: --model-server gave another instances.json")
print("segment_command_test: --model-server gives the same instances.json")
EOF2
# A server that is not there: an error naming the address.
if "$avp" segment --image "$work/image.ppm" --prompt a --backend "ywes://$stubs/ywes" \
  --model-server grpc://127.0.0.1:1 --out "$work/out3" >"$work/bad3.txt" 2>&1; then
  fail "a missing model server succeeded"
fi
grep -q "127.0.0.1:1" "$work/bad3.txt" || { cat "$work/bad3.txt" >&2; fail "error does not name the server"; }
kill -TERM $server
wait $server || fail "avp serve models did not stop cleanly on SIGTERM"
trap - EXIT
[ ! -e "$work/port" ] || fail "the port file was left behind"
grep -q "answered" "$work/serve.txt" || fail "no stop line"
grep -q "model 'text': 1 requests in 1 runs" "$work/serve.txt" ||
  { cat "$work/serve.txt" >&2; fail "no batching report for the text model"; }
# The segmentation service with its networks batched in process (--max-batch): the instances
# share the stubs' text encoder (its only network with a batch axis), the service says so at
# start and counts its calls at stop, and four clients at once get the instances.json of
# `avp segment` in process (the stacking itself: zsl.RemoteModelTest.InProcessBatching*).
# The spec ywes://DIR is served as model 'ywes' (clients name it in remote://HOST:PORT/ywes).
AVP_ZSL_DEVICE=cpu "$avp" serve segmentation --backend "ywes://$stubs/ywes" \
  --host 127.0.0.1 --port 0 --port-file "$work/seg-port" --threads 4 --instances 4 --max-batch 4 \
  --batch-delay-us 2000 >"$work/seg-serve.txt" 2>&1 &
segserver=$!
trap 'kill $segserver 2>/dev/null || true' EXIT
for _ in $(seq 1 100); do [ -s "$work/seg-port" ] && break; sleep 0.1; done
[ -s "$work/seg-port" ] || { cat "$work/seg-serve.txt" >&2; fail "avp serve segmentation wrote no port file"; }
grep -q "network 'text' (.*clip_stub_text.onnx): shared by the instances, batched: up to 4 rows" \
  "$work/seg-serve.txt" || { cat "$work/seg-serve.txt" >&2; fail "no batched text network"; }
grep -q "model 'ywes': READY" "$work/seg-serve.txt" ||
  { cat "$work/seg-serve.txt" >&2; fail "ywes://DIR is not served as model 'ywes'"; }
segport=$(cat "$work/seg-port")
pids=()
for p in a b c; do
  "$avp" segment --image "$work/image.ppm" --prompt "$p" --backend "ywes://$stubs/ywes" \
    --out "$work/local-$p" >"$work/local-$p.txt" 2>&1 || fail "avp segment $p failed"
  "$avp" segment --image "$work/image.ppm" --prompt "$p" \
    --backend "remote://127.0.0.1:$segport/ywes" --out "$work/served-$p" >"$work/served-$p.txt" 2>&1 &
  pids+=($!)
done
for pid in "${pids[@]}"; do wait "$pid" || fail "a client of the batched service failed"; done
kill -TERM $segserver
wait $segserver || fail "avp serve segmentation did not stop cleanly"
trap - EXIT
grep -q "network 'text': 3 calls in" "$work/seg-serve.txt" ||
  { cat "$work/seg-serve.txt" >&2; fail "the batched text network did not count 3 calls"; }
"$python" - "$work" <<'EOF2'
import json, sys
for p in "abc":
    a, b = (json.load(open("%s/%s-%s/instances.json" % (sys.argv[1], kind, p)))
            for kind in ("local", "served"))
    strip = lambda d: d["instances"]
    if strip(a) != strip(b) or len(a["instances"]) != 1:
        sys.exit("segment_command_test: the batched service answered %s otherwise" % p)
print("segment_command_test: the batched service gives the in-process instances")
EOF2
echo "segment_command_test: OK"
