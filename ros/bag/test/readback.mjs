// npm read-back of a real `avp run --record` (issue 17): runs the built avp for a short simulated
// episode with --record, then reads its episode.mcap with @mcap/core's McapIndexedReader and
// McapStreamReader (CRCs validated) and checks the ros2 profile as rosbag2 and Foxglove expect it
// (schema names like sensor_msgs/msg/Image in ros2msg, cdr channels each with
// offered_qos_profiles), one message per fused view on every topic of the layout, that every
// payload decodes with @foxglove/rosmsg2-serialization against the file's own schema text, and
// the values against the run folder's record.json (the exact X_WC, the views) and the metadata
// and ground-truth attachment.
// Usage: node readback.mjs --avp <avp> --lockfile <tests/npm/package-lock.json> --out <scratch>
// The npm packages come from scripts/setup, as for ros/mcap/test/readback.mjs.

import { execFileSync } from "node:child_process";
import { readFileSync, rmSync } from "node:fs";
import { join } from "node:path";

import { arg, npmTestRequire } from "../../../tests/npm/npm_test.mjs";

const avp = arg("readback.mjs", "--avp");
const lockfile = arg("readback.mjs", "--lockfile");
const outDir = arg("readback.mjs", "--out");
const require = npmTestRequire("recording_npm_readback", lockfile,
                                ["@mcap/core", "@foxglove/rosmsg2-serialization",
                                 "@foxglove/rosmsg"]);
const { McapIndexedReader, McapStreamReader } = require("@mcap/core");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const { parse } = require("@foxglove/rosmsg");

// ---- A real run ----------------------------------------------------------------------------------
const runDir = join(outDir, "run");
rmSync(runDir, { recursive: true, force: true });
execFileSync(avp, ["run", "--scenario", "tomato-multiple-clusters", "--seed", "2", "--views", "3",
                   "--segmenter", "oracle", "--threads", "2", "--out", runDir, "--record"],
             { stdio: ["ignore", "ignore", "inherit"] });
const mcapPath = join(runDir, "episode.mcap");
const record = JSON.parse(readFileSync(join(runDir, "record.json"), "utf8"));
const views = record.views_fused;
const bytes = new Uint8Array(readFileSync(mcapPath));

let failures = 0;
function check(ok, what) {
  if (!ok) {
    console.error(`FAIL ${what}`);
    failures++;
  }
}
function eq(actual, want, what) {
  check(actual === want, `${what}: expected ${String(want)}, got ${String(actual)}`);
}

const layout = {
  "/camera/camera/color/image_raw": "sensor_msgs/msg/Image",
  "/camera/camera/aligned_depth_to_color/image_raw": "sensor_msgs/msg/Image",
  "/camera/camera/color/camera_info": "sensor_msgs/msg/CameraInfo",
  "/tf": "tf2_msgs/msg/TFMessage",
  "/joint_states": "sensor_msgs/msg/JointState",
  "/avp/segmentation/instance_image": "sensor_msgs/msg/Image",
  "/avp/segmentation/instances": "std_msgs/msg/String",
  "/avp/sim/instance": "sensor_msgs/msg/Image",
  "/avp/sim/class": "sensor_msgs/msg/Image",
  "/avp/planning/candidates": "visualization_msgs/msg/MarkerArray",
  "/avp/map": "octomap_msgs/msg/Octomap",
  "/avp/step": "std_msgs/msg/String",
};

const readable = (buf) => ({
  size: async () => BigInt(buf.length),
  read: async (offset, length) => buf.subarray(Number(offset), Number(offset + length)),
});
const textDecoder = new TextDecoder();

// ---- Indexed: the ros2 profile -------------------------------------------------------------------
const indexed = await McapIndexedReader.Initialize({ readable: readable(bytes) });
eq(indexed.header.profile, "ros2", "header profile");
eq(indexed.channelsById.size, Object.keys(layout).length, "channel count");
const readers = new Map();  // channel id -> MessageReader
const topicOf = new Map();
for (const [id, ch] of indexed.channelsById) {
  const schema = indexed.schemasById.get(ch.schemaId);
  const want = layout[ch.topic];
  check(want !== undefined, `unexpected topic ${ch.topic}`);
  eq(schema?.name, want, `${ch.topic} schema name`);
  eq(schema?.encoding, "ros2msg", `${ch.topic} schema encoding`);
  eq(ch.messageEncoding, "cdr", `${ch.topic} message encoding`);
  const qos = ch.metadata.get("offered_qos_profiles") ?? "";
  check(/^- history: 1\n  depth: 10\n  reliability: 1\n  durability: 2\n/.test(qos),
        `${ch.topic} offered_qos_profiles: ${JSON.stringify(qos)}`);
  check(/^RIHS01_[0-9a-f]{64}$/.test(ch.metadata.get("topic_type_hash") ?? ""),
        `${ch.topic} topic_type_hash`);
  readers.set(id, new MessageReader(parse(textDecoder.decode(schema.data), { ros2: true })));
  topicOf.set(id, ch.topic);
}
const stats = indexed.statistics;
eq(stats?.messageCount, BigInt(views * Object.keys(layout).length), "statistics message count");
eq(stats?.attachmentCount, 1, "statistics attachment count");
eq(stats?.metadataCount, 1, "statistics metadata count");
for (const [id, topic] of topicOf) {
  eq(stats?.channelMessageCounts.get(id), BigInt(views), `messages on ${topic}`);
}

