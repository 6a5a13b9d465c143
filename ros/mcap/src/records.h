#pragma once

// The records of an MCAP file, read: shared by mcap.cpp (the parsing of each record) and
// reader.cpp (StreamReader, ReadIndexed, ReadStreaming). Internal to avp::ros_mcap.

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <fmt/format.h>

#include <avp/core/status.h>
#include <avp/ros/mcap/mcap.h>

namespace avp::ros::mcap::internal {

/// Reads fields of one record's content; `base` is the content's offset in the file (for errors).
class Cursor {
 public:
  Cursor(std::span<const uint8_t> bytes, uint64_t base, std::string_view what)
      : bytes_(bytes), base_(base), what_(what) {}
  bool ok() const { return error_.empty(); }
  const std::string& error() const { return error_; }
  uint64_t offset() const { return base_ + pos_; }
  size_t left() const { return bytes_.size() - pos_; }

  template <typename T>
  T Le(std::string_view field) {
    if (!Need(sizeof(T), field)) return 0;
    T v = 0;
    for (size_t i = 0; i < sizeof(T); ++i)
      v |= static_cast<T>(static_cast<T>(bytes_[pos_ + i]) << (8 * i));
    pos_ += sizeof(T);
    return v;
  }
  uint8_t U8(std::string_view f) { return Le<uint8_t>(f); }
  uint16_t U16(std::string_view f) { return Le<uint16_t>(f); }
  uint32_t U32(std::string_view f) { return Le<uint32_t>(f); }
  uint64_t U64(std::string_view f) { return Le<uint64_t>(f); }
  std::span<const uint8_t> Take(uint64_t n, std::string_view field) {
    if (!Need(n, field)) return {};
    auto s = bytes_.subspan(pos_, static_cast<size_t>(n));
    pos_ += static_cast<size_t>(n);
    return s;
  }
  std::string String(std::string_view field) {
    const uint32_t n = U32(field);
    auto s = Take(n, field);
    return {s.begin(), s.end()};
  }
  std::span<const uint8_t> Rest() { return Take(left(), "data"); }

 private:
  bool Need(uint64_t n, std::string_view field) {
    if (!error_.empty()) return false;
    if (n > left()) {
      error_ = fmt::format("{} field '{}' at offset {} needs {} bytes, the record has {} left",
                           what_, field, offset(), n, left());
      return false;
    }
    return true;
  }
  std::span<const uint8_t> bytes_;
  uint64_t base_;
  size_t pos_ = 0;
  std::string_view what_;
  std::string error_;
};

/// One record: its opcode, the file offset of the opcode, and its content (the bytes after the
/// 9-byte opcode + length).
struct Record {
  uint8_t op = 0;
  uint64_t offset = 0;
  std::span<const uint8_t> content;
  uint64_t end() const { return offset + 9 + content.size(); }
};

/// "Chunk", "Message", ... ("unknown" for any other opcode).
std::string_view OpcodeName(uint8_t op);
/// The record at `offset` of `bytes` (whose first byte is file offset `base`), or ParseError
/// naming `where` and the offset when the header or the content is cut short.
Result<Record> RecordAt(std::span<const uint8_t> bytes, uint64_t offset, uint64_t base,
                        const std::string& where);
/// ParseError "`where`: `c.error()`".
Status Bad(const std::string& where, const Cursor& c);

Result<Schema> ParseSchema(const Record& r, const std::string& where);
Result<Channel> ParseChannel(const Record& r, const std::string& where);
Result<Message> ParseMessage(const Record& r, const std::string& where);
/// Its CRC checked when non-zero.
Result<Attachment> ParseAttachment(const Record& r, const std::string& where);
Result<Metadata> ParseMetadata(const Record& r, const std::string& where);

/// A chunk's records decompressed ("zstd", "lz4") into `out`: exactly `size` bytes (checked
/// against max_file_bytes before anything is allocated), or ParseError naming the chunk.
Status Decompress(std::string_view compression, std::span<const uint8_t> in, uint64_t size,
                  const std::string& where, uint64_t offset, std::vector<uint8_t>& out);
/// A Chunk record's messages appended to `out` in the chunk's order, decompressed and its CRC
/// checked; its Schema and Channel records into `schemas` / `channels` when given.
Status ReadChunk(const Record& r, const std::string& where, std::vector<Message>& out,
                 std::vector<Schema>* schemas, std::vector<Channel>* channels);
/// The magic and the Header record at the start of `bytes` (profile, library into `file`);
/// ParseError saying what the file is when it is not MCAP.
Status ReadHeader(std::span<const uint8_t> bytes, const std::string& where, File& file);

}  // namespace avp::ros::mcap::internal
