#include "avp/ros/mcap/mcap.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <iterator>
#include <memory>
#include <optional>

#include <fmt/format.h>
#include <lz4frame.h>
#include <zstd.h>

#include <avp/core/text.h>
#include <avp/io/file.h>
#include <avp/io/file_kind.h>

#include "records.h"

namespace avp::ros::mcap {
namespace {

// ---- CRC-32
// ---------------------------------------------------------------------------------------

/// Slicing-by-8 tables: table[0] is the byte-wise table, table[k][i] the CRC of byte i followed
/// by k zero bytes (8 bytes per step; several times the byte-wise speed on megabyte images).
constexpr std::array<std::array<uint32_t, 256>, 8> MakeCrcTables() {
  std::array<std::array<uint32_t, 256>, 8> t{};
  for (uint32_t i = 0; i < 256; ++i) {
    uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    t[0][i] = c;
  }
  for (size_t k = 1; k < 8; ++k) {
    for (uint32_t i = 0; i < 256; ++i) t[k][i] = (t[k - 1][i] >> 8) ^ t[0][t[k - 1][i] & 0xFFu];
  }
  return t;
}
constexpr std::array<std::array<uint32_t, 256>, 8> kCrcTables = MakeCrcTables();

// ---- Little-endian building blocks
// ----------------------------------------------------------------

void PutU8(std::vector<uint8_t>& out, uint8_t v) { out.push_back(v); }
template <typename T>
void PutLe(std::vector<uint8_t>& out, T v) {
  for (size_t i = 0; i < sizeof(T); ++i) out.push_back(static_cast<uint8_t>(v >> (8 * i)));
}
void PutU16(std::vector<uint8_t>& out, uint16_t v) { PutLe(out, v); }
void PutU32(std::vector<uint8_t>& out, uint32_t v) { PutLe(out, v); }
void PutU64(std::vector<uint8_t>& out, uint64_t v) { PutLe(out, v); }
void PutBytes(std::vector<uint8_t>& out, std::span<const uint8_t> b) {
  out.insert(out.end(), b.begin(), b.end());
}
void PutString(std::vector<uint8_t>& out, std::string_view s) {
  PutU32(out, static_cast<uint32_t>(s.size()));
  out.insert(out.end(), s.begin(), s.end());
}
/// Appends a record: opcode, uint64 length, content.
void PutRecord(std::vector<uint8_t>& out, Opcode op, const std::vector<uint8_t>& content) {
  PutU8(out, static_cast<uint8_t>(op));
  PutU64(out, content.size());
  PutBytes(out, content);
}

}  // namespace

// ---- Reading records (records.h)
// --------------------------------------------------------------------------------------

namespace internal {

std::string_view OpcodeName(uint8_t op) {
  switch (static_cast<Opcode>(op)) {
    case Opcode::kHeader:
      return "Header";
    case Opcode::kFooter:
      return "Footer";
    case Opcode::kSchema:
      return "Schema";
    case Opcode::kChannel:
      return "Channel";
    case Opcode::kMessage:
      return "Message";
    case Opcode::kChunk:
      return "Chunk";
    case Opcode::kMessageIndex:
      return "Message Index";
    case Opcode::kChunkIndex:
      return "Chunk Index";
    case Opcode::kAttachment:
      return "Attachment";
    case Opcode::kAttachmentIndex:
      return "Attachment Index";
    case Opcode::kStatistics:
      return "Statistics";
    case Opcode::kMetadata:
      return "Metadata";
    case Opcode::kMetadataIndex:
      return "Metadata Index";
    case Opcode::kSummaryOffset:
      return "Summary Offset";
    case Opcode::kDataEnd:
      return "Data End";
  }
  return "unknown";
}

/// The record at `offset` of `bytes` (whose first byte is file offset `base`), or an error.
Result<Record> RecordAt(std::span<const uint8_t> bytes, uint64_t offset, uint64_t base,
                        const std::string& where) {
  const uint64_t rel = offset - base;
  if (rel + 9 > bytes.size()) {
    return ParseError(fmt::format("{}: truncated record header at offset {} ({} of 9 bytes left)",
                                  where, offset, bytes.size() - rel));
  }
  Record r;
  r.op = bytes[rel];
  r.offset = offset;
  uint64_t len = 0;
  for (size_t i = 0; i < 8; ++i) len |= static_cast<uint64_t>(bytes[rel + 1 + i]) << (8 * i);
  if (len > bytes.size() - rel - 9) {
    return ParseError(
        fmt::format("{}: truncated {} record at offset {}: its length is {} bytes, {} are left",
                    where, OpcodeName(r.op), offset, len, bytes.size() - rel - 9));
  }
  r.content = bytes.subspan(rel + 9, len);
  return r;
}

Status Bad(const std::string& where, const Cursor& c) {
  return ParseError(where + ": " + c.error());
}

Result<Schema> ParseSchema(const Record& r, const std::string& where) {
  Cursor c(r.content, r.offset + 9, "Schema");
  Schema s;
  s.id = c.U16("id");
  s.name = c.String("name");
  s.encoding = c.String("encoding");
  s.data = c.String("data");
  if (!c.ok()) return Bad(where, c);
  return s;
}

Result<Channel> ParseChannel(const Record& r, const std::string& where) {
  Cursor c(r.content, r.offset + 9, "Channel");
  Channel ch;
  ch.id = c.U16("id");
  ch.schema_id = c.U16("schema_id");
  ch.topic = c.String("topic");
  ch.message_encoding = c.String("message_encoding");
  const uint32_t map_len = c.U32("metadata");
  Cursor m(c.Take(map_len, "metadata"), c.offset() - map_len, "Channel metadata");
  while (c.ok() && m.ok() && m.left() > 0) {
    std::string key = m.String("key");
    ch.metadata[key] = m.String("value");
  }
  if (!c.ok()) return Bad(where, c);
  if (!m.ok()) return Bad(where, m);
  return ch;
}

Result<Message> ParseMessage(const Record& r, const std::string& where) {
  Cursor c(r.content, r.offset + 9, "Message");
  Message msg;
  msg.channel_id = c.U16("channel_id");
  msg.sequence = c.U32("sequence");
  msg.log_time = c.U64("log_time");
  msg.publish_time = c.U64("publish_time");
  auto data = c.Rest();
  if (!c.ok()) return Bad(where, c);
  msg.data.assign(data.begin(), data.end());
  return msg;
}

/// An Attachment record, its CRC (of every field before it) checked when non-zero.
Result<Attachment> ParseAttachment(const Record& r, const std::string& where) {
  Cursor c(r.content, r.offset + 9, "Attachment");
  Attachment a;
  a.log_time = c.U64("log_time");
  a.create_time = c.U64("create_time");
  a.name = c.String("name");
  a.media_type = c.String("media_type");
  const uint64_t size = c.U64("data_size");
  const auto data = c.Take(size, "data");
  const size_t crc_at = r.content.size() - c.left();
  const uint32_t crc = c.U32("crc");
  if (!c.ok()) return Bad(where, c);
  const uint32_t computed = Crc32(r.content.first(crc_at));
  if (crc != 0 && crc != computed) {
    return ParseError(fmt::format(
        "{}: CRC mismatch in the attachment '{}' at offset {}: stored {:08x}, computed {:08x}",
        where, a.name, r.offset, crc, computed));
  }
  a.data.assign(data.begin(), data.end());
  return a;
}

Result<Metadata> ParseMetadata(const Record& r, const std::string& where) {
  Cursor c(r.content, r.offset + 9, "Metadata");
  Metadata md;
  md.name = c.String("name");
  const uint32_t map_len = c.U32("metadata");
  Cursor m(c.Take(map_len, "metadata"), c.offset() - map_len, "Metadata map");
  while (c.ok() && m.ok() && m.left() > 0) {
    std::string key = m.String("key");
    md.metadata[key] = m.String("value");
  }
  if (!c.ok()) return Bad(where, c);
  if (!m.ok()) return Bad(where, m);
  return md;
}

/// The records of a chunk compressed with `compression` ("zstd" or "lz4", the MCAP spec's names;
/// lz4 is the LZ4 frame format), decompressed into `out`: exactly `size` bytes, or ParseError
/// naming the chunk. The size a chunk claims is checked against max_file_bytes before anything is
/// allocated (a damaged or hostile chunk cannot ask for more memory than a file could hold).
Status Decompress(std::string_view compression, std::span<const uint8_t> in, uint64_t size,
                  const std::string& where, uint64_t offset, std::vector<uint8_t>& out) {
  const std::string chunk = fmt::format("{}: chunk at offset {} ({})", where, offset, compression);
  AVP_RETURN_IF_ERROR(
      io::MaxFileBytes().Check(fmt::format("{}: its uncompressed size", chunk), size));
  out.assign(size, 0);
  if (compression == "zstd") {
    const size_t got = ZSTD_decompress(out.data(), out.size(), in.data(), in.size());
    if (ZSTD_isError(got) != 0) {
      return ParseError(fmt::format("{} does not decompress: {}", chunk, ZSTD_getErrorName(got)));
    }
    if (got != size) {
      return ParseError(
          fmt::format("{}: uncompressed_size {} but {} bytes decompressed", chunk, size, got));
    }
    return Status::Ok();
  }
  if (compression == "lz4") {
    LZ4F_dctx* raw = nullptr;
    if (LZ4F_isError(LZ4F_createDecompressionContext(&raw, LZ4F_VERSION)) != 0) {
      return InternalError(fmt::format("{}: no lz4 decompression context", chunk));
    }
    const std::unique_ptr<LZ4F_dctx, decltype(&LZ4F_freeDecompressionContext)> ctx(
        raw, &LZ4F_freeDecompressionContext);
    size_t read = 0, written = 0, hint = 1;
    while (hint != 0 && read < in.size()) {
      size_t src = in.size() - read;
      size_t dst = out.size() - written;
      hint =
          LZ4F_decompress(ctx.get(), out.data() + written, &dst, in.data() + read, &src, nullptr);
      if (LZ4F_isError(hint) != 0) {
        return ParseError(
            fmt::format("{} does not decompress: {}", chunk, LZ4F_getErrorName(hint)));
      }
      read += src;
      written += dst;
      if (src == 0 && dst == 0) break;  // no progress: the frame wants more than there is
    }
    if (hint != 0 || written != size) {
      return ParseError(fmt::format("{}: uncompressed_size {} but {} bytes decompressed{}", chunk,
                                    size, written,
                                    hint != 0 ? " (the lz4 frame is cut short)" : ""));
    }
    return Status::Ok();
  }
  return ParseError(fmt::format(
      "{}: compression '{}' is not one avp reads (uncompressed, zstd or lz4, as ROS 2 recorders "
      "write; `mcap decompress` turns any other into an uncompressed file)",
      chunk, EscapeText(compression)));
}

/// A chunk's messages (the chunk record `r`), decompressed and its CRC checked. `where` names the
/// file.
Status ReadChunk(const Record& r, const std::string& where, std::vector<Message>& out,
                 std::vector<Schema>* schemas, std::vector<Channel>* channels) {
  Cursor c(r.content, r.offset + 9, "Chunk");
  c.U64("message_start_time");
  c.U64("message_end_time");
  const uint64_t uncompressed_size = c.U64("uncompressed_size");
  const uint32_t crc = c.U32("uncompressed_crc");
  const std::string compression = c.String("compression");
  const uint64_t records_len = c.U64("records");
  const uint64_t records_offset = c.offset();
  auto records = c.Take(records_len, "records");
  if (!c.ok()) return Bad(where, c);
  std::vector<uint8_t> decompressed;
  if (!compression.empty()) {
    AVP_RETURN_IF_ERROR(
        Decompress(compression, records, uncompressed_size, where, r.offset, decompressed));
    records = decompressed;
  }
  if (records.size() != uncompressed_size) {
    return ParseError(
        fmt::format("{}: chunk at offset {}: uncompressed_size {} but {} record bytes", where,
                    r.offset, uncompressed_size, records.size()));
  }
  if (crc != 0 && Crc32(records) != crc) {
    return ParseError(
        fmt::format("{}: CRC mismatch in the chunk at offset {}: stored {:08x}, "
                    "computed {:08x}",
                    where, r.offset, crc, Crc32(records)));
  }
  std::vector<Message> messages;
  uint64_t at = records_offset;
  while (at < records_offset + records.size()) {
    AVP_ASSIGN_OR_RETURN(Record rec, RecordAt(records, at, records_offset, where));
    switch (static_cast<Opcode>(rec.op)) {
      case Opcode::kMessage: {
        AVP_ASSIGN_OR_RETURN(Message m, ParseMessage(rec, where));
        messages.push_back(std::move(m));
        break;
      }
      case Opcode::kSchema:
        if (schemas != nullptr) {
          AVP_ASSIGN_OR_RETURN(Schema s, ParseSchema(rec, where));
          schemas->push_back(std::move(s));
        }
        break;
      case Opcode::kChannel:
        if (channels != nullptr) {
          AVP_ASSIGN_OR_RETURN(Channel ch, ParseChannel(rec, where));
          channels->push_back(std::move(ch));
        }
        break;
      default:
        break;
    }
    at = rec.end();
  }
  out.insert(out.end(), std::make_move_iterator(messages.begin()),
             std::make_move_iterator(messages.end()));
  return Status::Ok();
}

Status ReadHeader(std::span<const uint8_t> bytes, const std::string& where, File& file) {
  if (bytes.size() < kMagic.size() ||
      !std::equal(kMagic.begin(), kMagic.end(), bytes.begin(),
                  [](char a, uint8_t b) { return static_cast<uint8_t>(a) == b; })) {
    const std::string kind = io::DescribeFileKind(
        std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
    return ParseError(fmt::format("{}: not an MCAP file{}: no magic at offset 0", where,
                                  kind.empty() ? "" : " (it is " + kind + ")"));
  }
  AVP_ASSIGN_OR_RETURN(Record r, RecordAt(bytes, 8, 0, where));
  if (r.op != static_cast<uint8_t>(Opcode::kHeader)) {
    return ParseError(fmt::format("{}: expected a Header record at offset 8, found opcode 0x{:02x}",
                                  where, r.op));
  }
  Cursor c(r.content, 17, "Header");
  file.profile = c.String("profile");
  file.library = c.String("library");
  if (!c.ok()) return Bad(where, c);
  return Status::Ok();
}

}  // namespace internal

using namespace internal;  // NOLINT: this file is the implementation

uint32_t Crc32(std::span<const uint8_t> bytes, uint32_t crc) {
  crc = ~crc;
  const uint8_t* p = bytes.data();
  size_t n = bytes.size();
  const auto& t = kCrcTables;
  for (; n >= 8; n -= 8, p += 8) {
    const uint32_t lo =
        crc ^ (uint32_t{p[0]} | uint32_t{p[1]} << 8 | uint32_t{p[2]} << 16 | uint32_t{p[3]} << 24);
    crc = t[7][lo & 0xFFu] ^ t[6][(lo >> 8) & 0xFFu] ^ t[5][(lo >> 16) & 0xFFu] ^ t[4][lo >> 24] ^
          t[3][p[4]] ^ t[2][p[5]] ^ t[1][p[6]] ^ t[0][p[7]];
  }
  for (; n > 0; --n, ++p) crc = t[0][(crc ^ *p) & 0xFFu] ^ (crc >> 8);
  return ~crc;
}

std::string OfferedQosProfiles(bool reliable, bool transient_local, uint32_t depth) {
  constexpr std::string_view kInfinite = "    sec: 2147483647\n    nsec: 4294967295\n";
  return fmt::format(
      "- history: 1\n  depth: {}\n  reliability: {}\n  durability: {}\n  deadline:\n{}"
      "  lifespan:\n{}  liveliness: 1\n  liveliness_lease_duration:\n{}"
      "  avoid_ros_namespace_conventions: false",
      depth, reliable ? 1 : 2, transient_local ? 1 : 2, kInfinite, kInfinite, kInfinite);
}

// ---- Writer
// ---------------------------------------------------------------------------------------

Writer::Writer(std::filesystem::path path, std::FILE* file, WriterOptions options)
    : path_(std::move(path)), file_(file), options_(std::move(options)) {}

Writer::~Writer() {
  if (!closed_) (void)Close();
}

Result<std::unique_ptr<Writer>> Writer::Open(const std::filesystem::path& path,
                                             WriterOptions options) {
  if (!options.compression.empty() && options.compression != "zstd" &&
      options.compression != "lz4") {
    return InvalidArgumentError(
        fmt::format("MCAP chunk compression {} is not one avp writes (none, zstd or lz4)",
                    QuoteText(options.compression)));
  }
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) {
    return IoError(fmt::format("{}: cannot create: {}", path.string(), std::strerror(errno)));
  }
  std::unique_ptr<Writer> w(new Writer(path, f, std::move(options)));
  std::vector<uint8_t> out(kMagic.begin(), kMagic.end());
  std::vector<uint8_t> header;
  PutString(header, w->options_.profile);
  PutString(header, w->options_.library);
  PutRecord(out, Opcode::kHeader, header);
  AVP_RETURN_IF_ERROR(w->WriteRaw(out));
  return w;
}

Status Writer::Fail(std::string what) {
  return IoError(fmt::format("{}: {}", path_.string(), what));
}

Status Writer::WriteRaw(std::span<const uint8_t> bytes) {
  if (file_ == nullptr) return Fail("write after Close()");
  if (std::fwrite(bytes.data(), 1, bytes.size(), file_) != bytes.size()) {
    return Fail(fmt::format("write failed at offset {}: {}", offset_, std::strerror(errno)));
  }
  data_crc_ = Crc32(bytes, data_crc_);
  offset_ += bytes.size();
  return Status::Ok();
}

Result<uint16_t> Writer::AddSchema(std::string_view name, std::string_view encoding,
                                   std::string_view data) {
  if (closed_) return Fail("AddSchema after Close()");
  if (schemas_.size() >= 0xFFFE) return Fail("too many schemas (65534 at most)");
  Schema s{static_cast<uint16_t>(schemas_.size() + 1), std::string(name), std::string(encoding),
           std::string(data)};
  std::vector<uint8_t> content, out;
  PutU16(content, s.id);
  PutString(content, s.name);
  PutString(content, s.encoding);
  PutString(content, s.data);
  PutRecord(out, Opcode::kSchema, content);
  AVP_RETURN_IF_ERROR(WriteRaw(out));
  schemas_.push_back(std::move(s));
  stats_.schema_count = static_cast<uint16_t>(schemas_.size());
  return schemas_.back().id;
}

Result<uint16_t> Writer::AddChannel(uint16_t schema_id, std::string_view topic,
                                    std::string_view message_encoding,
                                    std::map<std::string, std::string> metadata) {
  if (closed_) return Fail("AddChannel after Close()");
  if (schema_id > schemas_.size()) {
    return InvalidArgumentError(fmt::format("{}: channel '{}': no schema with id {} ({} added)",
                                            path_.string(), topic, schema_id, schemas_.size()));
  }
  if (channels_.size() >= 0xFFFF) return Fail("too many channels (65535 at most)");
  Channel ch{static_cast<uint16_t>(channels_.size()), schema_id, std::string(topic),
             std::string(message_encoding), std::move(metadata)};
  std::vector<uint8_t> content, map, out;
  PutU16(content, ch.id);
  PutU16(content, ch.schema_id);
  PutString(content, ch.topic);
  PutString(content, ch.message_encoding);
  for (const auto& [k, v] : ch.metadata) {
    PutString(map, k);
    PutString(map, v);
  }
  PutU32(content, static_cast<uint32_t>(map.size()));
  PutBytes(content, map);
  PutRecord(out, Opcode::kChannel, content);
  AVP_RETURN_IF_ERROR(WriteRaw(out));
  channels_.push_back(std::move(ch));
  stats_.channel_count = static_cast<uint32_t>(channels_.size());
  return channels_.back().id;
}

Status Writer::WriteAttachment(const Attachment& a) {
  if (closed_) return Fail("WriteAttachment after Close()");
  const uint64_t at = offset_;
  std::vector<uint8_t> content, out;
  PutU64(content, a.log_time);
  PutU64(content, a.create_time);
  PutString(content, a.name);
  PutString(content, a.media_type);
  PutU64(content, a.data.size());
  content.insert(content.end(), a.data.begin(), a.data.end());
  PutU32(content, Crc32(content));
  PutRecord(out, Opcode::kAttachment, content);
  AVP_RETURN_IF_ERROR(WriteRaw(out));
  std::vector<uint8_t> index;
  PutU64(index, at);
  PutU64(index, out.size());
  PutU64(index, a.log_time);
  PutU64(index, a.create_time);
  PutU64(index, a.data.size());
  PutString(index, a.name);
  PutString(index, a.media_type);
  PutRecord(attachment_index_, Opcode::kAttachmentIndex, index);
  ++stats_.attachment_count;
  return Status::Ok();
}

Status Writer::WriteMetadata(const Metadata& md) {
  if (closed_) return Fail("WriteMetadata after Close()");
  const uint64_t at = offset_;
  std::vector<uint8_t> content, map, out;
  PutString(content, md.name);
  for (const auto& [k, v] : md.metadata) {
    PutString(map, k);
    PutString(map, v);
  }
  PutU32(content, static_cast<uint32_t>(map.size()));
  PutBytes(content, map);
  PutRecord(out, Opcode::kMetadata, content);
  AVP_RETURN_IF_ERROR(WriteRaw(out));
  std::vector<uint8_t> index;
  PutU64(index, at);
  PutU64(index, out.size());
  PutString(index, md.name);
  PutRecord(metadata_index_, Opcode::kMetadataIndex, index);
  ++stats_.metadata_count;
  return Status::Ok();
}

Status Writer::Write(const Message& m) {
  return Write(m.channel_id, m.sequence, m.log_time, m.publish_time, m.data);
}

Status Writer::Write(uint16_t channel_id, uint32_t sequence, uint64_t log_time,
                     uint64_t publish_time, std::span<const uint8_t> data) {
  if (closed_) return Fail("Write after Close()");
  if (channel_id >= channels_.size()) {
    return InvalidArgumentError(fmt::format("{}: message on channel {}, but {} channels were added",
                                            path_.string(), channel_id, channels_.size()));
  }
  if (chunk_index_.empty()) {
    chunk_start_ = log_time;
    chunk_end_ = log_time;
  }
  chunk_start_ = std::min(chunk_start_, log_time);
  chunk_end_ = std::max(chunk_end_, log_time);
  chunk_index_[channel_id].emplace_back(log_time, chunk_.size());
  PutU8(chunk_, static_cast<uint8_t>(Opcode::kMessage));
  PutU64(chunk_, 2 + 4 + 8 + 8 + data.size());
  PutU16(chunk_, channel_id);
  PutU32(chunk_, sequence);
  PutU64(chunk_, log_time);
  PutU64(chunk_, publish_time);
  PutBytes(chunk_, data);

  if (stats_.message_count == 0) {
    stats_.message_start_time = log_time;
    stats_.message_end_time = log_time;
  }
  stats_.message_start_time = std::min(stats_.message_start_time, log_time);
  stats_.message_end_time = std::max(stats_.message_end_time, log_time);
  ++stats_.message_count;
  ++stats_.channel_message_counts[channel_id];
  if (chunk_.size() >= options_.chunk_size) return WriteChunk();
  return Status::Ok();
}

namespace {

/// A chunk's records as stored with `compression` ("" leaves them as they are).
Result<std::vector<uint8_t>> Compress(const std::string& compression,
                                      const std::vector<uint8_t>& records) {
  if (compression.empty()) return records;
  std::vector<uint8_t> out;
  if (compression == "zstd") {
    out.resize(ZSTD_compressBound(records.size()));
    const size_t n = ZSTD_compress(out.data(), out.size(), records.data(), records.size(), 3);
    if (ZSTD_isError(n) != 0) {
      return InternalError(fmt::format("zstd compression failed: {}", ZSTD_getErrorName(n)));
    }
    out.resize(n);
    return out;
  }
  out.resize(LZ4F_compressFrameBound(records.size(), nullptr));
  const size_t n =
      LZ4F_compressFrame(out.data(), out.size(), records.data(), records.size(), nullptr);
  if (LZ4F_isError(n) != 0) {
    return InternalError(fmt::format("lz4 compression failed: {}", LZ4F_getErrorName(n)));
  }
  out.resize(n);
  return out;
}

}  // namespace

Status Writer::WriteChunk() {
  if (chunk_index_.empty()) return Status::Ok();
  const uint64_t chunk_offset = offset_;
  std::vector<uint8_t> out;
  PutU8(out, static_cast<uint8_t>(Opcode::kChunk));
  AVP_ASSIGN_OR_RETURN(const std::vector<uint8_t> stored, Compress(options_.compression, chunk_));
  PutU64(out, 8 + 8 + 8 + 4 + 4 + options_.compression.size() + 8 + stored.size());
  PutU64(out, chunk_start_);
  PutU64(out, chunk_end_);
  PutU64(out, chunk_.size());
  PutU32(out, Crc32(chunk_));
  PutString(out, options_.compression);
  PutU64(out, stored.size());
  PutBytes(out, stored);
  const uint64_t chunk_length = out.size();
  std::map<uint16_t, uint64_t> index_offsets;
  for (auto& [channel, entries] : chunk_index_) {
    std::stable_sort(entries.begin(), entries.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    index_offsets[channel] = chunk_offset + out.size();
    std::vector<uint8_t> content;
    PutU16(content, channel);
    PutU32(content, static_cast<uint32_t>(entries.size() * 16));
    for (const auto& [time, offset] : entries) {
      PutU64(content, time);
      PutU64(content, offset);
    }
    PutRecord(out, Opcode::kMessageIndex, content);
  }
  const uint64_t index_length = out.size() - chunk_length;
  AVP_RETURN_IF_ERROR(WriteRaw(out));

  std::vector<uint8_t> ci;
  PutU64(ci, chunk_start_);
  PutU64(ci, chunk_end_);
  PutU64(ci, chunk_offset);
  PutU64(ci, chunk_length);
  PutU32(ci, static_cast<uint32_t>(index_offsets.size() * 10));
  for (const auto& [channel, offset] : index_offsets) {
    PutU16(ci, channel);
    PutU64(ci, offset);
  }
  PutU64(ci, index_length);
  PutString(ci, options_.compression);
  PutU64(ci, stored.size());  // compressed_size: the records as stored
  PutU64(ci, chunk_.size());
  PutRecord(chunk_indexes_, Opcode::kChunkIndex, ci);
  ++stats_.chunk_count;
  chunk_.clear();
  chunk_index_.clear();
  if (std::fflush(file_) != 0) return Fail(fmt::format("flush failed: {}", std::strerror(errno)));
  return Status::Ok();
}

Status Writer::Flush() {
  if (closed_) return Fail("Flush after Close()");
  AVP_RETURN_IF_ERROR(WriteChunk());
  if (std::fflush(file_) != 0) return Fail(fmt::format("flush failed: {}", std::strerror(errno)));
  return Status::Ok();
}

Status Writer::Close() {
  if (closed_) return Status::Ok();
  closed_ = true;
  Status status = WriteChunk();
  if (status.ok()) {
    std::vector<uint8_t> data_end;
    std::vector<uint8_t> content;
    PutU32(content, data_crc_);
    PutRecord(data_end, Opcode::kDataEnd, content);
    status = WriteRaw(data_end);
  }
  if (status.ok()) {
    // The summary: groups of Schema, Channel, Statistics, Chunk Index, Attachment Index and
    // Metadata Index records.
    const uint64_t summary_start = offset_;
    std::vector<uint8_t> summary, offsets;
    auto group = [&](Opcode op, const std::vector<uint8_t>& records) {
      if (records.empty()) return;
      std::vector<uint8_t> so;
      PutU8(so, static_cast<uint8_t>(op));
      PutU64(so, summary_start + summary.size());
      PutU64(so, records.size());
      PutRecord(offsets, Opcode::kSummaryOffset, so);
      PutBytes(summary, records);
    };
    std::vector<uint8_t> schemas, channels, stats;
    for (const Schema& s : schemas_) {
      std::vector<uint8_t> c;
      PutU16(c, s.id);
      PutString(c, s.name);
      PutString(c, s.encoding);
      PutString(c, s.data);
      PutRecord(schemas, Opcode::kSchema, c);
    }
    for (const Channel& ch : channels_) {
      std::vector<uint8_t> c, map;
      PutU16(c, ch.id);
      PutU16(c, ch.schema_id);
      PutString(c, ch.topic);
      PutString(c, ch.message_encoding);
      for (const auto& [k, v] : ch.metadata) {
        PutString(map, k);
        PutString(map, v);
      }
      PutU32(c, static_cast<uint32_t>(map.size()));
      PutBytes(c, map);
      PutRecord(channels, Opcode::kChannel, c);
    }
    {
      std::vector<uint8_t> c;
      PutU64(c, stats_.message_count);
      PutU16(c, stats_.schema_count);
      PutU32(c, stats_.channel_count);
      PutU32(c, stats_.attachment_count);
      PutU32(c, stats_.metadata_count);
      PutU32(c, stats_.chunk_count);
      PutU64(c, stats_.message_start_time);
      PutU64(c, stats_.message_end_time);
      PutU32(c, static_cast<uint32_t>(stats_.channel_message_counts.size() * 10));
      for (const auto& [channel, count] : stats_.channel_message_counts) {
        PutU16(c, channel);
        PutU64(c, count);
      }
      PutRecord(stats, Opcode::kStatistics, c);
    }
    group(Opcode::kSchema, schemas);
    group(Opcode::kChannel, channels);
    group(Opcode::kStatistics, stats);
    group(Opcode::kChunkIndex, chunk_indexes_);
    group(Opcode::kAttachmentIndex, attachment_index_);
    group(Opcode::kMetadataIndex, metadata_index_);
    const uint64_t summary_offset_start = summary_start + summary.size();
    std::vector<uint8_t> tail = summary;
    PutBytes(tail, offsets);
    PutU8(tail, static_cast<uint8_t>(Opcode::kFooter));
    PutU64(tail, 8 + 8 + 4);
    PutU64(tail, summary_start);
    PutU64(tail, summary_offset_start);
    PutU32(tail, Crc32(tail));  // from the summary's start through summary_offset_start
    tail.insert(tail.end(), kMagic.begin(), kMagic.end());
    status = WriteRaw(tail);
  }
  if (file_ != nullptr) {
    if (std::fclose(file_) != 0 && status.ok()) {
      status = Fail(fmt::format("close failed: {}", std::strerror(errno)));
    }
    file_ = nullptr;
  }
  return status;
}

}  // namespace avp::ros::mcap
