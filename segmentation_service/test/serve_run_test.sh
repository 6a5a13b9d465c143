#!/usr/bin/env bash
# `avp serve segmentation` in the background, then the same episode through it
# (--segmenter remote://127.0.0.1:PORT) and in-process (--segmenter oracle): metrics.csv must be
# identical apart from the timing columns (*_ms). Finally the server must stop cleanly on SIGTERM.
#
# usage: serve_run_test.sh AVP_BINARY WORK_DIR
set -euo pipefail

avp="$1"
work="$2"
rm -rf "$work"
mkdir -p "$work"
port_file="$work/port"
log="$work/serve.log"

fail() {
  echo "serve_run_test: $*" >&2
  echo "---- server log ($log) ----" >&2
  cat "$log" >&2 || true
  exit 1
}

"$avp" serve segmentation --host 127.0.0.1 --port 0 --port-file "$port_file" >"$log" 2>&1 &
server=$!
stop_server() {
  if kill -0 "$server" 2>/dev/null; then
    kill -TERM "$server" 2>/dev/null || true
    wait "$server" 2>/dev/null || true
  fi
}
trap stop_server EXIT

for _ in $(seq 1 600); do
  [ -s "$port_file" ] && break
  kill -0 "$server" 2>/dev/null || fail "the server exited before listening"
  sleep 0.1
done
[ -s "$port_file" ] || fail "no port in $port_file after 60 s"
port="$(cat "$port_file")"
echo "serve_run_test: server on 127.0.0.1:$port"

run() {  # run SEGMENTER OUT
  "$avp" run --scenario tomato-full-occlusion --seed 3 --views 3 --segmenter "$1" --out "$2" \
    >"$2.log" 2>&1 || { cat "$2.log" >&2; fail "avp run --segmenter $1 failed"; }
}
run "remote://127.0.0.1:$port" "$work/A"
run oracle "$work/B"

# Every column but the timings (header names ending in _ms).
metric_columns() {
  awk -F, 'NR == 1 { for (i = 1; i <= NF; ++i) keep[i] = ($i !~ /_ms$/) }
           { out = ""; sep = ""
             for (i = 1; i <= NF; ++i) if (keep[i]) { out = out sep $i; sep = "," }
             print out }' "$1"
}
metric_columns "$work/A/metrics.csv" >"$work/A.metrics"
metric_columns "$work/B/metrics.csv" >"$work/B.metrics"
[ "$(wc -l <"$work/A.metrics")" -eq 4 ] || fail "expected a header and 3 views in A/metrics.csv"
if ! diff -u "$work/B.metrics" "$work/A.metrics"; then
  fail "metrics through the server differ from the in-process ones"
fi
if grep -q "segment-error" "$work/A/metrics.csv"; then
  fail "a step's segmentation failed through the server"
fi

kill -TERM "$server"
rc=0
wait "$server" || rc=$?
trap - EXIT
[ "$rc" -eq 0 ] || fail "the server exited with $rc on SIGTERM"
grep -q "SIGTERM: shutting down" "$log" || fail "no shutdown message in the log"
grep -q "stopped after 3 answered" "$log" || fail "the server did not answer the 3 requests"
[ ! -e "$port_file" ] || fail "the port file was not removed at shutdown"
echo "serve_run_test: metrics.csv identical apart from timings; server stopped cleanly"
