#pragma once

// MCAP files (https://mcap.dev/spec), written and read by avp itself: the container that Foxglove,
// Lichtblick, Rerun's viewer and `ros2 bag info/play` (rosbag2_storage_mcap) open. avp writes the
// `ros2` profile: `ros2msg` schemas (the .msg text with its dependencies), `cdr` payloads and the
// `offered_qos_profiles` channel metadata rosbag2 stores. Docs: docs/recording.md.
//
// Writer: messages go into uncompressed chunks (a chunk is written once it holds chunk_size bytes,
// each followed by its Message Index records), so a long run writes step by step and a crash loses
// at most the open chunk. Attachments (files, e.g. ground_truth.json) and Metadata records (named
// string maps) go into the data section between the chunks. Close() writes Data End (the data
// section's CRC-32), the summary (Schema, Channel, Statistics, Chunk Index, Attachment Index and
// Metadata Index records, each group found through a Summary Offset record), the Footer (the
// summary's CRC-32) and the closing magic.
//
// Reading (StreamReader) is from disk, one record and one chunk at a time, so a file of any size is
// read in bounded memory: indexed (Footer -> summary -> Chunk Indexes: the chunks read in log-time
// order, overlapping chunks merged) or, for a file without a usable summary (truncated, not
// closed, written unindexed), in one streaming pass in file order. Both check every CRC they
// pass. A truncated or corrupt file is an error naming the file and the byte offset, after the
// messages of the intact chunks before it. ReadIndexed and ReadStreaming read a whole file into a
// File (tests, small files).

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>

namespace avp::ros::mcap {

/// The 8 bytes that open and close every MCAP file: 0x89 "MCAP0\r\n".
inline constexpr std::string_view kMagic{"\x89MCAP0\r\n", 8};

/// Record opcodes (spec: "Records").
enum class Opcode : uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kAttachment = 0x09,
  kAttachmentIndex = 0x0A,
  kStatistics = 0x0B,
  kMetadata = 0x0C,
  kMetadataIndex = 0x0D,
  kSummaryOffset = 0x0E,
  kDataEnd = 0x0F,
};

/// CRC-32 (IEEE 802.3, the zlib / MCAP one); `crc` continues an earlier value.
uint32_t Crc32(std::span<const uint8_t> bytes, uint32_t crc = 0);

struct Schema {
  uint16_t id = 0;       ///< > 0
  std::string name;      ///< "sensor_msgs/msg/Image"
  std::string encoding;  ///< "ros2msg"
  std::string data;      ///< the schema text
  friend bool operator==(const Schema&, const Schema&) = default;
};

struct Channel {
  uint16_t id = 0;
  uint16_t schema_id = 0;
  std::string topic;
  std::string message_encoding;  ///< "cdr"
  std::map<std::string, std::string> metadata;
  friend bool operator==(const Channel&, const Channel&) = default;
};

struct Message {
  uint16_t channel_id = 0;
  uint32_t sequence = 0;
  uint64_t log_time = 0;      ///< ns since the epoch
  uint64_t publish_time = 0;  ///< ns since the epoch
  std::vector<uint8_t> data;
  friend bool operator==(const Message&, const Message&) = default;
};

/// An Attachment record: a file stored beside the messages (e.g. ground_truth.json), outside the
/// chunks, with its own CRC-32 (of every field before it).
struct Attachment {
  uint64_t log_time = 0;     ///< ns since the epoch
  uint64_t create_time = 0;  ///< ns since the epoch
  std::string name;          ///< "ground_truth.json"
  std::string media_type;    ///< "application/json"
  std::string data;          ///< the bytes
  friend bool operator==(const Attachment&, const Attachment&) = default;
};

/// A Metadata record: a named string -> string map (e.g. "avp": command, revision, scene, ...).
struct Metadata {
  std::string name;
  std::map<std::string, std::string> metadata;
  friend bool operator==(const Metadata&, const Metadata&) = default;
};

struct Statistics {
  uint64_t message_count = 0;
  uint16_t schema_count = 0;
  uint32_t channel_count = 0;
  uint32_t attachment_count = 0;
  uint32_t metadata_count = 0;
  uint32_t chunk_count = 0;
  uint64_t message_start_time = 0;
  uint64_t message_end_time = 0;
  std::map<uint16_t, uint64_t> channel_message_counts;
  friend bool operator==(const Statistics&, const Statistics&) = default;
};

/// The `offered_qos_profiles` channel metadata as rosbag2 (Humble's integer enums, which Jazzy
/// also reads) writes it: one profile, keep-last `depth`, reliable or best effort, volatile or
/// transient local (a latched topic such as /tf_static), infinite deadline / lifespan / lease.
std::string OfferedQosProfiles(bool reliable = true, bool transient_local = false,
                               uint32_t depth = 10);

struct WriterOptions {
  std::string profile = "ros2";
  std::string library = "avp";
  /// A chunk is written once its records hold this many bytes (and on Close / Flush).
  uint64_t chunk_size = 4u << 20;
  /// How chunks are stored: "" (uncompressed), "zstd" (level 3) or "lz4" (the LZ4 frame format),
  /// the MCAP spec's names; Open refuses any other.
  std::string compression = "";
};

