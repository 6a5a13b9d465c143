#!/usr/bin/env bash
# `avp run --print-config` writes the effective configuration as YAML that `--config` reads back
# unchanged; flags apply over a config file; unknown keys are errors naming the key; `--planner
# help` and `--segmenter help` list what is registered with their options.
# Usage: print_config_test.sh AVP DIR
set -euo pipefail
avp=$1
dir=$2
rm -rf "$dir"
mkdir -p "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }

"$avp" run --print-config --scenario tomato-full-occlusion --seed 3 --planner isler-oa \
  --planner-option candidates.radii_m=0.3,0.5 --planner-option cost_weight=0.25 \
  --segmenter-option p_merge=0 --map-option semantics.policy=reference-max \
  --set episode.views=5 --no-noise > "$dir/a.yaml"
"$avp" run --config "$dir/a.yaml" --print-config > "$dir/b.yaml"
cmp "$dir/a.yaml" "$dir/b.yaml" || fail "the configuration did not read back unchanged"
for line in "scenario: tomato-full-occlusion" "seed: 3" "name: isler-oa" "radii_m: \[0.3, 0.5\]" \
            "cost_weight: 0.25" "p_merge: 0" "policy: reference-max" "views: 5" \
            "enabled: false"; do
  grep -q "$line" "$dir/a.yaml" || fail "'$line' not in the printed configuration"
done
# Flags apply over the file.
"$avp" run --config "$dir/a.yaml" --views 7 --print-config > "$dir/c.yaml"
grep -q "views: 7" "$dir/c.yaml" || fail "--views did not apply over --config"

# A flag naming another planner or scene source replaces the file's (and its options).
"$avp" run --config "$dir/a.yaml" --planner predefined --scene "${AVP_CONFIG_DIR:-configs}/scenes/example_plant.yaml" \
  --print-config > "$dir/d.yaml" || fail "--planner / --scene over a printed file"
grep -q "name: predefined" "$dir/d.yaml" || fail "--planner did not apply"
grep -q '^scenario: ""' "$dir/d.yaml" || fail "--scene did not replace the scenario"
# Only a valid configuration is printed.
if "$avp" run --set camera.width=-13 --print-config > "$dir/out.txt" 2>&1; then
  fail "an invalid configuration was printed"
fi
grep -q "camera.width (-13) must be > 0" "$dir/out.txt" || fail "$(cat "$dir/out.txt")"

# Unknown keys and bad values are named.
echo "episode: {viewz: 3}" > "$dir/bad.yaml"
if "$avp" run --config "$dir/bad.yaml" --print-config > "$dir/out.txt" 2>&1; then
  fail "an unknown key was accepted"
fi
grep -q "unknown run configuration key 'episode.viewz'" "$dir/out.txt" || fail "$(cat "$dir/out.txt")"
if "$avp" run --planner-option nope=1 --print-config > "$dir/out.txt" 2>&1; then
  fail "an unknown planner option was accepted"
fi
grep -q "unknown avp-nbv option 'nope' (known: ray_stride_px" "$dir/out.txt" || fail "$(cat "$dir/out.txt")"

# The registries, with their options.
"$avp" run --planner help > "$dir/planners.txt"
for name in avp-nbv predefined reference-nbv random isler-pc oracle-nbv oracle-detect; do
  grep -q "^  $name " "$dir/planners.txt" || fail "planner $name not listed"
done
"$avp" run --planner help:avp-nbv > "$dir/avp-nbv.txt"
grep -q "p_unknown=0.05" "$dir/avp-nbv.txt" || fail "avp-nbv's options not listed"
"$avp" run --segmenter help > "$dir/segmenters.txt"
for name in oracle oracle-perfect color ywes lsam "remote://"; do
  grep -q "^  $name" "$dir/segmenters.txt" || fail "segmenter $name not listed"
done
echo "print_config_test: ok"
