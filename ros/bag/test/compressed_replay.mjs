// Every bag a ROS 2 robot writes (issue 33): a real `avp run --record` is rewritten by
// npm's @mcap/core McapWriter with zstd chunks (@foxglove/wasm-zstd) and with lz4 frame chunks
// (lz4js), as Foxglove and the rosbag2 MCAP plugin write them, indexed or not; `avp replay` of each must give the
// same map and metrics as the replay of the uncompressed original (map.ot byte for byte,
// metrics.csv without its timing columns); so must the same messages as a rosbag2 folder of split
// MCAP files and as Humble's SQLite 3 storage (.db3, written by Python's sqlite3). Another
// implementation's writer checks avp's reader against the MCAP spec, not against avp's own writer.
// Usage: node compressed_replay.mjs --avp <avp> --lockfile <tests/npm/package-lock.json> --out <dir>
// The npm packages come from scripts/setup (tests/npm), as for readback.mjs.

import { execFileSync } from "node:child_process";
import { createHash } from "node:crypto";
import { readFileSync, rmSync, writeFileSync, mkdirSync } from "node:fs";
import { join } from "node:path";

import { arg, npmTestRequire } from "../../../tests/npm/npm_test.mjs";

const avp = arg("compressed_replay.mjs", "--avp");
const lockfile = arg("compressed_replay.mjs", "--lockfile");
const outDir = arg("compressed_replay.mjs", "--out");
const require = npmTestRequire("compressed_replay", lockfile,
                                ["@mcap/core", "@foxglove/wasm-zstd", "lz4js"]);
const { McapIndexedReader, McapWriter } = require("@mcap/core");
const zstd = require("@foxglove/wasm-zstd");
const lz4 = require("lz4js");
await zstd.isLoaded;

rmSync(outDir, { recursive: true, force: true });
mkdirSync(outDir, { recursive: true });
const run = (args) => execFileSync(avp, args, { stdio: ["ignore", "ignore", "inherit"] });

// ---- A real run, recorded, and its replay --------------------------------------------------------
const runDir = join(outDir, "run");
run(["run", "--scenario", "tomato-single-cluster", "--seed", "1", "--views", "3", "--threads", "2",
     "--out", runDir, "--record"]);
const original = new Uint8Array(readFileSync(join(runDir, "episode.mcap")));
run(["replay", join(runDir, "episode.mcap"), "--out", join(outDir, "replay-original")]);

const readable = (buf) => ({
  size: async () => BigInt(buf.length),
  read: async (offset, length) => buf.subarray(Number(offset), Number(offset + length)),
});
const reader = await McapIndexedReader.Initialize({ readable: readable(original) });

/** An in-memory writable for McapWriter: the buffers written, in order. */
function memoryWritable() {
  const parts = [];
  let position = 0n;
  return {
    parts,
    writable: {
      position: () => position,
      write: async (buffer) => {
        parts.push(Buffer.from(buffer));
        position += BigInt(buffer.byteLength);
      },
    },
  };
}

/** Starts `writer` with the recording's header, schemas and channels; the channel ids' map. */
async function startLike(writer) {
  await writer.start({ profile: reader.header.profile, library: "@mcap/core (avp test)" });
  const schemaIds = new Map();
  for (const [id, s] of reader.schemasById) {
    schemaIds.set(id, await writer.registerSchema({ name: s.name, encoding: s.encoding,
                                                    data: s.data }));
  }
  const channelIds = new Map();
  for (const [id, c] of reader.channelsById) {
    channelIds.set(id, await writer.registerChannel({
      topic: c.topic, schemaId: schemaIds.get(c.schemaId) ?? 0,
      messageEncoding: c.messageEncoding, metadata: c.metadata }));
  }
  return channelIds;
}

/** The recording written again by @mcap/core with `compress` for every chunk; `indexed` false:
 * no summary, no index of any kind (a reader must stream through the file). */
