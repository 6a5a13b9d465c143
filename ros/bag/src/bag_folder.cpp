// A rosbag2 bag folder's metadata.yaml (rosbag2_storage's BagMetadata, versions 1 to 9: Dashing to
// Jazzy): which storage plugin wrote the folder's files, the files in order (a split bag), the
// topics and their message counts, and the compression.

#include <algorithm>
#include <cctype>
#include <system_error>
#include <utility>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/io/yaml.h>
#include <avp/ros/bag/message_source.h>

namespace avp::ros::bag {
namespace {

namespace fs = std::filesystem;

constexpr std::string_view kInfoKey = "rosbag2_bagfile_information";
/// At most this many of a folder's names in a message.
constexpr size_t kMaxListedNames = 20;

/// "it holds 'a.db3', 'b.db3'" (sorted; at most kMaxListedNames) or "it is empty".
std::string FolderListing(const fs::path& folder) {
  std::vector<std::string> names;
  std::error_code ec;
  for (fs::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec)) {
    std::error_code kind_ec;
    names.push_back(it->path().filename().string() + (it->is_directory(kind_ec) ? "/" : ""));
  }
  if (names.empty()) return "it is empty";
  std::sort(names.begin(), names.end());
  const size_t total = names.size();
  if (total > kMaxListedNames) names.resize(kMaxListedNames);
  std::vector<std::string> quoted;
  for (const std::string& n : names) quoted.push_back(QuoteText(n));
  return fmt::format(
      "it holds {}{}", fmt::join(quoted, ", "),
      total > names.size() ? fmt::format(" and {} more", total - names.size()) : std::string());
}

/// OK when `folder` is a folder holding metadata.yaml; else says what is there instead.
Status CheckMetadataFile(const fs::path& folder, const fs::path& file) {
  std::error_code ec;
  if (!fs::exists(folder, ec)) {
    return NotFoundError(fmt::format("bag folder '{}' does not exist", folder.string()));
  }
  if (!fs::is_directory(folder, ec)) {
    return InvalidArgumentError(fmt::format(
        "'{}' is not a folder (a rosbag2 bag folder holds metadata.yaml and the bag's files)",
        folder.string()));
  }
  if (!fs::exists(file, ec)) {
    return NotFoundError(fmt::format(
        "'{}' does not exist ({}): a rosbag2 bag folder holds metadata.yaml beside its .db3 or "
        ".mcap files; for a recording that was cut short, `ros2 bag reindex {}` writes it again",
        file.string(), FolderListing(folder), folder.string()));
  }
  return Status::Ok();
}

/// map[key]; an undefined node when `map` is not a map or lacks the key (yaml-cpp throws for a
/// scalar's subscript and for most questions to the node of a missing key).
YAML::Node Get(const YAML::Node& map, std::string_view key) {
  if (!map.IsDefined() || !map.IsMap()) return YAML::Node(YAML::NodeType::Undefined);
  const YAML::Node v = map[std::string(key)];
  return v.IsDefined() ? v : YAML::Node(YAML::NodeType::Undefined);
}

/// Defined and not null.
bool Present(const YAML::Node& node) { return node.IsDefined() && !node.IsNull(); }

/// node[key] as a string; "" when absent or null (keys older metadata versions lack).
Result<std::string> OptionalString(const YAML::Node& node, std::string_view key,
                                   std::string_view context) {
  if (!Present(Get(node, key))) return std::string();
  return io::ReadString(node, key, context);
}

std::string Upper(std::string text) {
  for (char& c : text) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return text;
}

/// compression_mode and compression_format (metadata version 3 and later). FILE mode is refused:
/// its files are compressed whole.
Status ReadCompression(const YAML::Node& info, std::string_view context, BagFolderMetadata& m) {
  AVP_ASSIGN_OR_RETURN(const std::string mode, OptionalString(info, "compression_mode", context));
  AVP_ASSIGN_OR_RETURN(const std::string format,
                       OptionalString(info, "compression_format", context));
  // rosbag2 reads the mode case-insensitively; "NONE" and "" are the same.
  m.compression_mode = Upper(mode) == "NONE" ? "" : Upper(mode);
  if (m.compression_mode.empty()) return Status::Ok();  // the format has no effect then
  if (m.compression_mode == "FILE") {
    return InvalidArgumentError(fmt::format(
        "{}: 'compression_mode' is FILE: the bag's files are compressed whole ({}), which avp "
        "does not read; decompress them first: `zstd -d FILE` on each file, then in "
        "metadata.yaml drop the .zstd from relative_file_paths (and files) and set "
        "compression_mode and compression_format to \"\"; or `ros2 bag convert -i BAG -o "
        "out.yaml` (Humble and later) with an out.yaml whose output_bags entry has a uri, a "
        "storage_id, `all: true` (Jazzy: `all_topics: true`) and no compression",
        context, format.empty() ? std::string("format unnamed") : QuoteText(format)));
  }
  if (m.compression_mode != "MESSAGE") {
    return InvalidArgumentError(
        fmt::format("{}: 'compression_mode' is {}, not one rosbag2 writes (\"\", FILE or MESSAGE)",
                    context, QuoteText(mode)));
  }
  if (format != "zstd") {
    return InvalidArgumentError(fmt::format(
        "{}: 'compression_format' is {}: avp reads per-message compression with zstd only "
        "(rosbag2's compressor)",
        context, QuoteText(format)));
  }
  m.compression_format = format;
  return Status::Ok();
}

/// topics_with_message_count: each topic's type and message count.
Status ReadTopics(const YAML::Node& info, std::string_view context, BagFolderMetadata& m) {
  const YAML::Node topics = Get(info, "topics_with_message_count");
  if (!Present(topics)) return Status::Ok();
  if (!topics.IsSequence()) {
    return InvalidArgumentError(
        fmt::format("{}: 'topics_with_message_count' must be a list of topics", context));
  }
  for (size_t i = 0; i < topics.size(); ++i) {
    const std::string where = fmt::format("{}: topics_with_message_count[{}]", context, i);
    const YAML::Node entry = topics[i];
    const YAML::Node topic = Get(entry, "topic_metadata");
    if (!topic.IsDefined() || !topic.IsMap()) {
      return InvalidArgumentError(
          fmt::format("{}: 'topic_metadata' is missing or not a map of name, type, ...", where));
    }
    const std::string topic_where = where + ": topic_metadata";
    AVP_ASSIGN_OR_RETURN(const std::string name, io::ReadString(topic, "name", topic_where));
    AVP_ASSIGN_OR_RETURN(const std::string type, io::ReadString(topic, "type", topic_where));
    AVP_ASSIGN_OR_RETURN(const int64_t count, io::ReadInt(entry, "message_count", where));
    if (count < 0) {
      return InvalidArgumentError(
          fmt::format("{}: 'message_count' is {}, must be >= 0", where, count));
    }
    m.topic_types.emplace(name, type);
    m.topic_counts[name] += static_cast<uint64_t>(count);
  }
  return Status::Ok();
}

/// relative_file_paths[i] as a path inside `folder`: relative, no "..".
Result<fs::path> ResolveFile(const fs::path& folder, const std::string& text,
                             std::string_view where) {
  const fs::path relative(text);
  if (text.empty() || relative.is_absolute() || relative.has_root_path()) {
    return InvalidArgumentError(
        fmt::format("{} is {}: it must name a file inside the bag folder (a relative path)", where,
                    QuoteText(text)));
  }
  for (const fs::path& part : relative) {
    if (part == "..") {
      return InvalidArgumentError(fmt::format(
          "{} is {}: '..' would leave the bag folder; avp reads only the files inside it", where,
          QuoteText(text)));
    }
  }
  fs::path file = folder / relative;
  std::error_code ec;
  // Older rosbag2 (metadata versions up to 3, some of 4) prefixed each path with the bag
  // folder's own name: "my_bag/my_bag_0.db3".
  if (!fs::exists(file, ec) && *relative.begin() == folder.filename()) {
    const fs::path rest = relative.lexically_relative(*relative.begin());
    if (!rest.empty() && rest != "." && fs::exists(folder / rest, ec)) file = folder / rest;
  }
  if (!fs::is_regular_file(file, ec)) {
    return NotFoundError(fmt::format("{}: {} {} in the bag folder ({})", where, QuoteText(text),
                                     fs::exists(file, ec) ? "is not a file" : "does not exist",
                                     FolderListing(folder)));
  }
  return file;
}

/// relative_file_paths: the bag's files in order, as absolute paths.
Status ReadFiles(const fs::path& folder, const YAML::Node& info, std::string_view context,
                 BagFolderMetadata& m) {
  const YAML::Node paths = Get(info, "relative_file_paths");
  if (!Present(paths) || !paths.IsSequence() || paths.size() == 0) {
    return InvalidArgumentError(fmt::format(
        "{}: 'relative_file_paths' is {}: it must list the bag's .db3 or .mcap files ({})", context,
        !Present(paths) ? "missing" : "empty or not a list", FolderListing(folder)));
  }
  fs::path absolute_folder = fs::absolute(folder).lexically_normal();
  if (!absolute_folder.has_filename()) absolute_folder = absolute_folder.parent_path();
  for (size_t i = 0; i < paths.size(); ++i) {
    const std::string where = fmt::format("{}: relative_file_paths[{}]", context, i);
    if (!paths[i].IsScalar()) {
      return InvalidArgumentError(fmt::format("{} must be a file name", where));
    }
    AVP_ASSIGN_OR_RETURN(fs::path file, ResolveFile(absolute_folder, paths[i].Scalar(), where));
    m.files.push_back(std::move(file));
  }
  return Status::Ok();
}

/// The root's rosbag2_bagfile_information map.
Result<YAML::Node> BagfileInformation(const YAML::Node& root, const fs::path& file) {
  if (const YAML::Node info = Get(root, kInfoKey); info.IsDefined() && info.IsMap()) return info;
  std::vector<std::string> keys;
  if (root.IsMap()) {
    for (const auto& kv : root) {
      if (keys.size() == kMaxListedNames) {
        keys.push_back(fmt::format("{} more", root.size() - kMaxListedNames));
        break;
      }
      keys.push_back(QuoteText(kv.first.Scalar()));
    }
  }
  return InvalidArgumentError(fmt::format(
      "'{}': no '{}' map, so not a rosbag2 bag's metadata.yaml ({})", file.string(), kInfoKey,
      keys.empty() ? std::string("it has no top-level keys")
                   : fmt::format("its top-level keys: {}", fmt::join(keys, ", "))));
}

}  // namespace

