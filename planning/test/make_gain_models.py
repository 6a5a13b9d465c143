#!/usr/bin/python3
"""Writes the learned gain models the C++ tests load (planning/test/learned_gain_test.cpp) into
OUT_DIR: a good one (a small tree ensemble with a correct manifest) with its check rows, and the
bad ones avp must refuse by name. The feature names, version and hash are read from the planner's
sources, so the good model matches the code under test; the trees come from scripts/learn-gain.

  make_gain_models.py REPO_ROOT OUT_DIR
"""

import importlib.machinery
import json
import os
import re
import sys

import numpy as np
import onnx
from onnx import helper

root, out = sys.argv[1], sys.argv[2]
os.makedirs(out, exist_ok=True)
learn = importlib.machinery.SourceFileLoader(
    "learn_gain", os.path.join(root, "scripts", "learn-gain")).load_module()

with open(os.path.join(root, "planning", "src", "view_features.cpp"), encoding="utf-8") as f:
    source = f.read()
block = source[source.index("kNames = {"):]
names = re.findall(r'"([a-z_0-9]+)"', block[:block.index("};")])
with open(os.path.join(root, "planning", "include", "avp", "planning", "view_features.h"),
          encoding="utf-8") as f:
    version = int(re.search(r"kViewFeatureVersion = (\d+);", f.read()).group(1))


def fnv(texts):
    h = 14695981039346656037
    for t in texts:
        for b in (t + "\n").encode():
            h ^= b
            h = (h * 1099511628211) % (1 << 64)
    return f"{h:016x}"


feature_hash = fnv([f"avp-view-features/{version}"] + names)
manifest = {"format": learn.FORMAT, "feature_version": version, "feature_hash": feature_hash,
            "feature_names": names, "data": {"rows": 400, "scenarios": ["synthetic"],
                                             "seeds": "0-0 (1)"},
            "training": {"model_hash": "test"}}

# A model of a known function: the share grows with the first feature, falls with the second.
rng = np.random.RandomState(0)
X = rng.rand(400, len(names)).astype(np.float32)
y = 0.7 * X[:, 0] - 0.3 * X[:, 1] + 0.2
model = learn.fit(X, y, {"max_iter": 20, "max_depth": 3, "learning_rate": 0.3,
                         "max_leaf_nodes": 8, "min_samples_leaf": 5, "l2_regularization": 0.0})


def write(name, blob):
    with open(os.path.join(out, name), "wb") as f:
        f.write(blob)


good = learn.to_onnx(model, len(names), manifest)
write("good.onnx", good)
with open(os.path.join(out, "good.onnx.check.json"), "w", encoding="utf-8") as f:
    json.dump({"tolerance": 1e-5, "rows": X[:32].astype(float).tolist(),
               "predictions": model.predict(X[:32]).tolist()}, f)
write("truncated.onnx", good[: len(good) // 2])
write("not_onnx.onnx", b"this is not an ONNX model\n")


def variant(name, change_manifest=None, change_model=None):
    m = onnx.load_from_string(good)
    if change_manifest is not None:
        doc = dict(manifest)
        change_manifest(doc)
        del m.metadata_props[:]
        if doc:
            helper.set_model_props(m, {learn.MANIFEST_KEY: json.dumps(doc)})
    if change_model is not None:
        change_model(m)
    write(name, m.SerializeToString())


variant("no_manifest.onnx", change_manifest=lambda d: d.clear())
variant("old_version.onnx", change_manifest=lambda d: d.update(feature_version=version + 7))
variant("other_names.onnx", change_manifest=lambda d: d.update(
    feature_names=list(reversed(names)), feature_hash="0123456789abcdef"))
variant("other_format.onnx", change_manifest=lambda d: d.update(format="someone-elses/3"))


def nan_base(m):
    for a in m.graph.node[0].attribute:
        if a.name == "base_values":
            a.floats[0] = float("nan")


def wide_input(m):
    m.graph.input[0].type.tensor_type.shape.dim[1].dim_value = len(names) + 1


variant("nan.onnx", change_model=nan_base)
variant("wide_input.onnx", change_model=wide_input)
print(f"make_gain_models: {len(names)} features, hash {feature_hash}, models in {out}")