async function rewrite(compress, chunkSize, indexed = true) {
  const { parts, writable } = memoryWritable();
  const writer = new McapWriter({
    writable,
    chunkSize,
    compressChunk: compress,
    ...(indexed ? {} : {
      useStatistics: false, useSummaryOffsets: false, useChunkIndex: false,
      useMessageIndex: false, useAttachmentIndex: false, useMetadataIndex: false,
      repeatSchemas: false, repeatChannels: false,
    }),
  });
  const channelIds = await startLike(writer);
  for await (const m of reader.readMessages()) {
    await writer.addMessage({ ...m, channelId: channelIds.get(m.channelId) });
  }
  for await (const a of reader.readAttachments()) await writer.addAttachment(a);
  for await (const md of reader.readMetadata()) await writer.addMetadata(md);
  await writer.end();
  return Buffer.concat(parts);
}

/** metrics.csv without the columns that time the work (they differ between any two runs). */
function metricsWithoutTimes(dir) {
  const rows = readFileSync(join(dir, "metrics.csv"), "utf8").trim().split("\n")
    .map((l) => l.split(","));
  const keep = rows[0].map((name, i) => (/_ms$/.test(name) ? -1 : i)).filter((i) => i >= 0);
  return rows.map((r) => keep.map((i) => r[i]).join(",")).join("\n");
}

