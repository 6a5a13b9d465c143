#!/usr/bin/env python3
"""Writes a rosbag2 bag folder as ROS 2 Humble's `ros2 bag record` does with its default storage:
`<folder>/<name>_0.db3` (SQLite 3, schema version 3: the `schema`, `metadata`, `topics` and
`messages` tables and the `timestamp_idx` index of rosbag2_storage_default_plugins) and
`<folder>/metadata.yaml` (rosbag2_bagfile_information, version 5), from a JSON manifest of
messages. Python's standard library only (sqlite3, json, base64), so that a test can write a
Humble bag without ROS.

Manifest: {"topics": [{"name": "/tf", "type": "tf2_msgs/msg/TFMessage"}, ...],
           "messages": [{"topic": "/tf", "t": 1700000000000000000, "data": "<base64 CDR>"}, ...]}
Usage: write_humble_db3.py MANIFEST.json FOLDER [--split N]  (N files, split by message count)
       write_humble_db3.py --from-mcap FILE.mcap FOLDER [--split N]
--from-mcap reads the messages of an MCAP file with uncompressed chunks (as `avp run --record`
writes by default) instead of a manifest: the README's Humble example is made from a recording.
"""

import base64
import json
import os
import sqlite3
import struct
import sys

QOS = ("- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  deadline:\n"
       "    sec: 2147483647\n    nsec: 4294967295\n  lifespan:\n    sec: 2147483647\n"
       "    nsec: 4294967295\n  liveliness: 1\n  liveliness_lease_duration:\n"
       "    sec: 2147483647\n    nsec: 4294967295\n  avoid_ros_namespace_conventions: false")

# rosbag2 Humble (rosbag2_storage_default_plugins/src/.../sqlite_storage.cpp, schema version 3).
SCHEMA = [
    "CREATE TABLE schema(schema_version INTEGER PRIMARY KEY,ros_distro TEXT NOT NULL);",
    "CREATE TABLE metadata(id INTEGER PRIMARY KEY,metadata_version INTEGER NOT NULL,"
    "metadata TEXT NOT NULL);",
    "CREATE TABLE topics(id INTEGER PRIMARY KEY,name TEXT NOT NULL,type TEXT NOT NULL,"
    "serialization_format TEXT NOT NULL,offered_qos_profiles TEXT NOT NULL);",
    "CREATE TABLE messages(id INTEGER PRIMARY KEY,topic_id INTEGER NOT NULL,"
    "timestamp INTEGER NOT NULL, data BLOB NOT NULL);",
    "CREATE INDEX timestamp_idx ON messages (timestamp ASC);",
]


def write_db3(path, topics, messages):
    if os.path.exists(path):
        os.remove(path)
    db = sqlite3.connect(path)
    for statement in SCHEMA:
        db.execute(statement)
    db.execute("INSERT INTO schema VALUES (3, 'humble')")
    ids = {}
    for t in topics:
        ids[t["name"]] = len(ids) + 1
        db.execute("INSERT INTO topics VALUES (?, ?, ?, 'cdr', ?)",
                   (ids[t["name"]], t["name"], t["type"], QOS))
    db.executemany("INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)",
                   ((ids[m["topic"]], m["t"], base64.b64decode(m["data"])) for m in messages))
    db.commit()
    db.close()


def metadata_yaml(files, topics, messages):
    counts = {t["name"]: 0 for t in topics}
    for m in messages:
        counts[m["topic"]] += 1
    start = min(m["t"] for m in messages)
    duration = max(m["t"] for m in messages) - start
    lines = ["rosbag2_bagfile_information:", "  version: 5", "  storage_identifier: sqlite3",
             "  duration:", f"    nanoseconds: {duration}", "  starting_time:",
             f"    nanoseconds_since_epoch: {start}", f"  message_count: {len(messages)}",
             "  topics_with_message_count:"]
    for t in topics:
        lines += ["    - topic_metadata:", f"        name: {t['name']}",
                  f"        type: {t['type']}", "        serialization_format: cdr",
                  f"        offered_qos_profiles: {json.dumps(QOS)}",
                  f"      message_count: {counts[t['name']]}"]
    lines += ['  compression_format: ""', '  compression_mode: ""', "  relative_file_paths:"]
    lines += [f"    - {f}" for f in files]
    lines += ["  files:"]
    for f, part in files.items():
        lines += [f"    - path: {f}", "      starting_time:",
                  f"        nanoseconds_since_epoch: {min(m['t'] for m in part)}",
                  "      duration:",
                  f"        nanoseconds: {max(m['t'] for m in part) - min(m['t'] for m in part)}",
                  f"      message_count: {len(part)}"]
    return "\n".join(lines) + "\n"


def read_mcap(path):
    """The topics and messages of an MCAP file whose chunks are uncompressed, as a manifest."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"\x89MCAP0\r\n":
        raise SystemExit(f"{path}: not an MCAP file")
    schemas, channels, messages = {}, {}, []

    def string(buf, at):
        n = struct.unpack_from("<I", buf, at)[0]
        return buf[at + 4:at + 4 + n].decode(), at + 4 + n

    def records(buf, at, end):
        while at + 9 <= end:
            op, n = struct.unpack_from("<BQ", buf, at)
            body = buf[at + 9:at + 9 + n]
            at += 9 + n
            if op == 0x02:  # Footer
                return
            if op == 0x03:  # Schema
                sid = struct.unpack_from("<H", body, 0)[0]
                schemas[sid], _ = string(body, 2)
            elif op == 0x04:  # Channel
                cid, sid = struct.unpack_from("<HH", body, 0)
                topic, _ = string(body, 4)
                channels[cid] = (topic, schemas.get(sid, ""))
            elif op == 0x05:  # Message
                cid, _, log_time = struct.unpack_from("<HIQ", body, 0)
                topic, _ = channels[cid]
                messages.append({"topic": topic, "t": log_time,
                                 "data": base64.b64encode(body[22:]).decode()})
            elif op == 0x06:  # Chunk
                compression, at2 = string(body, 28)
                if compression:
                    raise SystemExit(f"{path}: a {compression} chunk (only uncompressed ones here)")
                length = struct.unpack_from("<Q", body, at2)[0]
                records(body, at2 + 8, at2 + 8 + length)

    records(data, 8, len(data))
    topics = [{"name": t, "type": ty} for t, ty in dict(channels.values()).items()]
    return {"topics": topics, "messages": messages}


def main():
    args = sys.argv[1:]
    split = 1
    if "--split" in args:
        i = args.index("--split")
        split = int(args[i + 1])
        del args[i:i + 2]
    if args and args[0] == "--from-mcap":
        manifest = read_mcap(args[1])
        folder = args[2]
    else:
        manifest_path, folder = args
        with open(manifest_path) as f:
            manifest = json.load(f)
    topics, messages = manifest["topics"], manifest["messages"]
    messages.sort(key=lambda m: m["t"])  # stable: ties keep the manifest's order
    os.makedirs(folder, exist_ok=True)
    name = os.path.basename(os.path.normpath(folder))
    files = {}
    per_file = -(-len(messages) // split)
    for k in range(split):
        part = messages[k * per_file:(k + 1) * per_file]
        if not part:
            continue
        file_name = f"{name}_{k}.db3"
        write_db3(os.path.join(folder, file_name), topics, part)
        files[file_name] = part
    with open(os.path.join(folder, "metadata.yaml"), "w") as f:
        f.write(metadata_yaml(files, topics, messages))
    print(f"wrote {folder}: {len(messages)} messages in {len(files)} .db3 file(s)")


if __name__ == "__main__":
    main()
