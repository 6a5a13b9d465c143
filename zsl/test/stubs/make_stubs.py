#!/usr/bin/python3
"""Writes stub ONNX model directories for the zsl runtime tests (docs/zero-shot-models.md §8).

Usage: /usr/bin/python3 make_stubs.py OUT_DIR [--clip-merges FILE] [--bert-vocab FILE]

Run by the CTest fixture `zsl_make_stubs` (FIXTURES_SETUP zsl_stubs) into
<build>/zsl/stub_models. Needs Debian's python3-onnx (onnx 1.12) and numpy; nothing is downloaded.
Every stub carries the REAL I/O contract of the model it stands for (names, element types, ranks,
static dimensions) but computes a small, exactly known function. All models are opset 17 / IR 8 and
pass onnx.checker.check_model. Each model directory has a manifest.json (format of
docs/zero-shot-models.md, "Model directory and manifest") whose `bytes` and `sha256` are those of
the written files and whose `inputs`/`outputs` are read back from the written graphs.

Directories (OUT_DIR/...):

  ywes/          detector (yoloworld.txtfeats/1, N = 32), text (clip.text/1), segmenter.encoder
                 (evitsam.encoder/1, S = 512), segmenter.decoder (evitsam.decoder.single/1)
  ywes_logits/   as ywes/, the detector emits logits; manifest score_activation "sigmoid"
  ywes_baked/    detector yoloworld.baked/1 (nc = 2, baked_names ["tomato", "leaf"]), no text model
  ywes_baked_logits/  as ywes_baked/, logits + "sigmoid"
  ywes_transposed/    detector with output0 [1,8400,4+N], manifest declares layout "[A,4+N]"
  ywes_official_shapes/  the stubs with the I/O shapes of the official exports: EfficientViT-SAM
                 (encoder [batch_size,3,S,S] -> [?,256,?,?], decoder masks [?,1,?,?]) and
                 YOLO-World (output0 [?,?,?]); the manifest states the docs' static shapes
  lsam/          grounding (gdino.ort/1, L dynamic), segmenter.encoder, segmenter.decoder
  ywes_heavy_text/  (only with --bench) ywes whose text model does transformer-sized work:
                 clip_text_heavy(), for bench_zsl --serve-clients; not used by tests
  wrong/<case>/  a complete ywes or lsam set with one defect (see WRONG below); every case must fail
                 at load time with text naming the model role, the tensor and the expectation.

The planted functions (the constants are repeated in zsl/test/*_test.cpp, which assert them):

YOLO-World, text features (detector/yolo_world_stub_txt32.onnx)
  images f32 [1,3,640,640], txt_feats f32 [1,32,512] -> output0 f32 [1,36,8400]
  rows 0..3 (cx, cy, w, h; letterboxed 640 px): zero except at the planted anchors PLANTED_ANCHORS,
  where they are the planted box. Rows 4+n:
  score[n, a] = clip(sum_k txt_feats[n, k] * P[k, a], 0, 1) * mean(images[0, 0]), the mean of the
  R channel over the whole 640x640 input (padding included), with P [512, 8400] zero except
  P[k, a_k] = 1 for the planted pairs (k, a_k) of PLANTED_ANCHORS.
  Supports: the right class fires at the right anchor (a one-hot txt_feats row k lights anchor a_k);
  exact un-letterboxing (planted boxes); RGB order, /255 and pad 114 (through mean(R)); zeroed
  unused txt_feats rows score 0.
  The logit variant outputs 20 * score - 10 in rows 4+ (boxes unchanged): sigmoid gives ~1 / ~0.
YOLO-World, baked (detector/yolo_world_stub_baked2.onnx): images only -> output0 [1,6,8400]; as
  above with txt_feats fixed to the one-hot rows e_0 ("tomato": anchor a_0) and e_1 ("leaf": a_1).
CLIP text (text/clip_stub_text.onnx)
  input_ids int64 [B,77] -> text_embeds f32 [B,512]:
  E[b, t] = table[input_ids[b, t] mod 16] if input_ids[b, t] < CLIP_STUB_MAX_ID else 0 (table =
  16x16 identity: a one-hot of the id's bucket); C = CumSum(E, axis 1) (a causal stand-in);
  pooled[b] = C[b, ArgMax(input_ids[b])] (ArgMax picks the FIRST maximum, i.e. the first EOT);
  text_embeds[b] = pooled[b] @ W with W [16, 512] = [I_16 | 0] (a fixed projection: MatMul by I_16
  then a zero Pad; NOT normalised).
  So text_embeds[b, c] (c < 16) = the number of tokens up to the first EOT whose id is below 562
  (the fixture's SOT; SOT and EOT themselves, fixture or real, count nothing) and whose
  id mod 16 = c; dims 16..511 are 0. Supports: pooling at the first EOT, 0-padding ==
  EOT-padding, truncation keeps EOT, tokenizer -> encoder -> L2 -> cache.
SAM encoder (segmenter/evitsam_stub_encoder.onnx), S = 512
  input_image f32 [1,3,512,512] -> image_embeddings f32 [1,256,64,64]:
  AveragePool 8x8 / stride 8, then a 1x1 conv without bias whose output channel c copies input
  channel c mod 3. A mean-colour image (normalised to 0) gives 0; padding shows as 0 cells.
SAM decoder (segmenter/evitsam_stub_decoder_single.onnx)
  image_embeddings f32 [1,256,64,64], point_coords f32 [B,N,2], point_labels f32 [B,N] ->
  masks f32 [B,1,256,256], iou_predictions f32 [B,1].
  With (x0, y0) = point_coords[b, 0] and (x1, y1) = point_coords[b, 1] in the 1024 prompt frame:
  masks[b, 0, i, j] = +10 if x0 <= 4(j+0.5) <= x1 and y0 <= 4(i+0.5) <= y1 and the first two labels
  are (2, 3); -10 otherwise (all -10 for any other labels, or N < 2). iou_predictions = 0.875.
  The embedding is read (its mean, times 0) so the graph uses every input.
  Supports exact masks: box (100,200)-(300,500) lights columns 25..74 and rows 50..124.
Grounding DINO (grounding/groundingdino_stub_800x1200.onnx)
  img f32 [1,3,800,1200], input_ids / position_ids / token_type_ids int64 [1,L], attention_mask bool
  [1,L], text_token_mask bool [1,L,L] -> logits f32 [1,900,256], boxes f32 [1,900,4].
  logits[0, q, t] (pre-sigmoid) = +10 if q is a planted query whose bucket set contains
  input_ids[0, t] mod 97 and attention_mask[0, t]; -10 otherwise, and -10 for t >= L.
  boxes[0, q] = the planted normalised (cx, cy, w, h) for planted queries, 0 elsewhere.
  The other inputs are read (times 0). With the stub vocabulary (grounding/bert_stub_vocab.txt),
  "tomato" (id 1100, bucket 33) lights query 7, "leaf" (1101, bucket 34) query 123, "stem" (1102,
  bucket 35) query 899, and "cat" / "dog" (1103 / 1104, buckets 36 / 37) both light query 456.
  Supports: phrases -> queries, box/text thresholds, box scaling.

WRONG (each under wrong/<case>/, a full set with this one defect; the manifest's inputs/outputs
describe the defective graph faithfully unless the case is about the manifest):
  renamed_input         detector input 'image' instead of 'images'
  int32_labels          segmenter.decoder point_labels int32 (expects float32)
  int32_input_ids       text input_ids int32 (expects int64)
  wrong_rank            detector txt_feats [32,512] (expects rank 3 [1,N,512])
  wrong_static_dim      segmenter.encoder image_embeddings [1,256,32,32] (expects [1,256,64,64])
  transposed_output     detector output0 [1,8400,36] without postprocess.layout "[A,4+N]"
  missing_output        segmenter.decoder without iou_predictions
  truncated_file        segmenter.decoder file cut to half (manifest bytes = the cut size): ORT
                        cannot parse it
  size_mismatch         text model listed with bytes + 1
  missing_file          segmenter.encoder file absent (state MISSING)
  sha256_mismatch       detector sha256 wrong (only caught when sha256 checking is on)
  declared_io_mismatch  manifest declares txt_feats [1,16,512]; the model has [1,32,512]
  encoder_size_mismatch manifest segmenter.encoder preprocess.size 1024; the model's S is 512
  n_max_mismatch        manifest detector postprocess.n_max 16; the model's N is 32
  extra_input           segmenter.decoder with an extra input 'mask_input' [1,1,256,256]
"""

