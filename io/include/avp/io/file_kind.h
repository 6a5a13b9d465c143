#pragma once

#include <string>
#include <string_view>

namespace avp::io {

/// What a file is, recognised by its first bytes, in a user's words: "a PNG image", "a JPEG
/// image", "an MCAP recording", "an SQLite database (a rosbag2 .db3?)", "an avp map (.avpmap)",
/// "an OctoMap map (.bt / .ot)", "a PLY mesh or point cloud", "an STL mesh", "a binary glTF mesh
/// (.glb)", "a COLLADA mesh (.dae)", "a Wavefront OBJ mesh", "a zip archive", the JSON files avp
/// writes ("an avp run record (record.json)", "an avp bench record (bench.json)", "an avp folder
/// state file (avp-state.json)"), or "a binary file". Empty when the bytes are text it does not
/// recognise (YAML, JSON of another program, CSV): then the reader's own error says more. So that
/// a file passed where another kind is expected is named, with what the option accepts.
std::string DescribeFileKind(std::string_view head);

}  // namespace avp::io
