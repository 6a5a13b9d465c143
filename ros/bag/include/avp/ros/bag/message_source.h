#pragma once

// A bag's messages, one at a time in log-time order, in bounded memory: the one way `avp replay`
// reads every bag a ROS 2 robot writes (docs/recording.md "Replaying a real robot's bag"):
//  - an MCAP file: uncompressed, zstd or lz4 chunks, indexed (its chunks read through the Chunk
//    Indexes in log-time order) or not (a streaming pass in file order, each chunk's messages by
//    log time);
//  - a rosbag2 SQLite 3 file (.db3, Humble's default storage);
//  - a rosbag2 bag folder: metadata.yaml naming one or several .mcap or .db3 files (a split bag),
//    merged in log-time order.
// Nothing holds more than the open chunk (MCAP) or the current row (SQLite) of each file.

#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>

namespace avp::ros::bag {

/// One message of a bag.
struct BagMessage {
  std::string topic;  ///< "/camera/camera/color/image_raw"
  std::string type;   ///< "sensor_msgs/msg/Image" (MCAP: the schema name; SQLite: topics.type)
  std::string encoding = "cdr";  ///< MCAP: the channel's message_encoding; SQLite: "cdr"
  uint64_t log_time = 0;         ///< ns since the epoch (MCAP log_time; SQLite timestamp)
  std::vector<uint8_t> data;     ///< the serialized message (CDR for a ROS 2 bag)
};

/// A named record besides the messages: an MCAP Attachment (avp recordings: ground_truth.json).
struct BagAttachment {
  std::string name;
  std::string media_type;
  std::string data;
};

/// What is known of a bag when it is opened, before its first message.
struct BagInfo {
  /// What was opened, for messages: "MCAP (indexed, zstd chunks)", "MCAP (streaming)",
  /// "rosbag2 SQLite 3", "rosbag2 folder: 3 MCAP files".
  std::string format;
  /// The files read, in order.
  std::vector<std::filesystem::path> files;
  /// Their total size, bytes.
  uint64_t file_bytes = 0;
  /// MCAP Metadata records by name (avp recordings: "avp"); empty for SQLite bags.
  std::map<std::string, std::map<std::string, std::string>> metadata;
  /// MCAP Attachments (an indexed file: through its Attachment Indexes; a streaming pass: those
  /// before the first message, where avp's recorder writes them).
  std::vector<BagAttachment> attachments;
  /// Topic -> type, as far as known when opened (an index, a summary, SQLite's topics table,
  /// metadata.yaml; a streaming MCAP pass: the channels before the first message). Messages of
  /// topics not listed here may still come.
  std::map<std::string, std::string> topic_types;
  /// Topic -> message count when the bag says (an MCAP summary, SQLite, metadata.yaml).
  std::map<std::string, uint64_t> topic_counts;
};

/// A bag's messages in log-time order.
class MessageSource {
 public:
  virtual ~MessageSource() = default;
  virtual const BagInfo& info() const = 0;
  /// The next message (ties in log time: file order); nullopt at the end. An error when the rest
  /// of the bag cannot be read (a truncated or corrupt file: the error names the file and the
  /// byte offset or row where it stops); every message before it was delivered intact. After an
  /// error or the end, Next keeps returning the same.
  virtual Result<std::optional<BagMessage>> Next() = 0;
  /// Bytes of the bag's files read so far (progress; the intact part when damaged).
  virtual uint64_t bytes_read() const = 0;
};

/// An MCAP file (ros::mcap::StreamReader).
Result<std::unique_ptr<MessageSource>> OpenMcapSource(const std::filesystem::path& file);

/// A rosbag2 SQLite 3 file (.db3): its `topics` and `messages` tables, messages by timestamp
/// (then id). Errors name the file: not SQLite, no rosbag2 tables, a message on an unknown
/// topic id. Every schema rosbag2 wrote (Dashing to Jazzy) reads; encoding is the topic's
/// serialization_format. A damaged or truncated file: the messages before the damage, then an
/// error naming the last good row.
Result<std::unique_ptr<MessageSource>> OpenSqliteSource(const std::filesystem::path& file);

/// OpenSqliteSource for a bag recorded with per-message compression (metadata.yaml's
/// compression_mode MESSAGE): `message_compression` is its compression_format, "" (none) or
/// "zstd" (each row's data one zstd frame, decompressed to at most 1 GiB; a frame that does not
/// record its size is refused). InvalidArgument for any other.
Result<std::unique_ptr<MessageSource>> OpenSqliteSource(const std::filesystem::path& file,
                                                        std::string_view message_compression);

/// A rosbag2 bag folder's metadata.yaml (rosbag2_bagfile_information): the storage and its files.
struct BagFolderMetadata {
  int version = 0;
  std::string storage_identifier;            ///< "sqlite3" or "mcap"
  std::vector<std::filesystem::path> files;  ///< absolute: the folder / relative_file_paths
  std::map<std::string, std::string> topic_types;
  std::map<std::string, uint64_t> topic_counts;
  std::string compression_format;  ///< "" or "zstd"
  std::string compression_mode;    ///< "", "FILE" or "MESSAGE"
};

/// Reads `folder`/metadata.yaml. Errors name the file and the key: not YAML, no
/// rosbag2_bagfile_information, an unknown storage, a file it names that does not exist, a path
/// that is absolute or leaves the folder (".."), compression_mode FILE (the files compressed
/// whole: refused, saying how to decompress them; so compression_mode is "" or "MESSAGE" here).
Result<BagFolderMetadata> ReadBagFolderMetadata(const std::filesystem::path& folder);

/// Merges sources in log-time order (ties: the earlier source first): a split bag's files.
std::unique_ptr<MessageSource> MergeSources(std::vector<std::unique_ptr<MessageSource>> sources,
                                            std::string format);

/// Opens a bag: an MCAP file, a .db3 file, or a bag folder (metadata.yaml; a folder without one:
/// its .mcap or .db3 files in name order). Errors name the path and say what it is when it is
/// none of these.
Result<std::unique_ptr<MessageSource>> OpenBag(const std::filesystem::path& path);

}  // namespace avp::ros::bag