let failures = 0;
const want = {
  metrics: metricsWithoutTimes(join(outDir, "replay-original")),
  map: readFileSync(join(outDir, "replay-original", "map.ot")),
};
const variants = [
  ["zstd", (data) => ({ compression: "zstd", compressedData: zstd.compress(data, 3) })],
  ["lz4", (data) => ({ compression: "lz4", compressedData: lz4.compress(data) })],
];
for (const [name, compress] of variants) {
  // Small chunks too (many chunks per file), and a file without any index or summary.
  for (const [chunkSize, indexed] of [[4 * 1024 * 1024, true], [64 * 1024, true],
                                      [1024 * 1024, false]]) {
    const label = `${name}, ${chunkSize / 1024} KiB chunks${indexed ? "" : ", no index"}`;
    const bytes = await rewrite(compress, chunkSize, indexed);
    let chunks = "unindexed";
    if (indexed) {
      const check = await McapIndexedReader.Initialize({
        readable: readable(new Uint8Array(bytes)) });
      const kinds = new Set(check.chunkIndexes.map((c) => c.compression));
      if (kinds.size !== 1 || !kinds.has(name)) {
        console.error(`FAIL ${label}: the chunks are compressed ${[...kinds].join(", ")}`);
        failures++;
        continue;
      }
      chunks = `${check.chunkIndexes.length} chunks`;
    }
    const file = join(outDir, `${name}-${chunkSize}${indexed ? "" : "-unindexed"}.mcap`);
    writeFileSync(file, bytes);
    const replayDir = join(outDir, `replay-${name}-${chunkSize}${indexed ? "" : "-unindexed"}`);
    run(["replay", file, "--out", replayDir]);
    const metrics = metricsWithoutTimes(replayDir);
    const map = readFileSync(join(replayDir, "map.ot"));
    if (metrics !== want.metrics) {
      console.error(`FAIL ${label}: metrics.csv differs from the uncompressed replay's`);
      failures++;
    } else if (!map.equals(want.map)) {
      console.error(`FAIL ${label}: map.ot differs from the uncompressed replay's`);
      failures++;
    } else {
      console.log(`ok ${label}: ${chunks}, ${bytes.length} bytes ` +
                  `(uncompressed ${original.length}); the same map and metrics`);
    }
  }
}
// ---- The same frames as a split bag and as ROS 2 Humble's SQLite 3 storage ------------------------
// A rosbag2 folder of two MCAP files (split by message count; the metadata and attachments in the
// first), and a Humble `.db3` folder (one file, and split in two) written by Python's sqlite3 in
// rosbag2's own tables (write_humble_db3.py): the split MCAP replays to the same map and metrics;
// a .db3 has no MCAP metadata or attachment (no run configuration, no ground truth), so its
// replay is compared by its map, byte for byte.
const all = [];
for await (const m of reader.readMessages()) all.push(m);
async function writeMcapPart(messages, withRecords) {
  const { parts, writable } = memoryWritable();
  const writer = new McapWriter({
    writable,
  });
  const channelIds = await startLike(writer);
  if (withRecords) {
    for await (const a of reader.readAttachments()) await writer.addAttachment(a);
    for await (const md of reader.readMetadata()) await writer.addMetadata(md);
  }
  for (const m of messages) await writer.addMessage({ ...m, channelId: channelIds.get(m.channelId) });
  await writer.end();
  return Buffer.concat(parts);
}
const splitDir = join(outDir, "split_mcap");
mkdirSync(splitDir, { recursive: true });
const half = Math.ceil(all.length / 2);
writeFileSync(join(splitDir, "split_mcap_0.mcap"), await writeMcapPart(all.slice(0, half), true));
writeFileSync(join(splitDir, "split_mcap_1.mcap"), await writeMcapPart(all.slice(half), false));
writeFileSync(join(splitDir, "metadata.yaml"), [
  "rosbag2_bagfile_information:", "  version: 5", "  storage_identifier: mcap",
  "  relative_file_paths:", "    - split_mcap_0.mcap", "    - split_mcap_1.mcap", ""].join("\n"));
{
  const replayDir = join(outDir, "replay-split-mcap");
  run(["replay", splitDir, "--out", replayDir]);
  if (metricsWithoutTimes(replayDir) !== want.metrics) {
    console.error("FAIL split MCAP folder: metrics.csv differs from the single file's replay");
    failures++;
  } else if (!readFileSync(join(replayDir, "map.ot")).equals(want.map)) {
    console.error("FAIL split MCAP folder: map.ot differs from the single file's replay");
    failures++;
  } else {
    console.log(`ok split MCAP folder (2 files, ${all.length} messages): the same map and metrics`);
  }
}
const manifest = {
  topics: [...reader.channelsById.values()].map((c) => ({
    name: c.topic, type: reader.schemasById.get(c.schemaId)?.name ?? "" })),
  messages: all.map((m) => ({ topic: reader.channelsById.get(m.channelId).topic,
                              t: m.logTime.toString(), data: Buffer.from(m.data).toString("base64") })),
};
// JSON numbers lose nanoseconds past 2^53: the stamps go as text and Python reads them as ints.
const manifestPath = join(outDir, "manifest.json");
writeFileSync(manifestPath, JSON.stringify(manifest).replace(/"t":"(\d+)"/g, '"t":$1'));
const python = process.env.PYTHON ?? "python3";
const writer = new URL("./write_humble_db3.py", import.meta.url).pathname;
const mapOnly = [];
for (const split of [1, 2]) {
  const bagDir = join(outDir, `humble_${split}`);
  execFileSync(python, [writer, manifestPath, bagDir, "--split", String(split)],
               { stdio: ["ignore", "inherit", "inherit"] });
  const replayDir = join(outDir, `replay-humble-${split}`);
  run(["replay", bagDir, "--out", replayDir]);
  mapOnly.push(replayDir);
  if (!readFileSync(join(replayDir, "map.ot")).equals(want.map)) {
    console.error(`FAIL Humble .db3 folder (${split} file(s)): map.ot differs`);
    failures++;
  } else {
    console.log(`ok Humble .db3 folder (${split} file(s)): the same map, byte for byte`);
  }
}
// The .db3 file itself (not its folder) is a bag too.
{
  const replayDir = join(outDir, "replay-humble-file");
  run(["replay", join(outDir, "humble_1", "humble_1_0.db3"), "--out", replayDir]);
  if (!readFileSync(join(replayDir, "map.ot")).equals(want.map)) {
    console.error("FAIL Humble .db3 file: map.ot differs");
    failures++;
  } else {
    console.log("ok Humble .db3 file: the same map, byte for byte");
  }
}