class Writer {
 public:
  /// Creates (truncates) `path` and writes the magic and the Header record.
  static Result<std::unique_ptr<Writer>> Open(const std::filesystem::path& path,
                                              WriterOptions options = {});
  ~Writer();  ///< Closes if Close() was not called (errors are then lost: call Close()).
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  /// Adds a schema (written to the file at once); returns its id (1, 2, ...).
  Result<uint16_t> AddSchema(std::string_view name, std::string_view encoding,
                             std::string_view data);
  /// Adds a channel on a schema returned by AddSchema (0: no schema); returns its id (0, 1, ...).
  Result<uint16_t> AddChannel(uint16_t schema_id, std::string_view topic,
                              std::string_view message_encoding,
                              std::map<std::string, std::string> metadata = {});
  /// Writes an Attachment record (in the data section, outside the chunks; indexed in the
  /// summary by an Attachment Index record).
  Status WriteAttachment(const Attachment& attachment);
  /// Writes a Metadata record (indexed in the summary by a Metadata Index record).
  Status WriteMetadata(const Metadata& metadata);
  /// Appends a message to the open chunk; writes the chunk when it is full.
  Status Write(const Message& message);
  Status Write(uint16_t channel_id, uint32_t sequence, uint64_t log_time, uint64_t publish_time,
               std::span<const uint8_t> data);
  /// Writes the open chunk (if any) and flushes the file.
  Status Flush();
  /// Writes the open chunk, Data End, the summary, the Footer and the magic; closes the file.
  Status Close();

  const std::filesystem::path& path() const { return path_; }
  const Statistics& statistics() const { return stats_; }

 private:
  Writer(std::filesystem::path path, std::FILE* file, WriterOptions options);
  Status WriteRaw(std::span<const uint8_t> bytes);  // to the file, counting the data CRC
  Status WriteChunk();
  Status Fail(std::string what);

  std::filesystem::path path_;
  std::FILE* file_ = nullptr;
  WriterOptions options_;
  uint64_t offset_ = 0;
  uint32_t data_crc_ = 0;
  bool closed_ = false;
  std::vector<Schema> schemas_;
  std::vector<Channel> channels_;
  Statistics stats_;
  // The open chunk.
  std::vector<uint8_t> chunk_;
  uint64_t chunk_start_ = 0, chunk_end_ = 0;
  std::map<uint16_t, std::vector<std::pair<uint64_t, uint64_t>>> chunk_index_;  // log time, offset
  std::vector<uint8_t> chunk_indexes_;     // Chunk Index records for the summary
  std::vector<uint8_t> attachment_index_;  // Attachment Index records for the summary
  std::vector<uint8_t> metadata_index_;    // Metadata Index records for the summary
};

/// What a reader found.
struct File {
  std::string profile;
  std::string library;
  std::vector<Schema> schemas;
  std::vector<Channel> channels;
  std::vector<Message> messages;        ///< file order (streaming) or log-time order (indexed)
  std::vector<Attachment> attachments;  ///< file order (indexed: through the Attachment Indexes)
  std::vector<Metadata> metadata;       ///< file order (indexed: through the Metadata Indexes)
  Statistics statistics;                ///< from the summary (indexed); counted (streaming)
  uint32_t chunk_count = 0;             ///< chunks read
};

/// An MCAP file's messages one at a time, in bounded memory (at most one record, or the chunks
/// whose log times overlap, decoded at once).
class StreamReader {
 public:
  enum class Mode {
    kAuto,       ///< indexed when the summary reads, else a streaming pass
    kIndexed,    ///< indexed, else the summary's error
    kStreaming,  ///< a streaming pass in file order, even when the file has a summary
  };
  /// Opens `path` and reads its Header; indexed: the summary, attachments and metadata;
  /// streaming: the records outside chunks wherever they are (schemas, channels, metadata,
  /// attachments: a scan of the record headers that seeks over the chunks) and the first chunk.
  /// Errors: the file cannot be opened, is not MCAP (saying what it is), or (kIndexed) its
  /// summary does not read.
  static Result<std::unique_ptr<StreamReader>> Open(const std::filesystem::path& path,
                                                    Mode mode = Mode::kAuto);
  ~StreamReader();
  StreamReader(const StreamReader&) = delete;
  StreamReader& operator=(const StreamReader&) = delete;

  /// The next message: indexed, in log-time order (ties: file order); streaming, in file order
  /// (each chunk's messages by log time). nullopt at the end. An error names the file and the
  /// byte offset of the damage; every message before it was returned; after it, Next returns it
  /// again.
  Result<std::optional<Message>> Next();

  bool indexed() const;
  /// Profile, library, schemas, channels, attachments, metadata, statistics (indexed: the
  /// summary's; streaming: what has been read so far) and chunks read; `messages` is empty.
  const File& info() const;
  /// kAuto: why the file is read streaming ("" when indexed).
  const std::string& fallback_reason() const;
  /// The chunks' compressions seen: "uncompressed", "zstd", "lz4", comma-separated.
  const std::string& chunk_compression() const;
  uint64_t bytes_read() const;
  uint64_t file_bytes() const;
  /// The file's size, or where the damage begins.
  uint64_t intact_bytes() const;
  const std::filesystem::path& path() const;

  struct Impl;

 private:
  explicit StreamReader(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// Reads through the Footer, the summary and its chunk, attachment and metadata indexes, checking
/// the summary's, each chunk's and each attachment's CRC. Errors name the file and the byte offset.
Result<File> ReadIndexed(const std::filesystem::path& path);

/// What ReadStreaming returns: the records before any damage, and the damage (OK when none).
struct StreamResult {
  File file;
  Status status;              ///< OK, or what is wrong and where (file and byte offset)
  uint64_t intact_bytes = 0;  ///< bytes read before the damage (the whole file when OK)
};

/// Reads record by record from the start, checking each chunk's and attachment's CRC and the data
/// section's CRC. Messages of a chunk are returned only when the whole chunk is intact.
StreamResult ReadStreaming(const std::filesystem::path& path);

}  // namespace avp::ros::mcap