Result<BagFolderMetadata> ReadBagFolderMetadata(const fs::path& folder) {
  const fs::path file = folder / "metadata.yaml";
  AVP_RETURN_IF_ERROR(CheckMetadataFile(folder, file));
  AVP_ASSIGN_OR_RETURN(const YAML::Node root, io::LoadYamlFile(file));
  AVP_ASSIGN_OR_RETURN(const YAML::Node info, BagfileInformation(root, file));
  const std::string context = fmt::format("'{}': {}", file.string(), kInfoKey);

  BagFolderMetadata m;
  AVP_ASSIGN_OR_RETURN(const int64_t version, io::ReadInt(info, "version", context));
  if (version < 1 || version > 1000) {
    return InvalidArgumentError(
        fmt::format("{}: 'version' is {}: rosbag2 writes 1 to 9 (Humble: 4 or 5, Jazzy: 8 or 9)",
                    context, version));
  }
  m.version = static_cast<int>(version);
  AVP_ASSIGN_OR_RETURN(m.storage_identifier, io::ReadString(info, "storage_identifier", context));
  if (m.storage_identifier != "sqlite3" && m.storage_identifier != "mcap") {
    return InvalidArgumentError(fmt::format(
        "{}: 'storage_identifier' is {}: avp reads rosbag2's sqlite3 (.db3) and mcap (.mcap) "
        "storage",
        context, QuoteText(m.storage_identifier)));
  }
  AVP_RETURN_IF_ERROR(ReadCompression(info, context, m));
  AVP_RETURN_IF_ERROR(ReadTopics(info, context, m));
  AVP_RETURN_IF_ERROR(ReadFiles(folder, info, context, m));
  return m;
}

}  // namespace avp::ros::bag
