// MCAP read-back with npm's readers (issue 17): runs mcap_ros2_dump (avp's MCAP writer, real ROS 2
// messages from avp's ros/msg encoders), then reads the file with @mcap/core's McapIndexedReader
// and McapStreamReader (CRCs validated) and checks the header, schemas, channels, statistics and
// every message against the JSON sidecar; decodes each payload with @foxglove/rosmsg2-serialization
// against the file's own ros2msg schema text parsed by @foxglove/rosmsg; recomputes the data
// section and summary CRCs (which the npm readers do not check); and checks that @mcap/core
// refuses a copy with one payload byte flipped.
// Usage: node readback.mjs --dump <mcap_ros2_dump> --lockfile <tests/npm/package-lock.json>
//                          --out <scratch dir>
// The npm packages come from scripts/setup: ${XDG_CACHE_HOME:-~/.cache}/avp/npm-test/<sha256 of
// the lockfile>/node_modules (or AVP_NPM_TEST_DIR=<dir holding node_modules>).

import { execFileSync } from "node:child_process";
import { readFileSync } from "node:fs";
import { join } from "node:path";
import zlib from "node:zlib";

import { arg, npmTestRequire } from "../../../tests/npm/npm_test.mjs";

const dumpExe = arg("readback.mjs", "--dump");
const lockfile = arg("readback.mjs", "--lockfile");
const outDir = arg("readback.mjs", "--out");
const require = npmTestRequire("mcap_npm_readback", lockfile,
                                ["@mcap/core", "@foxglove/rosmsg2-serialization",
                                 "@foxglove/rosmsg"]);
const { McapIndexedReader, McapStreamReader } = require("@mcap/core");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const { parse } = require("@foxglove/rosmsg");

const mcapPath = execFileSync(dumpExe, [outDir]).toString("utf8").trim();
const expected = JSON.parse(readFileSync(join(outDir, "expected.json"), "utf8"));
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

// Deep comparison; typed arrays compare as arrays, bigints as numbers where exact.
function diff(want, actual, path) {
  if (ArrayBuffer.isView(actual)) actual = Array.from(actual);
  if (typeof actual === "bigint") actual = Number(actual);
  if (Array.isArray(want)) {
    if (!Array.isArray(actual)) return `${path}: expected an array, got ${JSON.stringify(actual)}`;
    if (want.length !== actual.length) {
      return `${path}: expected ${want.length} elements, got ${actual.length}`;
    }
    for (let i = 0; i < want.length; i++) {
      const d = diff(want[i], actual[i], `${path}[${i}]`);
      if (d) return d;
    }
    return undefined;
  }
  if (want !== null && typeof want === "object") {
    if (actual === null || typeof actual !== "object") return `${path}: expected an object`;
    for (const key of Object.keys(want)) {
      const d = diff(want[key], actual[key], `${path}.${key}`);
      if (d) return d;
    }
    for (const key of Object.keys(actual)) {
      if (!(key in want)) return `${path}.${key}: not expected`;
    }
    return undefined;
  }
  if (typeof want === "boolean" && typeof actual === "number") actual = actual !== 0;
  return Object.is(want, actual) ? undefined : `${path}: expected ${want}, got ${actual}`;
}

const textDecoder = new TextDecoder();
const readers = new Map();  // schema id -> MessageReader

function checkSchemasAndChannels(schemas, channels, where) {
  eq(schemas.size, expected.schemas.length, `${where} schema count`);
  expected.schemas.forEach((s, i) => {
    const got = schemas.get(i + 1);
    check(got !== undefined, `${where} schema ${i + 1} missing`);
    if (!got) return;
    eq(got.name, s.name, `${where} schema ${i + 1} name`);
    eq(got.encoding, s.encoding, `${where} schema ${i + 1} encoding`);
    eq(textDecoder.decode(got.data), s.data, `${where} schema ${i + 1} text`);
    if (!readers.has(got.id)) {
      readers.set(got.id, new MessageReader(parse(textDecoder.decode(got.data), { ros2: true })));
    }
  });
  eq(channels.size, expected.channels.length, `${where} channel count`);
  for (const c of expected.channels) {
    const got = channels.get(c.id);
    check(got !== undefined, `${where} channel ${c.id} missing`);
    if (!got) continue;
    eq(got.topic, c.topic, `${where} channel ${c.id} topic`);
    eq(got.messageEncoding, c.message_encoding, `${where} channel ${c.id} encoding`);
    eq(schemas.get(got.schemaId)?.name, c.schema_name, `${where} channel ${c.id} schema`);
    eq(got.metadata.get("offered_qos_profiles"), c.offered_qos_profiles,
       `${where} channel ${c.id} offered_qos_profiles`);
  }
}