// ---- Metadata and the ground-truth attachment ----------------------------------------------------
const metadata = [];
for await (const m of indexed.readMetadata()) metadata.push(m);
eq(metadata.length, 1, "metadata records");
const md = metadata[0]?.metadata ?? new Map();
eq(metadata[0]?.name, "avp", "metadata name");
eq(md.get("command"), "avp run", "metadata command");
eq(md.get("seed"), "2", "metadata seed");
eq(md.get("scene"), record.scene.name, "metadata scene");
eq(md.get("planner"), record.config.planner.name, "metadata planner");
eq(md.get("base_frame"), "igus_rebel_base_link", "metadata base_frame");
check((md.get("run_config") ?? "").includes("episode:"), "metadata run_config is the YAML");
const attachments = [];
for await (const a of indexed.readAttachments({ validateCrcs: true })) attachments.push(a);
eq(attachments.length, 1, "attachments");
eq(attachments[0]?.name, "ground_truth.json", "attachment name");
eq(attachments[0]?.mediaType, "application/json", "attachment media type");
let gt;
try {
  gt = JSON.parse(textDecoder.decode(attachments[0].data));
} catch (err) {
  check(false, `ground_truth.json does not parse: ${err.message}`);
}
check(gt !== undefined && typeof gt === "object", "ground_truth.json is a JSON object");

// ---- Every message decodes; values against record.json -------------------------------------------
const byTopic = new Map();
let decoded = 0;
for await (const m of indexed.readMessages({ validateCrcs: true })) {
  const topic = topicOf.get(m.channelId);
  let value;
  try {
    value = readers.get(m.channelId).readMessage(m.data);
    decoded++;
  } catch (err) {
    check(false, `${topic} message ${m.sequence} does not decode: ${err.message}`);
    continue;
  }
  eq(m.logTime, m.publishTime, `${topic} log time = publish time`);
  if (!byTopic.has(topic)) byTopic.set(topic, []);
  byTopic.get(topic).push({ m, value });
}
eq(decoded, views * Object.keys(layout).length, "messages decoded");
for (let v = 0; v < views; v++) {
  const color = byTopic.get("/camera/camera/color/image_raw")?.[v]?.value;
  const depth = byTopic.get("/camera/camera/aligned_depth_to_color/image_raw")?.[v]?.value;
  const ids = byTopic.get("/avp/segmentation/instance_image")?.[v]?.value;
  const info = byTopic.get("/camera/camera/color/camera_info")?.[v]?.value;
  const tf = byTopic.get("/tf")?.[v]?.value;
  const stepMsg = byTopic.get("/avp/step")?.[v];
  const map = byTopic.get("/avp/map")?.[v]?.value;
  const inst = byTopic.get("/avp/segmentation/instances")?.[v]?.value;
  if (!color || !depth || !ids || !info || !tf || !stepMsg || !map || !inst) {
    check(false, `view ${v}: a topic is missing`);
    continue;
  }
  eq(color.encoding, "rgb8", `view ${v} colour encoding`);
  eq(color.data.length, color.width * color.height * 3, `view ${v} colour bytes`);
  eq(depth.encoding, "32FC1", `view ${v} depth encoding`);
  eq(depth.data.length, depth.width * depth.height * 4, `view ${v} depth bytes`);
  eq(ids.encoding, "mono16", `view ${v} instance image encoding`);
  eq(info.width, color.width, `view ${v} camera_info width`);
  eq(tf.transforms[0].header.frame_id, "igus_rebel_base_link", `view ${v} TF parent`);
  eq(tf.transforms[0].child_frame_id, color.header.frame_id, `view ${v} TF child`);
  eq(map.binary, true, `view ${v} octomap binary`);
  eq(map.id, "OcTree", `view ${v} octomap id`);
  check(map.data.length > 0, `view ${v} octomap data`);
  const step = JSON.parse(stepMsg.value.data);
  eq(step.view, v, `view ${v} step index`);
  eq(BigInt(step.stamp_ns), stepMsg.m.logTime, `view ${v} step stamp = log time`);
  const want = record.steps[v].X_WC.matrix;  // 4x4 rows from record.json
  for (let r = 0; r < 3; r++) {
    for (let c = 0; c < 4; c++) {
      eq(step.X_WC[r * 4 + c], want[r][c], `view ${v} X_WC[${r}][${c}] (exact)`);
    }
  }
  eq(step.known_voxels, record.steps[v].known_voxels, `view ${v} known voxels`);
  const seg = JSON.parse(inst.data);
  eq(seg.width, color.width, `view ${v} instances width`);
  eq(seg.instances.length, record.steps[v].masks, `view ${v} instance count`);
  for (const [i, e] of seg.instances.entries()) {
    const sum = e.mask.counts.reduce((a, b) => a + b, 0);
    eq(sum, e.mask.size[0] * e.mask.size[1], `view ${v} instance ${i} RLE covers the image`);
  }
}

// ---- Streaming, CRCs validated -------------------------------------------------------------------
const stream = new McapStreamReader({ validateCrcs: true });
stream.append(bytes);
let streamed = 0;
let streamedAttachments = 0;
for (let r; (r = stream.nextRecord()); ) {
  if (r.type === "Message") streamed++;
  if (r.type === "Attachment") streamedAttachments++;
}
check(stream.done(), "streaming: the reader did not reach the end magic");
eq(streamed, views * Object.keys(layout).length, "streaming message count");
eq(streamedAttachments, 1, "streaming attachments");

if (failures > 0) {
  console.error(`recording_npm_readback: ${failures} failure(s) in ${mcapPath}`);
  process.exit(1);
}
console.log(`recording_npm_readback: ${mcapPath}: ${views} views x ${Object.keys(layout).length} ` +
            `topics (${bytes.length} bytes) read back with @mcap/core (indexed and streaming, CRCs ` +
            `checked), every message decoded with @foxglove/rosmsg2-serialization; X_WC exact ` +
            `against record.json; metadata and ground_truth.json present`);