import argparse
import hashlib
import json
import os
import shutil
import sys

try:
    import numpy as np
    import onnx
    from onnx import TensorProto, helper, numpy_helper
except ImportError as error:  # the fixture must fail, not skip
    sys.stderr.write(
        "make_stubs: cannot import onnx/numpy with %s (%s); run scripts/setup (it installs "
        "python3-onnx) and use /usr/bin/python3\n" % (sys.executable, error))
    sys.exit(1)

OPSET = 17
IR_VERSION = 8

# YOLO-World: (embedding dim k, anchor a_k, box cx, cy, w, h in letterboxed 640 px).
# Anchors: 0..6399 stride 8 (80x80, a = gy*80+gx), 6400..7999 stride 16, 8000..8399 stride 32.
PLANTED_ANCHORS = [
    (0, 10 * 80 + 20, 164.0, 84.0, 64.0, 48.0),
    (1, 6400 + 20 * 40 + 10, 168.0, 328.0, 96.0, 128.0),
    (2, 8000 + 5 * 20 + 15, 496.0, 176.0, 200.0, 150.0),
    (3, 8399, 624.0, 624.0, 32.0, 32.0),
]
YOLO_N = 32
YOLO_ANCHORS = 8400
BAKED_NAMES = ["tomato", "leaf"]