function checkMessages(messages, channels, where) {
  eq(messages.length, expected.messages.length, `${where} message count`);
  const n = Math.min(messages.length, expected.messages.length);
  for (let i = 0; i < n; i++) {
    const m = messages[i];
    const e = expected.messages[i];
    const w = `${where} message ${i}`;
    eq(m.channelId, e.channel_id, `${w} channel`);
    eq(m.sequence, e.sequence, `${w} sequence`);
    eq(m.logTime, BigInt(e.log_time), `${w} log time`);
    eq(m.publishTime, BigInt(e.publish_time), `${w} publish time`);
    const reader = readers.get(channels.get(m.channelId).schemaId);
    let value;
    try {
      value = reader.readMessage(m.data);
    } catch (err) {
      check(false, `${w}: the CDR payload does not decode: ${err.message}`);
      continue;
    }
    const d = diff(e.value, value, `${w} (${channels.get(m.channelId).topic})`);
    check(d === undefined, d);
  }
}

const readable = (buf) => ({
  size: async () => BigInt(buf.length),
  read: async (offset, length) => buf.subarray(Number(offset), Number(offset + length)),
});

// ---- Indexed -------------------------------------------------------------------------------------
const indexed = await McapIndexedReader.Initialize({ readable: readable(bytes) });
eq(indexed.header.profile, "ros2", "indexed header profile");
eq(indexed.header.library, "avp", "indexed header library");
checkSchemasAndChannels(indexed.schemasById, indexed.channelsById, "indexed");
const stats = indexed.statistics;
check(stats !== undefined, "indexed: no Statistics record");
eq(stats?.messageCount, BigInt(expected.statistics.message_count), "statistics message count");
eq(stats?.chunkCount, expected.statistics.chunk_count, "statistics chunk count");
eq(stats?.channelCount, expected.channels.length, "statistics channel count");
eq(stats?.schemaCount, expected.schemas.length, "statistics schema count");
eq(stats?.messageStartTime, BigInt(expected.statistics.message_start_time), "statistics start");
eq(stats?.messageEndTime, BigInt(expected.statistics.message_end_time), "statistics end");
eq(indexed.chunkIndexes.length, expected.statistics.chunk_count, "chunk index count");
check(expected.statistics.chunk_count > 1, "the test file should have several chunks");
const perChannel = new Map();
for (const m of expected.messages) perChannel.set(m.channel_id, (perChannel.get(m.channel_id) ?? 0) + 1);
for (const [id, count] of perChannel) {
  eq(stats?.channelMessageCounts.get(id), BigInt(count), `statistics count of channel ${id}`);
}
// Attachments and metadata through their summary indexes; the attachment's CRC validated.
eq(stats?.attachmentCount, expected.statistics.attachment_count, "statistics attachment count");
eq(stats?.metadataCount, expected.statistics.metadata_count, "statistics metadata count");
eq(indexed.attachmentIndexes.length, expected.attachments.length, "attachment index count");
eq(indexed.metadataIndexes.length, expected.metadata.length, "metadata index count");
const attachments = [];
for await (const a of indexed.readAttachments({ validateCrcs: true })) attachments.push(a);
eq(attachments.length, expected.attachments.length, "attachments read");
expected.attachments.forEach((e, i) => {
  const a = attachments[i];
  if (!a) return;
  eq(a.name, e.name, `attachment ${i} name`);
  eq(a.mediaType, e.media_type, `attachment ${i} media type`);
  eq(a.logTime, BigInt(e.log_time), `attachment ${i} log time`);
  eq(a.createTime, BigInt(e.create_time), `attachment ${i} create time`);
  eq(textDecoder.decode(a.data), e.data, `attachment ${i} data`);
});
const metadata = [];
for await (const m of indexed.readMetadata()) metadata.push(m);
eq(metadata.length, expected.metadata.length, "metadata records read");
expected.metadata.forEach((e, i) => {
  const m = metadata[i];
  if (!m) return;
  eq(m.name, e.name, `metadata ${i} name`);
  const d = diff(e.metadata, Object.fromEntries(m.metadata), `metadata ${i}`);
  check(d === undefined, d);
});

