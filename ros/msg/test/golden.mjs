// Golden bytes against ROS 2's own definitions (issue 14). Runs rosmsg_golden_dump, then for every
// sample: encodes its value with @foxglove/rosmsg2-serialization against
//   - npm's ROS 2 Humble and Jazzy definitions (@foxglove/rosmsg-msgs-common) where the type is
//     there (octomap_msgs and rmw_dds_common are not), and
//   - avp's own schema text (Definition<T>(), parsed by @foxglove/rosmsg),
// and checks the bytes equal avp's; then decodes avp's bytes with each and checks the value.
// Usage: node golden.mjs --dump <rosmsg_golden_dump> --lockfile <tests/npm/package-lock.json>
// The npm packages come from scripts/setup: ${XDG_CACHE_HOME:-~/.cache}/avp/npm-test/<sha256 of
// the lockfile>/node_modules (or AVP_NPM_TEST_DIR=<dir holding node_modules>).

import { execFileSync } from "node:child_process";
import { join } from "node:path";

import { arg, npmTestRequire } from "../../../tests/npm/npm_test.mjs";

const dumpExe = arg("golden.mjs", "--dump");
const lockfile = arg("golden.mjs", "--lockfile");
const require = npmTestRequire("ros_msg_golden", lockfile,
                                ["@foxglove/rosmsg2-serialization", "@foxglove/rosmsg",
                                 "@foxglove/rosmsg-msgs-common", "@foxglove/cdr"]);
const { MessageReader, MessageWriter } = require("@foxglove/rosmsg2-serialization");
const { parse } = require("@foxglove/rosmsg");
const common = require("@foxglove/rosmsg-msgs-common");

const dump = JSON.parse(execFileSync(dumpExe, { maxBuffer: 256 << 20 }).toString("utf8"));

// "sensor_msgs/msg/Image" -> "sensor_msgs/Image"
const shortName = (rosName) => rosName.replace("/msg/", "/");

function commonDefinitions(set, rosName) {
  const root = set[shortName(rosName)];
  if (root === undefined) return undefined;
  return [root, ...Object.values(set)];
}

function avpDefinitions(rosName, distro) {
  const text = dump.definitions[rosName][distro];
  return parse(text, { ros2: true });
}

function toHex(bytes) {
  return Buffer.from(bytes.buffer, bytes.byteOffset, bytes.byteLength).toString("hex");
}

// Deep comparison; typed arrays compare as arrays, numbers with Object.is (so -0 != 0).
function diff(expected, actual, path) {
  if (ArrayBuffer.isView(actual)) actual = Array.from(actual);
  if (Array.isArray(expected)) {
    if (!Array.isArray(actual)) return `${path}: expected an array, got ${JSON.stringify(actual)}`;
    if (expected.length !== actual.length) {
      return `${path}: expected ${expected.length} elements, got ${actual.length}`;
    }
    for (let i = 0; i < expected.length; i++) {
      const d = diff(expected[i], actual[i], `${path}[${i}]`);
      if (d) return d;
    }
    return undefined;
  }
  if (expected !== null && typeof expected === "object") {
    if (actual === null || typeof actual !== "object") {
      return `${path}: expected an object, got ${JSON.stringify(actual)}`;
    }
    const keys = new Set([...Object.keys(expected), ...Object.keys(actual)]);
    for (const k of keys) {
      const d = diff(expected[k], actual[k], path ? `${path}.${k}` : k);
      if (d) return d;
    }
    return undefined;
  }
  if (typeof expected === "number" && typeof actual === "number") {
    return Object.is(expected, actual) ? undefined : `${path}: expected ${expected}, got ${actual}`;
  }
  return expected === actual ? undefined
                             : `${path}: expected ${JSON.stringify(expected)}, got ${JSON.stringify(actual)}`;
}

// @foxglove/cdr 3.5.0's CdrWriter.string() writes value.length (UTF-16 code units) as the length
// and truncates the UTF-8 bytes to it, so npm cannot produce reference bytes for non-ASCII
// strings. For samples with such strings only npm's reader is used (it decodes UTF-8 correctly);
// the ASCII samples cover the same layouts byte for byte.
function hasNonAscii(value) {
  if (typeof value === "string") return /[^\x00-\x7f]/.test(value);
  if (Array.isArray(value)) return value.some(hasNonAscii);
  if (value !== null && typeof value === "object") return Object.values(value).some(hasNonAscii);
  return false;
}

let failures = 0;
let checks = 0;
let decodeOnly = 0;
const coveredByCommon = new Set();
for (const [index, sample] of dump.samples.entries()) {
  const label = `sample ${index} ${sample.type} (${sample.distro})`;
  const variants = [];
  const distros = sample.distro === "any" ? ["humble", "jazzy"] : [sample.distro];
  for (const distro of distros) {
    const set = distro === "humble" ? common.ros2humble : common.ros2jazzy;
    const defs = commonDefinitions(set, sample.type);
    if (defs !== undefined) {
      variants.push([`npm ros2${distro}`, defs]);
      coveredByCommon.add(sample.type);
    }
    variants.push([`avp's ${distro} schema`, avpDefinitions(sample.type, distro)]);
  }
  const avpBytes = Buffer.from(sample.hex, "hex");
  const nonAscii = hasNonAscii(sample.value);
  if (nonAscii) decodeOnly++;
  for (const [what, defs] of variants) {
    checks++;
    try {
      const npmHex = nonAscii ? sample.hex : toHex(new MessageWriter(defs).writeMessage(sample.value));
      if (npmHex !== sample.hex) {
        failures++;
        console.error(`FAIL ${label} with ${what}: bytes differ\n  avp ${sample.hex}\n  npm ${npmHex}`);
        continue;
      }
      // Decode from an exact-size copy: @foxglove/cdr may read past the end of a view otherwise.
      const copy = new Uint8Array(avpBytes.length);
      copy.set(avpBytes);
      const reader = new MessageReader(defs);
      const decoded = reader.readMessage(copy);
      const d = diff(sample.value, decoded, "");
      if (d) {
        failures++;
        console.error(`FAIL ${label} with ${what}: npm decodes avp's bytes differently: ${d}`);
      } else if (reader.lastReadHadTrailingBytes()) {
        failures++;
        console.error(`FAIL ${label} with ${what}: avp's bytes have trailing bytes`);
      }
    } catch (e) {
      failures++;
      console.error(`FAIL ${label} with ${what}: ${e.stack || e}`);
    }
  }
}

const types = new Set(dump.samples.map((s) => s.type));
const notInCommon = [...types].filter((t) => !coveredByCommon.has(t));
console.log(`ros_msg_golden: ${dump.samples.length} samples of ${types.size} types, ${checks} checks, ` +
            `${failures} failures; ${decodeOnly} samples with non-ASCII strings checked by decoding only; ` +
            `checked against avp's schema only (not in ` +
            `@foxglove/rosmsg-msgs-common): ${notInCommon.join(", ")}`);
process.exit(failures === 0 ? 0 : 1);