CLIP_BUCKETS = 16
# Ids >= this (the fixture's SOT 562 / EOT 563, or CLIP's 49406 / 49407) count nothing.
CLIP_STUB_MAX_ID = 562
SAM_S = 512

GDINO_BUCKETS = 97
GDINO_QUERIES = 900
GDINO_MAX_TEXT = 256
# (query, buckets, normalised cx, cy, w, h)
GDINO_PLANTED = [
    (7, [33], 0.25, 0.25, 0.2, 0.3),
    (123, [34], 0.5, 0.5, 0.4, 0.2),
    (456, [36, 37], 0.75, 0.6, 0.1, 0.1),
    (899, [35], 0.1, 0.9, 0.2, 0.2),
]
BERT_WORDS = {"tomato": 1100, "leaf": 1101, "stem": 1102, "cat": 1103, "dog": 1104}


# ---- graph helpers -------------------------------------------------------------------------------

class Graph:
    """Collects nodes and initializers with unique names."""

    def __init__(self, name):
        self.name = name
        self.nodes = []
        self.inits = []
        self.count = 0

    def const(self, value, dtype=np.float32, name=None):
        self.count += 1
        name = name or "c%d" % self.count
        self.inits.append(numpy_helper.from_array(np.asarray(value, dtype=dtype), name))
        return name

    def op(self, op_type, inputs, output=None, **attrs):
        self.count += 1
        output = output or "t%d_%s" % (self.count, op_type.lower())
        self.nodes.append(helper.make_node(op_type, inputs, [output], **attrs))
        return output

    def model(self, inputs, outputs):
        graph = helper.make_graph(self.nodes, self.name, inputs, outputs, self.inits)
        model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                                  ir_version=IR_VERSION, producer_name="avp make_stubs.py")
        onnx.checker.check_model(model)
        return model


def vi(name, elem, shape):
    return helper.make_tensor_value_info(name, elem, shape)


F32, I64, I32, BOOL = TensorProto.FLOAT, TensorProto.INT64, TensorProto.INT32, TensorProto.BOOL


# ---- the stubs -----------------------------------------------------------------------------------

def yolo_world(baked=False, logits=False, rename_images=False, rank2_txt=False, transposed=False,
               official_shapes=False):
    """official_shapes: the output as the docs' torch.onnx.export of Ultralytics' WorldModel gives
    it with torch 1.13 (scripts/export-random-weights): all three dimensions symbolic."""
    g = Graph("yolo_world_stub")
    images = "image" if rename_images else "images"
    n = len(BAKED_NAMES) if baked else YOLO_N
    inputs = [vi(images, F32, [1, 3, 640, 640])]
    if baked:
        feats = np.zeros((1, n, 512), np.float32)
        for c in range(n):
            feats[0, c, c] = 1.0
        txt = g.const(feats)
    elif rank2_txt:
        inputs.append(vi("txt_feats", F32, [YOLO_N, 512]))
        txt = g.op("Unsqueeze", ["txt_feats", g.const([0], np.int64)])
    else:
        inputs.append(vi("txt_feats", F32, [1, YOLO_N, 512]))
        txt = "txt_feats"
    # P [512, 8400]: zeros with the planted ones.
    zeros_p = g.op("ConstantOfShape", [g.const([512, YOLO_ANCHORS], np.int64)],
                   value=numpy_helper.from_array(np.zeros(1, np.float32)))
    p = g.op("ScatterND", [zeros_p, g.const([[k, a] for k, a, *_ in PLANTED_ANCHORS], np.int64),
                           g.const([1.0] * len(PLANTED_ANCHORS))])
    raw = g.op("MatMul", [txt, p])  # [1, n, 8400]
    clipped = g.op("Clip", [raw, g.const(0.0), g.const(1.0)])
    red = g.op("Slice", [images, g.const([0], np.int64), g.const([1], np.int64),
                         g.const([1], np.int64)])
    mean_red = g.op("ReduceMean", [red], axes=[1, 2, 3], keepdims=0)  # [1]
    scores = g.op("Mul", [clipped, mean_red])
    if logits:
        scores = g.op("Sub", [g.op("Mul", [scores, g.const(20.0)]), g.const(10.0)])
    zeros_b = g.op("ConstantOfShape", [g.const([4, YOLO_ANCHORS], np.int64)],
                   value=numpy_helper.from_array(np.zeros(1, np.float32)))
    idx, upd = [], []
    for _, a, cx, cy, w, h in PLANTED_ANCHORS:
        for row, v in enumerate((cx, cy, w, h)):
            idx.append([row, a])
            upd.append(v)
    boxes = g.op("ScatterND", [zeros_b, g.const(idx, np.int64), g.const(upd)])
    boxes = g.op("Unsqueeze", [boxes, g.const([0], np.int64)])  # [1, 4, 8400]
    if transposed:
        out = g.op("Concat", [boxes, scores], axis=1)
        g.op("Transpose", [out], "output0", perm=[0, 2, 1])
        outputs = [vi("output0", F32, [1, YOLO_ANCHORS, 4 + n])]
    else:
        g.op("Concat", [boxes, scores], "output0", axis=1)
        outputs = [vi("output0", F32, ["o0", "o1", "o2"] if official_shapes
                      else [1, 4 + n, YOLO_ANCHORS])]
    return g.model(inputs, outputs)