// avp's own writer with --record-compression: the same run recorded again, read by @mcap/core
// (its decompressors: another implementation's) to the same payloads on every topic but /avp/step
// (timings), and replayed
// to the same map.
const payloads = async (buf, handlers) => {
  const r = await McapIndexedReader.Initialize({ readable: readable(buf),
                                                 decompressHandlers: handlers });
  const out = [];
  for await (const m of r.readMessages()) {
    const topic = r.channelsById.get(m.channelId).topic;
    if (topic === "/avp/step") continue;  // the step's timings: they differ between any two runs
    out.push(`${topic} ${createHash("sha256").update(m.data).digest("hex")}`);
  }
  return { list: out.join("\n"), kinds: new Set(r.chunkIndexes.map((c) => c.compression)) };
};
const handlers = {
  zstd: (data, size) => zstd.decompress(data, Number(size)),
  lz4: (data, size) => lz4.decompress(data, Number(size)),
};
const wantPayloads = await payloads(original, handlers);
for (const name of ["zstd", "lz4"]) {
  const dir = join(outDir, `run-${name}`);
  run(["run", "--scenario", "tomato-single-cluster", "--seed", "1", "--views", "3", "--threads",
       "2", "--out", dir, "--record", "--record-compression", name]);
  const bytes = new Uint8Array(readFileSync(join(dir, "episode.mcap")));
  const got = await payloads(bytes, handlers);
  const replayDir = join(outDir, `replay-run-${name}`);
  run(["replay", join(dir, "episode.mcap"), "--out", replayDir]);
  if (got.kinds.size !== 1 || !got.kinds.has(name)) {
    console.error(`FAIL avp --record-compression ${name}: chunks ${[...got.kinds].join(", ")}`);
    failures++;
  } else if (got.list !== wantPayloads.list) {
    console.error(`FAIL avp --record-compression ${name}: payloads differ from the uncompressed ` +
                  "recording's");
    failures++;
  } else if (!readFileSync(join(replayDir, "map.ot")).equals(want.map)) {
    console.error(`FAIL avp --record-compression ${name}: its replay's map.ot differs`);
    failures++;
  } else {
    console.log(`ok avp --record-compression ${name}: ${bytes.length} bytes (uncompressed ` +
                `${original.length}); @mcap/core reads the same payloads; the same map`);
  }
}

// A compression avp does not read, and a zstd chunk that does not decompress: refused, named.
const refused = [
  ["bz2", (data) => ({ compression: "bz2", compressedData: data }),
   /compression 'bz2' is not one avp reads \(uncompressed, zstd or lz4.*mcap decompress/],
  ["corrupt zstd", (data) => ({ compression: "zstd", compressedData: data.subarray(0, 64) }),
   /\(zstd\) does not decompress/],
];
for (const [name, compress, message] of refused) {
  const file = join(outDir, `${name.replace(" ", "-")}.mcap`);
  writeFileSync(file, await rewrite(compress, 4 * 1024 * 1024));
  let output = "";
  try {
    execFileSync(avp, ["replay", file, "--out", join(outDir, `replay-${name.replace(" ", "-")}`)],
                 { stdio: ["ignore", "pipe", "pipe"] });
  } catch (e) {
    output = `${e.stdout}${e.stderr}`;
  }
  if (!message.test(output)) {
    console.error(`FAIL ${name}: expected ${message}, got: ${output || "success"}`);
    failures++;
  } else {
    console.log(`ok ${name}: refused (${output.trim().split("\n").pop().slice(0, 160)})`);
  }
}
if (failures > 0) {
  console.error(`compressed_replay: ${failures} failure(s)`);
  process.exit(1);
}
console.log("compressed_replay: ok");