const indexedMessages = [];
for await (const m of indexed.readMessages({ validateCrcs: true })) indexedMessages.push(m);
// The indexed reader yields log-time order; the sidecar is in write order with equal log times
// kept in write order, which the sequence numbers give.
indexedMessages.sort((a, b) => (a.logTime < b.logTime ? -1 : a.logTime > b.logTime ? 1 : a.sequence - b.sequence));
checkMessages(indexedMessages, indexed.channelsById, "indexed");

// ---- Streaming -----------------------------------------------------------------------------------
const stream = new McapStreamReader({ validateCrcs: true });
stream.append(bytes);
const sSchemas = new Map();
const sChannels = new Map();
const sMessages = [];
const sAttachments = [];
const sMetadata = [];
let dataEnd;
let footer;
for (let r; (r = stream.nextRecord()); ) {
  if (r.type === "Header") {
    eq(r.profile, "ros2", "streaming header profile");
  } else if (r.type === "Schema" && dataEnd === undefined) {
    sSchemas.set(r.id, r);
  } else if (r.type === "Channel" && dataEnd === undefined) {
    sChannels.set(r.id, r);
  } else if (r.type === "Message") {
    sMessages.push(r);
  } else if (r.type === "Attachment") {
    sAttachments.push(r);
  } else if (r.type === "Metadata") {
    sMetadata.push(r);
  } else if (r.type === "DataEnd") {
    dataEnd = r;
  } else if (r.type === "Footer") {
    footer = r;
  }
}
check(stream.done(), "streaming: the reader did not reach the end magic");
checkSchemasAndChannels(sSchemas, sChannels, "streaming");
checkMessages(sMessages, sChannels, "streaming");
eq(sAttachments.map((a) => a.name).join(","), expected.attachments.map((a) => a.name).join(","),
   "streaming attachments");
eq(sMetadata.map((m) => m.name).join(","), expected.metadata.map((m) => m.name).join(","),
   "streaming metadata");

// ---- The CRCs the npm readers leave unchecked ----------------------------------------------------
check(dataEnd !== undefined && footer !== undefined, "streaming: no Data End or Footer record");
if (dataEnd && footer) {
  const summaryStart = Number(footer.summaryStart);
  const dataEndAt = summaryStart - (1 + 8 + 4);
  eq(zlib.crc32(bytes.subarray(0, dataEndAt)), dataEnd.dataSectionCrc, "data section CRC");
  const footerAt = bytes.length - 8 - (1 + 8 + 8 + 8 + 4);
  eq(zlib.crc32(bytes.subarray(summaryStart, footerAt + 1 + 8 + 8 + 8)), footer.summaryCrc,
     "summary CRC");
  check(dataEnd.dataSectionCrc !== 0 && footer.summaryCrc !== 0, "CRCs must be written (non-zero)");
}

// ---- A flipped payload byte is refused by @mcap/core's CRC check ---------------------------------
const bad = bytes.slice();
const firstImage = expected.messages.find((m) => m.value.encoding === "rgb8");
const needle = Buffer.from(firstImage.value.data.slice(0, 32));
const at = Buffer.from(bad.buffer).indexOf(needle);
check(at > 0, "the first image's pixels are not in the file");
bad[at + 5] ^= 0xff;
let refused = "";
try {
  const r = await McapIndexedReader.Initialize({ readable: readable(bad) });
  for await (const m of r.readMessages({ validateCrcs: true })) void m;
} catch (err) {
  refused = err.message;
}
check(/crc/i.test(refused), `@mcap/core should refuse a flipped payload byte by CRC, got "${refused}"`);

if (failures > 0) {
  console.error(`mcap_npm_readback: ${failures} failure(s) in ${mcapPath}`);
  process.exit(1);
}
console.log(`mcap_npm_readback: ${expected.messages.length} messages on ${expected.channels.length} ` +
            `channels in ${expected.statistics.chunk_count} chunks, ${attachments.length} ` +
            `attachment(s) and ${metadata.length} metadata record(s) read back with @mcap/core ` +
            `(indexed and streaming, CRCs checked) and decoded with @foxglove/rosmsg2-serialization`);