def clip_text(int32_ids=False):
    g = Graph("clip_text_stub")
    elem = I32 if int32_ids else I64
    inputs = [vi("input_ids", elem, ["batch", 77])]
    ids = g.op("Cast", ["input_ids"], to=I64) if int32_ids else "input_ids"
    bucket = g.op("Mod", [ids, g.const(CLIP_BUCKETS, np.int64)])
    onehot = g.op("Gather", [g.const(np.eye(CLIP_BUCKETS, dtype=np.float32)), bucket], axis=0)
    counted = g.op("Cast", [g.op("Less", [ids, g.const(CLIP_STUB_MAX_ID, np.int64)])], to=F32)
    e = g.op("Mul", [onehot, g.op("Unsqueeze", [counted, g.const([2], np.int64)])])
    c = g.op("CumSum", [e, g.const(1, np.int64)])  # [B, 77, 16]
    eot = g.op("ArgMax", [ids], axis=1, keepdims=1)  # [B, 1]: the first maximum
    pooled = g.op("GatherND", [c, eot], batch_dims=1)  # [B, 16]
    # The projection [I_16 | 0] as MatMul by I_16 and a zero Pad to 512 (a few bytes, not 32 KB).
    projected = g.op("MatMul", [pooled, g.const(np.eye(CLIP_BUCKETS, dtype=np.float32))])
    g.op("Pad", [projected, g.const([0, 0, 0, 512 - CLIP_BUCKETS], np.int64), g.const(0.0)],
         "text_embeds")
    return g.model(inputs, [vi("text_embeds", F32, ["batch", 512])])


def clip_text_heavy(layers=4, width=512, hidden=2048, table=1024):
    """The CLIP text contract with a transformer-sized amount of work (bench_zsl --serve-clients):
    input_ids int64 [B,77] -> embedding table[ids mod table] [B,77,W] -> `layers` residual MLP
    blocks (MatMul W x H, Relu, MatMul H x W, Add) -> mean over the 77 tokens -> text_embeds
    [B,W]. Seeded random weights; about 0.6 GMAC per prompt at the defaults. Not used by tests."""
    rng = np.random.default_rng(20261204)
    g = Graph("clip_text_heavy_stub")
    inputs = [vi("input_ids", I64, ["batch", 77])]
    bucket = g.op("Mod", ["input_ids", g.const(table, np.int64)])
    x = g.op("Gather", [g.const(rng.standard_normal((table, width)).astype(np.float32)), bucket],
             axis=0)
    for _ in range(layers):
        w1 = (rng.standard_normal((width, hidden)) / np.sqrt(width)).astype(np.float32)
        w2 = (rng.standard_normal((hidden, width)) / np.sqrt(hidden)).astype(np.float32)
        h = g.op("Relu", [g.op("MatMul", [x, g.const(w1)])])
        x = g.op("Add", [x, g.op("MatMul", [h, g.const(w2)])])
    g.op("ReduceMean", [x], "text_embeds", axes=[1], keepdims=0)
    return g.model(inputs, [vi("text_embeds", F32, ["batch", width])])


def sam_encoder(small_output=False, official_shapes=False):
    """official_shapes: the graph's I/O as the official export_encoder.py gives them with torch
    1.13 (a dynamic batch axis, symbolic output dimensions): [batch_size,3,S,S] -> [?,256,?,?]."""
    g = Graph("evitsam_encoder_stub")
    k = SAM_S // 64 * (2 if small_output else 1)
    pooled = g.op("AveragePool", ["input_image"], kernel_shape=[k, k], strides=[k, k])
    w = np.zeros((256, 3, 1, 1), np.float32)
    for c in range(256):
        w[c, c % 3, 0, 0] = 1.0
    g.op("Conv", [pooled, g.const(w)], "image_embeddings")
    side = 32 if small_output else 64
    if official_shapes:
        return g.model([vi("input_image", F32, ["batch_size", 3, SAM_S, SAM_S])],
                       [vi("image_embeddings", F32, ["e0", 256, "e2", "e3"])])
    return g.model([vi("input_image", F32, [1, 3, SAM_S, SAM_S])],
                   [vi("image_embeddings", F32, [1, 256, side, side])])


def sam_decoder(int32_labels=False, drop_iou=False, extra_input=False, official_shapes=False):
    """official_shapes: outputs as the official export_decoder.py --return-single-mask gives them
    with torch 1.13: masks [?,1,?,?], iou_predictions [?,1]."""
    g = Graph("evitsam_decoder_single_stub")
    inputs = [vi("image_embeddings", F32, [1, 256, 64, 64]),
              vi("point_coords", F32, ["batch", "points", 2]),
              vi("point_labels", I32 if int32_labels else F32, ["batch", "points"])]
    labels = g.op("Cast", ["point_labels"], to=F32) if int32_labels else "point_labels"
    # Pad one point (label -1) so that N < 2 still slices.
    coords = g.op("Pad", ["point_coords", g.const([0, 0, 0, 0, 1, 0], np.int64), g.const(-1.0)])
    labels = g.op("Pad", [labels, g.const([0, 0, 0, 1], np.int64), g.const(-1.0)])

    def corner(point, axis):
        s = g.op("Slice", [coords, g.const([point, axis], np.int64),
                           g.const([point + 1, axis + 1], np.int64), g.const([1, 2], np.int64)])
        return g.op("Reshape", [s, g.const([-1, 1, 1, 1], np.int64)])  # [B,1,1,1]

    x0, y0, x1, y1 = corner(0, 0), corner(0, 1), corner(1, 0), corner(1, 1)
    centres = (4.0 * (np.arange(256, dtype=np.float32) + 0.5)).astype(np.float32)
    xs = g.const(centres.reshape(1, 1, 1, 256))
    ys = g.const(centres.reshape(1, 1, 256, 1))
    in_x = g.op("And", [g.op("GreaterOrEqual", [xs, x0]), g.op("LessOrEqual", [xs, x1])])
    in_y = g.op("And", [g.op("GreaterOrEqual", [ys, y0]), g.op("LessOrEqual", [ys, y1])])

    def label(point):
        return g.op("Slice", [labels, g.const([point], np.int64), g.const([point + 1], np.int64),
                              g.const([1], np.int64)])  # [B,1]

    l0, l1 = label(0), label(1)
    box = g.op("And", [g.op("Equal", [l0, g.const(2.0)]), g.op("Equal", [l1, g.const(3.0)])])
    box = g.op("Reshape", [box, g.const([-1, 1, 1, 1], np.int64)])
    inside = g.op("And", [g.op("And", [in_x, in_y]), box])
    masks = g.op("Where", [inside, g.const(10.0), g.const(-10.0)])
    used = g.op("Mul", [g.op("ReduceMean", ["image_embeddings"], keepdims=0), g.const(0.0)])
    if extra_input:
        inputs.append(vi("mask_input", F32, [1, 1, 256, 256]))
        used = g.op("Add", [used, g.op("Mul", [g.op("ReduceMean", ["mask_input"], keepdims=0),
                                               g.const(0.0)])])
    g.op("Add", [masks, used], "masks")
    g.op("Add", [g.op("Mul", [l0, g.const(0.0)]), g.const(0.875)], "iou_predictions")
    outputs = [vi("masks", F32, ["m0", 1, "m2", "m3"] if official_shapes else ["batch", 1, 256, 256])]
    if not drop_iou:
        outputs.append(vi("iou_predictions", F32, ["i0" if official_shapes else "batch", 1]))
    return g.model(inputs, outputs)


def grounding_dino():
    g = Graph("groundingdino_stub")
    inputs = [vi("img", F32, [1, 3, 800, 1200]),
              vi("input_ids", I64, [1, "text_len"]),
              vi("attention_mask", BOOL, [1, "text_len"]),
              vi("position_ids", I64, [1, "text_len"]),
              vi("token_type_ids", I64, [1, "text_len"]),
              vi("text_token_mask", BOOL, [1, "text_len", "text_len"])]
    zero = g.const([0], np.int64)
    ids = g.op("Squeeze", ["input_ids", zero])  # [L]
    bucket = g.op("Mod", [ids, g.const(GDINO_BUCKETS, np.int64)])
    onehot = g.op("OneHot", [bucket, g.const([GDINO_BUCKETS], np.int64), g.const([0.0, 1.0])],
                  axis=-1)  # [L, 97]
    q = np.zeros((len(GDINO_PLANTED), GDINO_BUCKETS), np.float32)
    for i, (_, buckets, *_) in enumerate(GDINO_PLANTED):
        q[i, buckets] = 1.0
    hits = g.op("MatMul", [g.const(q), g.op("Transpose", [onehot], perm=[1, 0])])  # [K, L]
    upd = g.op("Sub", [g.op("Mul", [hits, g.const(20.0)]), g.const(10.0)])
    length = g.op("Shape", [ids])  # [1] = L
    base_shape = g.op("Concat", [g.const([GDINO_QUERIES], np.int64), length], axis=0)
    base = g.op("ConstantOfShape", [base_shape],
                value=numpy_helper.from_array(np.full(1, -10.0, np.float32)))
    q_idx = g.const([[qq] for qq, *_ in GDINO_PLANTED], np.int64)
    lg = g.op("ScatterND", [base, q_idx, upd])  # [900, L]
    mask = g.op("Squeeze", ["attention_mask", zero])
    lg = g.op("Where", [mask, lg, g.const(-10.0)])
    # Everything else is read, times 0.
    extra = [g.op("ReduceMean", ["img"], keepdims=0),
             g.op("Cast", [g.op("ReduceSum", ["position_ids"], keepdims=0)], to=F32),
             g.op("Cast", [g.op("ReduceSum", ["token_type_ids"], keepdims=0)], to=F32),
             g.op("Cast", [g.op("ReduceSum", [g.op("Cast", ["text_token_mask"], to=I64)],
                                keepdims=0)], to=F32)]
    used = g.op("Mul", [g.op("Sum", extra), g.const(0.0)])
    lg = g.op("Add", [lg, used])
    pad_end = g.op("Sub", [g.const([GDINO_MAX_TEXT], np.int64), length])
    pads = g.op("Concat", [g.const([0, 0, 0], np.int64), pad_end], axis=0)
    lg = g.op("Pad", [lg, pads, g.const(-10.0)])  # [900, 256]
    g.op("Unsqueeze", [lg, zero], "logits")
    zeros_b = g.op("ConstantOfShape", [g.const([GDINO_QUERIES, 4], np.int64)],
                   value=numpy_helper.from_array(np.zeros(1, np.float32)))
    planted = np.array([box for _, _, *box in GDINO_PLANTED], np.float32)  # [K, 4]
    boxes = g.op("ScatterND", [zeros_b, q_idx, g.const(planted)])
    g.op("Unsqueeze", [boxes, zero], "boxes")
    return g.model(inputs, [vi("logits", F32, [1, GDINO_QUERIES, GDINO_MAX_TEXT]),
                            vi("boxes", F32, [1, GDINO_QUERIES, 4])])


# ---- vocabularies --------------------------------------------------------------------------------

def clip_merges_text(fixture):
    if fixture and os.path.isfile(fixture):
        with open(fixture, "rb") as f:
            return f.read()
    # A minimal merges file in the bpe_simple_vocab_16e6.txt format (line 1 is a header).
    return b"#version: 0.2 - avp stub\nt o\nm a\nto ma\n"


def clip_special_ids(merges):
    lines = merges.decode("utf-8").split("\n")[1:]
    count = len([line for line in lines if line.strip()])
    return 512 + count, 512 + count + 1


def bert_vocab_text(fixture):
    if fixture and os.path.isfile(fixture):
        with open(fixture, "rb") as f:
            return f.read()
    # bert-base-uncased's layout for the ids that matter: [PAD] 0, [UNK] 100, [CLS] 101, [SEP] 102,
    # [MASK] 103, punctuation from 999 ("." is 1012), then the planted words at BERT_WORDS.
    vocab = ["[unused%d]" % i for i in range(1110)]
    vocab[0], vocab[100], vocab[101], vocab[102], vocab[103] = (
        "[PAD]", "[UNK]", "[CLS]", "[SEP]", "[MASK]")
    punct = "!\"#$%&'()*+,-./:;<=>?@[\\]^_`{|}~"
    for i, ch in enumerate(punct):
        vocab[999 + i] = ch
    for i, ch in enumerate("0123456789abcdefghijklmnopqrstuvwxyz"):
        vocab[1040 + i] = ch
    for word, i in BERT_WORDS.items():
        vocab[i] = word
    vocab[1105] = "##s"
    return ("\n".join(vocab) + "\n").encode("utf-8")


# ---- manifests -----------------------------------------------------------------------------------

ELEM_NAMES = {F32: "float32", I64: "int64", I32: "int32", BOOL: "bool"}


def io_of(model):
    def one(v):
        dims = [d.dim_value if d.HasField("dim_value") else -1
                for d in v.type.tensor_type.shape.dim]
        return {"name": v.name, "type": ELEM_NAMES[v.type.tensor_type.elem_type], "shape": dims}
    inits = {i.name for i in model.graph.initializer}
    return ([one(v) for v in model.graph.input if v.name not in inits],
            [one(v) for v in model.graph.output])


def sha256_of(data):
    return hashlib.sha256(data).hexdigest()


class ModelDir:
    """One model directory: files plus the manifest entries that describe them."""

    def __init__(self, root, description):
        self.root = root
        self.models = {}
        self.description = description
        os.makedirs(root, exist_ok=True)

    def write(self, relative, data):
        path = os.path.join(self.root, relative)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "wb") as f:
            f.write(data)
        return {"file": relative, "bytes": len(data), "sha256": sha256_of(data)}

    def add(self, role, contract, relative, model, licence="stub (generated; no weights)",
            origin="zsl/test/stubs/make_stubs.py", **extra):
        data = model.SerializeToString()
        entry = {"contract": contract}
        entry.update(self.write(relative, data))
        entry["licence"] = licence
        entry["origin"] = origin
        entry["inputs"], entry["outputs"] = io_of(model)
        entry.update(extra)
        self.models[role] = entry
        return entry

    def save(self):
        manifest = {"format": "avp.zsl.models/1", "description": self.description,
                    "models": self.models}
        with open(os.path.join(self.root, "manifest.json"), "w") as f:
            json.dump(manifest, f, indent=2)
            f.write("\n")


DETECTOR_PRE = {"size": [640, 640], "resize": "fit", "padding": "centre", "pad_value": 114,
                "pad_space": "pixels", "channel_order": "rgb", "scale": 1.0 / 255.0,
                "mean": [0.0, 0.0, 0.0], "std": [1.0, 1.0, 1.0]}
ENCODER_PRE = {"size": [SAM_S, SAM_S], "resize": "fit", "padding": "bottom_right", "pad_value": 0,
               "pad_space": "normalized", "channel_order": "rgb", "scale": 1.0,
               "mean": [123.675, 116.28, 103.53], "std": [58.395, 57.12, 57.375]}
DECODER_POST = {"prompt_frame": 1024, "low_res": 256, "mask_threshold": 0.0}
GROUNDING_PRE = {"size": [800, 1200], "resize": "stretch", "padding": "none",
                 "channel_order": "rgb", "scale": 1.0 / 255.0, "mean": [0.485, 0.456, 0.406],
                 "std": [0.229, 0.224, 0.225]}
GROUNDING_POST = {"box_format": "cxcywh_normalized", "score_activation": "sigmoid"}


def add_segmenter(d, encoder=None, decoder=None, encoder_pre=None):
    d.add("segmenter.encoder", "evitsam.encoder/1", "segmenter/evitsam_stub_encoder.onnx",
          encoder or sam_encoder(), preprocess=encoder_pre or ENCODER_PRE)
    d.add("segmenter.decoder", "evitsam.decoder.single/1",
          "segmenter/evitsam_stub_decoder_single.onnx", decoder or sam_decoder(),
          postprocess=DECODER_POST)


def add_text(d, merges, model=None):
    sot, eot = clip_special_ids(merges)
    vocab = d.write("text/clip_stub_merges.txt", merges)
    d.add("text", "clip.text/1", "text/clip_stub_text.onnx", model or clip_text(),
          text={"tokenizer": "clip_bpe", "context": 77, "sot": sot, "eot": eot, "pad": 0,
                "vocabulary": vocab, "dim": 512, "normalized_in_graph": False})


def make_ywes(root, merges, description, detector=None, logits=False, baked=False, post=None,
              text_model=None, encoder=None, decoder=None, encoder_pre=None):
    d = ModelDir(root, description)
    if baked:
        name = "detector/yolo_world_stub_baked2%s.onnx" % ("_logits" if logits else "")
        d.add("detector", "yoloworld.baked/1", name,
              detector or yolo_world(baked=True, logits=logits),
              preprocess=DETECTOR_PRE,
              postprocess=post or {"layout": "[4+N,A]", "box_format": "cxcywh",
                                   "score_activation": "sigmoid" if logits else "none",
                                   "baked_names": BAKED_NAMES})
    else:
        name = "detector/yolo_world_stub_txt32%s.onnx" % ("_logits" if logits else "")
        d.add("detector", "yoloworld.txtfeats/1", name, detector or yolo_world(logits=logits),
              preprocess=DETECTOR_PRE,
              postprocess=post or {"layout": "[4+N,A]", "box_format": "cxcywh",
                                   "score_activation": "sigmoid" if logits else "none",
                                   "n_max": YOLO_N})
        add_text(d, merges, text_model)
    add_segmenter(d, encoder, decoder, encoder_pre)
    return d


def make_lsam(root, bert_vocab, description, decoder=None):
    d = ModelDir(root, description)
    vocab = d.write("grounding/bert_stub_vocab.txt", bert_vocab)
    d.add("grounding", "gdino.ort/1", "grounding/groundingdino_stub_800x1200.onnx",
          grounding_dino(), licence="stub (generated; no weights)", preprocess=GROUNDING_PRE,
          postprocess=GROUNDING_POST,
          text={"tokenizer": "bert_wordpiece", "context": 256, "cls": 101, "sep": 102, "pad": 0,
                "period": 1012, "vocabulary": vocab, "lower_case": True})
    add_segmenter(d, decoder=decoder)
    return d


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("out_dir")
    parser.add_argument("--clip-merges", help="CLIP merges fixture to ship as the text vocabulary")
    parser.add_argument("--bert-vocab", help="WordPiece vocab.txt fixture for the grounding model")
    parser.add_argument("--bench", action="store_true",
                        help="also ywes_heavy_text/: ywes with clip_text_heavy() as its text model "
                             "(34 MB; for bench_zsl --serve-clients)")
    args = parser.parse_args()

    out = os.path.abspath(args.out_dir)
    if os.path.isdir(out):
        shutil.rmtree(out)
    os.makedirs(out)
    merges = clip_merges_text(args.clip_merges)
    bert = bert_vocab_text(args.bert_vocab)

    make_ywes(os.path.join(out, "ywes"), merges, "ywes stubs: YOLO-World text features").save()
    make_ywes(os.path.join(out, "ywes_logits"), merges, "ywes stubs, detector emits logits",
              logits=True).save()
    make_ywes(os.path.join(out, "ywes_baked"), merges, "ywes stubs, baked vocabulary",
              baked=True).save()
    make_ywes(os.path.join(out, "ywes_baked_logits"), merges, "ywes stubs, baked, logits",
              baked=True, logits=True).save()
    make_ywes(os.path.join(out, "ywes_transposed"), merges, "ywes stubs, [A,4+N] detector",
              detector=yolo_world(transposed=True),
              post={"layout": "[A,4+N]", "box_format": "cxcywh", "score_activation": "none",
                    "n_max": YOLO_N}).save()
    make_lsam(os.path.join(out, "lsam"), bert,
              "lsam stubs: Grounding DINO + EfficientViT-SAM").save()
    # The official EfficientViT-SAM and YOLO-World exports leave dimensions dynamic that the docs
    # state; the manifest states them (docs/zero-shot-models.md) and avp checks the stated values.
    d = make_ywes(os.path.join(out, "ywes_official_shapes"), merges,
                  "ywes stubs with the I/O shapes of the official EfficientViT-SAM and YOLO-World exports",
                  detector=yolo_world(official_shapes=True),
                  encoder=sam_encoder(official_shapes=True),
                  decoder=sam_decoder(official_shapes=True))
    d.models["detector"]["outputs"][0]["shape"] = [1, 4 + YOLO_N, YOLO_ANCHORS]
    d.models["segmenter.encoder"]["inputs"][0]["shape"] = [1, 3, SAM_S, SAM_S]
    d.models["segmenter.encoder"]["outputs"][0]["shape"] = [1, 256, 64, 64]
    d.models["segmenter.decoder"]["outputs"][0]["shape"] = [-1, 1, 256, 256]
    d.save()
    if args.bench:
        make_ywes(os.path.join(out, "ywes_heavy_text"), merges,
                  "ywes stubs, a text model with transformer-sized work (benchmarks only)",
                  text_model=clip_text_heavy()).save()

    wrong = os.path.join(out, "wrong")
    ywes_cases = {
        "renamed_input": dict(detector=yolo_world(rename_images=True)),
        "int32_labels": dict(decoder=sam_decoder(int32_labels=True)),
        "int32_input_ids": dict(text_model=clip_text(int32_ids=True)),
        "wrong_rank": dict(detector=yolo_world(rank2_txt=True)),
        "wrong_static_dim": dict(encoder=sam_encoder(small_output=True)),
        "transposed_output": dict(detector=yolo_world(transposed=True)),
        "missing_output": dict(decoder=sam_decoder(drop_iou=True)),
        "extra_input": dict(decoder=sam_decoder(extra_input=True)),
        "encoder_size_mismatch": dict(encoder_pre=dict(ENCODER_PRE, size=[1024, 1024])),
        "n_max_mismatch": dict(post={"layout": "[4+N,A]", "box_format": "cxcywh",
                                     "score_activation": "none", "n_max": 16}),
    }
    for case, kwargs in ywes_cases.items():
        make_ywes(os.path.join(wrong, case), merges, "wrong contract: " + case, **kwargs).save()

    # Defects in the files or the manifest rather than in a graph.
    d = make_ywes(os.path.join(wrong, "truncated_file"), merges, "wrong: truncated decoder")
    entry = d.models["segmenter.decoder"]
    path = os.path.join(d.root, entry["file"])
    with open(path, "rb") as f:
        data = f.read()
    entry.update(d.write(entry["file"], data[: len(data) // 2]))
    d.save()

    d = make_ywes(os.path.join(wrong, "size_mismatch"), merges, "wrong: text bytes + 1")
    d.models["text"]["bytes"] += 1
    d.save()

    d = make_ywes(os.path.join(wrong, "missing_file"), merges, "wrong: encoder file absent")
    os.remove(os.path.join(d.root, d.models["segmenter.encoder"]["file"]))
    d.save()

    d = make_ywes(os.path.join(wrong, "sha256_mismatch"), merges, "wrong: detector sha256")
    d.models["detector"]["sha256"] = "0" * 64
    d.save()

    d = make_ywes(os.path.join(wrong, "declared_io_mismatch"), merges, "wrong: declared txt_feats")
    for tensor in d.models["detector"]["inputs"]:
        if tensor["name"] == "txt_feats":
            tensor["shape"] = [1, 16, 512]
    d.save()

    count = sum(len(files) for _, _, files in os.walk(out))
    print("make_stubs: wrote %d files under %s" % (count, out))


if __name__ == "__main__":
    main()
