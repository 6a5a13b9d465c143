// Reading MCAP files from disk in bounded memory: StreamReader (one record, one chunk at a time),
// and ReadIndexed / ReadStreaming on top of it (docs/recording.md).
#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <deque>
#include <limits>
#include <memory>
#include <optional>
#include <utility>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/io/file.h>
#include <avp/ros/mcap/mcap.h>

#include "records.h"

namespace avp::ros::mcap {

using namespace internal;  // NOLINT: the records this reader reads

namespace {

constexpr uint64_t kRecordHeader = 9;  // opcode + uint64 length
constexpr uint64_t kFooterSize = 1 + 8 + 8 + 8 + 4;

bool IsMagic(std::span<const uint8_t> b) {
  return b.size() == kMagic.size() &&
         std::equal(kMagic.begin(), kMagic.end(), b.begin(),
                    [](char a, uint8_t x) { return static_cast<uint8_t>(a) == x; });
}

uint64_t LeU64(std::span<const uint8_t> b) {
  uint64_t v = 0;
  for (size_t i = 0; i < 8; ++i) v |= static_cast<uint64_t>(b[i]) << (8 * i);
  return v;
}

/// A record read from the file: its bytes (opcode, length, content) and the view of them.
struct OwnedRecord {
  std::vector<uint8_t> bytes;
  Record record;
};

/// Where a chunk is and which log times it holds (a Chunk Index record).
struct ChunkRef {
  uint64_t start_time = 0;
  uint64_t end_time = 0;
  uint64_t offset = 0;
  uint64_t length = 0;
};

/// A message of a loaded chunk, waiting for its turn in log-time order.
struct Pending {
  uint64_t log_time = 0;
  uint64_t seq = 0;  ///< load order: ties in log time keep the file's order
  Message message;
};

bool Later(const Pending& a, const Pending& b) {
  return a.log_time != b.log_time ? a.log_time > b.log_time : a.seq > b.seq;
}

}  // namespace

struct StreamReader::Impl {
  std::filesystem::path path;
  std::string where;
  std::FILE* file = nullptr;
  uint64_t file_pos = 0;  ///< where the next fread reads
  uint64_t size = 0;
  File info;
  bool indexed = false;
  std::string fallback_reason;
  std::string compressions;
  // Indexed: the chunks by start time and a heap of the loaded chunks' messages.
  std::vector<ChunkRef> chunks;
  size_t next_chunk = 0;
  std::vector<Pending> heap;
  uint64_t seq = 0;
  // Streaming: the position, the data section's CRC so far, the messages of the last chunk.
  uint64_t pos = 0;
  uint64_t scanned_until = 0;
  uint32_t data_crc = 0;
  bool data_end = false;
  std::deque<Message> queue;
  // Both: the bytes read, and how it ended.
  uint64_t bytes_read = 0;
  bool done = false;
  Status damage;
  uint64_t intact_bytes = 0;

  ~Impl() {
    if (file != nullptr) std::fclose(file);
  }

  /// Reads `n` bytes at `offset` into `out` (after what it holds); ParseError when the file ends
  /// first, ResourceExhausted past max_file_bytes.
  Status ReadInto(uint64_t offset, uint64_t n, std::string_view what, std::vector<uint8_t>& out) {
    if (offset > size || n > size - offset) {
      return ParseError(fmt::format("{}: {} at offset {} needs {} bytes, the file has {} left",
                                    where, what, offset, n, offset > size ? 0 : size - offset));
    }
    if (n > io::MaxFileBytes().value()) {
      return io::MaxFileBytes().Check(
          fmt::format("{}: {} at offset {} ({} bytes)", where, what, offset, n), n);
    }
    const size_t at = out.size();
    out.resize(at + n);
    if ((offset != file_pos && fseeko(file, static_cast<off_t>(offset), SEEK_SET) != 0) ||
        std::fread(out.data() + at, 1, n, file) != n) {
      file_pos = std::numeric_limits<uint64_t>::max();
      return IoError(fmt::format("{}: read of {} bytes at offset {} failed: {}", where, n, offset,
                                 std::strerror(errno)));
    }
    file_pos = offset + n;
    bytes_read += n;
    return Status::Ok();
  }

  Result<std::vector<uint8_t>> ReadAt(uint64_t offset, uint64_t n, std::string_view what) {
    std::vector<uint8_t> out;
    AVP_RETURN_IF_ERROR(ReadInto(offset, n, what, out));
    return out;
  }

  /// The record at `offset` (its header and content); ParseError naming the offset when the file
  /// ends inside it.
  Result<OwnedRecord> RecordFrom(uint64_t offset) {
    if (offset > size || size - offset < kRecordHeader) {
      return ParseError(fmt::format("{}: truncated record header at offset {} ({} of 9 bytes left)",
                                    where, offset, offset > size ? 0 : size - offset));
    }
    OwnedRecord r;
    AVP_RETURN_IF_ERROR(ReadInto(offset, kRecordHeader, "record", r.bytes));
    const uint64_t len = LeU64(std::span(r.bytes).subspan(1));
    if (len > size - offset - kRecordHeader) {
      return ParseError(
          fmt::format("{}: truncated {} record at offset {}: its length is {} bytes, {} are left",
                      where, OpcodeName(r.bytes[0]), offset, len, size - offset - kRecordHeader));
    }
    AVP_RETURN_IF_ERROR(ReadInto(offset + kRecordHeader, len, OpcodeName(r.bytes[0]), r.bytes));
    r.record.op = r.bytes[0];
    r.record.offset = offset;
    r.record.content = std::span<const uint8_t>(r.bytes).subspan(kRecordHeader);
    return r;
  }

  /// The magic and the Header record; pos after it.
  Status ReadFileHeader() {
    const uint64_t n = std::min<uint64_t>(size, kMagic.size() + kRecordHeader);
    AVP_ASSIGN_OR_RETURN(std::vector<uint8_t> start, ReadAt(0, n, "the file's start"));
    if (n == kMagic.size() + kRecordHeader && IsMagic(std::span(start).first(kMagic.size()))) {
      AVP_ASSIGN_OR_RETURN(OwnedRecord header, RecordFrom(kMagic.size()));
      start.resize(kMagic.size());
      start.insert(start.end(), header.bytes.begin(), header.bytes.end());
    }
    AVP_RETURN_IF_ERROR(ReadHeader(start, where, info));
    pos = start.size();
    data_crc = Crc32(start);
    return Status::Ok();
  }

  // ---- Indexed ----------------------------------------------------------------------------------

  /// The summary through the Footer; chunks, attachments and metadata through their indexes.
  Status OpenIndexed() {
    std::vector<uint8_t> magic;
    if (size < kMagic.size() * 2 + kFooterSize ||
        !ReadInto(size - kMagic.size(), kMagic.size(), "closing magic", magic).ok() ||
        !IsMagic(magic)) {
      return ParseError(fmt::format(
          "{}: no closing magic at the end (offset {}): the file is truncated or was not closed; "
          "read it streaming to recover the intact chunks",
          where, size >= 8 ? size - 8 : 0));
    }
    const uint64_t footer_at = size - kMagic.size() - kFooterSize;
    AVP_ASSIGN_OR_RETURN(const OwnedRecord footer, RecordFrom(footer_at));
    if (footer.record.op != static_cast<uint8_t>(Opcode::kFooter) ||
        footer.record.content.size() != 20) {
      return ParseError(fmt::format("{}: no Footer record at offset {}", where, footer_at));
    }
    Cursor fc(footer.record.content, footer_at + kRecordHeader, "Footer");
    const uint64_t summary_start = fc.U64("summary_start");
    fc.U64("summary_offset_start");
    const uint32_t summary_crc = fc.U32("summary_crc");
    if (summary_start == 0) {
      return ParseError(
          fmt::format("{}: the Footer at offset {} names no summary section", where, footer_at));
    }
    if (summary_start < 8 || summary_start > footer_at) {
      return ParseError(fmt::format("{}: Footer at offset {}: summary_start {} is outside the file",
                                    where, footer_at, summary_start));
    }
    AVP_ASSIGN_OR_RETURN(
        const std::vector<uint8_t> summary,
        ReadAt(summary_start, footer_at + 1 + 8 + 8 + 8 - summary_start, "summary section"));
    if (summary_crc != 0 && Crc32(summary) != summary_crc) {
      return ParseError(fmt::format(
          "{}: summary CRC mismatch (summary at offset {}): stored {:08x}, computed {:08x}", where,
          summary_start, summary_crc, Crc32(summary)));
    }
    return ReadSummary(std::span(summary).first(footer_at - summary_start), summary_start);
  }

  Status ReadSummary(std::span<const uint8_t> bytes, uint64_t summary_start) {
    uint64_t at = summary_start;
    while (at < summary_start + bytes.size()) {
      AVP_ASSIGN_OR_RETURN(const Record r, RecordAt(bytes, at, summary_start, where));
      switch (static_cast<Opcode>(r.op)) {
        case Opcode::kSchema: {
          AVP_ASSIGN_OR_RETURN(Schema s, ParseSchema(r, where));
          info.schemas.push_back(std::move(s));
          break;
        }
        case Opcode::kChannel: {
          AVP_ASSIGN_OR_RETURN(Channel ch, ParseChannel(r, where));
          info.channels.push_back(std::move(ch));
          break;
        }
        case Opcode::kStatistics:
          AVP_RETURN_IF_ERROR(ParseStatistics(r));
          break;
        case Opcode::kChunkIndex:
          AVP_RETURN_IF_ERROR(AddChunkIndex(r, summary_start));
          break;
        case Opcode::kAttachmentIndex:
        case Opcode::kMetadataIndex:
          AVP_RETURN_IF_ERROR(ReadIndexedRecord(r, summary_start));
          break;
        default:
          break;
      }
      at = r.end();
    }
    std::stable_sort(chunks.begin(), chunks.end(), [](const ChunkRef& a, const ChunkRef& b) {
      return a.start_time != b.start_time ? a.start_time < b.start_time : a.offset < b.offset;
    });
    return Status::Ok();
  }

  Status ParseStatistics(const Record& r) {
    Statistics& s = info.statistics;
    Cursor c(r.content, r.offset + 9, "Statistics");
    s.message_count = c.U64("message_count");
    s.schema_count = c.U16("schema_count");
    s.channel_count = c.U32("channel_count");
    s.attachment_count = c.U32("attachment_count");
    s.metadata_count = c.U32("metadata_count");
    s.chunk_count = c.U32("chunk_count");
    s.message_start_time = c.U64("message_start_time");
    s.message_end_time = c.U64("message_end_time");
    const uint32_t len = c.U32("channel_message_counts");
    Cursor m(c.Take(len, "channel_message_counts"), c.offset() - len, "Statistics counts");
    while (c.ok() && m.ok() && m.left() > 0) {
      const uint16_t channel = m.U16("channel_id");
      s.channel_message_counts[channel] = m.U64("count");
    }
    if (!c.ok()) return Bad(where, c);
    if (!m.ok()) return Bad(where, m);
    return Status::Ok();
  }

  Status AddChunkIndex(const Record& r, uint64_t summary_start) {
    Cursor c(r.content, r.offset + 9, "Chunk Index");
    ChunkRef ref;
    ref.start_time = c.U64("message_start_time");
    ref.end_time = c.U64("message_end_time");
    ref.offset = c.U64("chunk_start_offset");
    ref.length = c.U64("chunk_length");
    const uint32_t offsets_len = c.U32("message_index_offsets");
    c.Take(offsets_len, "message_index_offsets");
    c.U64("message_index_length");
    const std::string compression = c.String("compression");
    if (!c.ok()) return Bad(where, c);
    if (ref.offset < 8 || ref.offset > summary_start || ref.length > summary_start - ref.offset ||
        ref.length < 9) {
      return ParseError(fmt::format(
          "{}: Chunk Index at offset {} points at bytes {}..{}, outside the data section", where,
          r.offset, ref.offset, ref.offset + ref.length));
    }
    NoteCompression(compression);
    chunks.push_back(ref);
    return Status::Ok();
  }

  void NoteCompression(const std::string& compression) {
    const std::string name = compression.empty() ? "uncompressed" : compression;
    if (compressions.find(name) == std::string::npos) {
      compressions += (compressions.empty() ? "" : ", ") + name;
    }
  }

  /// An attachment or metadata record through its index.
  Status ReadIndexedRecord(const Record& r, uint64_t summary_start) {
    const bool attachment = r.op == static_cast<uint8_t>(Opcode::kAttachmentIndex);
    Cursor c(r.content, r.offset + 9, attachment ? "Attachment Index" : "Metadata Index");
    const uint64_t record_at = c.U64("offset");
    const uint64_t length = c.U64("length");
    if (!c.ok()) return Bad(where, c);
    if (record_at < 8 || record_at > summary_start || length > summary_start - record_at ||
        length < 9) {
      return ParseError(
          fmt::format("{}: {} at offset {} points at bytes {}..{}, outside the data section", where,
                      OpcodeName(r.op), r.offset, record_at, record_at + length));
    }
    AVP_ASSIGN_OR_RETURN(const OwnedRecord rec, RecordFrom(record_at));
    const Opcode want = attachment ? Opcode::kAttachment : Opcode::kMetadata;
    if (rec.record.op != static_cast<uint8_t>(want) || rec.record.end() != record_at + length) {
      return ParseError(fmt::format(
          "{}: {} at offset {} points at offset {}, which holds a {} record of {} bytes, not a {} "
          "of {}",
          where, OpcodeName(r.op), r.offset, record_at, OpcodeName(rec.record.op),
          rec.record.end() - record_at, OpcodeName(static_cast<uint8_t>(want)), length));
    }
    if (attachment) {
      AVP_ASSIGN_OR_RETURN(Attachment a, ParseAttachment(rec.record, where));
      info.attachments.push_back(std::move(a));
    } else {
      AVP_ASSIGN_OR_RETURN(Metadata md, ParseMetadata(rec.record, where));
      info.metadata.push_back(std::move(md));
    }
    return Status::Ok();
  }

  /// The next chunk's messages onto the heap.
  Status LoadChunk(const ChunkRef& ref) {
    AVP_ASSIGN_OR_RETURN(const OwnedRecord chunk, RecordFrom(ref.offset));
    if (chunk.record.op != static_cast<uint8_t>(Opcode::kChunk) ||
        chunk.record.end() != ref.offset + ref.length) {
      return ParseError(
          fmt::format("{}: a Chunk Index points at offset {}, which holds a {} record, not a Chunk",
                      where, ref.offset, OpcodeName(chunk.record.op)));
    }
    std::vector<Message> messages;
    AVP_RETURN_IF_ERROR(ReadChunk(chunk.record, where, messages, nullptr, nullptr));
    ++info.chunk_count;
    for (Message& m : messages) {
      heap.push_back({m.log_time, seq++, std::move(m)});
      std::push_heap(heap.begin(), heap.end(), Later);
    }
    return Status::Ok();
  }

  Result<std::optional<Message>> NextIndexed() {
    while (damage.ok() && next_chunk < chunks.size() &&
           (heap.empty() || chunks[next_chunk].start_time <= heap.front().log_time)) {
      const ChunkRef& ref = chunks[next_chunk++];
      if (Status s = LoadChunk(ref); !s.ok()) {
        damage = std::move(s);
        intact_bytes = ref.offset;
      }
    }
    if (heap.empty()) {
      done = true;
      if (!damage.ok()) return damage;
      return std::optional<Message>();
    }
    std::pop_heap(heap.begin(), heap.end(), Later);
    Message m = std::move(heap.back().message);
    heap.pop_back();
    return std::optional<Message>(std::move(m));
  }

  // ---- Streaming --------------------------------------------------------------------------------

  /// The next record in file order: messages into the queue, the rest into `info`. Sets `done`
  /// at the Footer.
  Status ReadNextRecord() {
    if (pos == size) {
      return ParseError(
          fmt::format("{}: the file ends at offset {} without {}: truncated (the messages before "
                      "it are intact)",
                      where, pos, data_end ? "its Footer" : "a Data End record"));
    }
    AVP_ASSIGN_OR_RETURN(const OwnedRecord owned, RecordFrom(pos));
    const Record& r = owned.record;
    AVP_RETURN_IF_ERROR(StreamRecord(r));
    if (!data_end) data_crc = Crc32(owned.bytes, data_crc);
    if (r.op == static_cast<uint8_t>(Opcode::kFooter)) {
      AVP_ASSIGN_OR_RETURN(
          const std::vector<uint8_t> magic,
          ReadAt(r.end(), std::min<uint64_t>(kMagic.size(), size - r.end()), "closing magic"));
      if (!IsMagic(magic)) {
        return ParseError(fmt::format(
            "{}: no closing magic after the Footer at offset {} (the file ends at byte {})", where,
            pos, size));
      }
      done = true;
      intact_bytes = size;
    }
    pos = r.end();
    return Status::Ok();
  }

  Status StreamRecord(const Record& r) {
    const auto op = static_cast<Opcode>(r.op);
    if (r.offset < scanned_until && (op == Opcode::kSchema || op == Opcode::kChannel ||
                                     op == Opcode::kMetadata || op == Opcode::kAttachment)) {
      return Status::Ok();  // read by ScanOutsideChunks
    }
    switch (op) {
      case Opcode::kSchema: {
        AVP_ASSIGN_OR_RETURN(Schema s, ParseSchema(r, where));
        if (!data_end) info.schemas.push_back(std::move(s));
        return Status::Ok();
      }
      case Opcode::kChannel: {
        AVP_ASSIGN_OR_RETURN(Channel ch, ParseChannel(r, where));
        if (!data_end) info.channels.push_back(std::move(ch));
        return Status::Ok();
      }
      case Opcode::kMessage: {
        AVP_ASSIGN_OR_RETURN(Message m, ParseMessage(r, where));
        queue.push_back(std::move(m));
        return Status::Ok();
      }
      case Opcode::kChunk:
        return StreamChunk(r);
      case Opcode::kAttachment: {
        AVP_ASSIGN_OR_RETURN(Attachment a, ParseAttachment(r, where));
        info.attachments.push_back(std::move(a));
        return Status::Ok();
      }
      case Opcode::kMetadata: {
        AVP_ASSIGN_OR_RETURN(Metadata md, ParseMetadata(r, where));
        info.metadata.push_back(std::move(md));
        return Status::Ok();
      }
      case Opcode::kDataEnd:
        return CheckDataEnd(r);
      default:
        return Status::Ok();
    }
  }

  /// A chunk's messages into the queue, by log time (a chunk may hold them out of order).
  Status StreamChunk(const Record& r) {
    Cursor c(r.content, r.offset + 9, "Chunk");
    c.U64("message_start_time");
    c.U64("message_end_time");
    c.U64("uncompressed_size");
    c.U32("uncompressed_crc");
    NoteCompression(c.String("compression"));
    std::vector<Message> messages;
    AVP_RETURN_IF_ERROR(ReadChunk(r, where, messages, &info.schemas, &info.channels));
    ++info.chunk_count;
    std::stable_sort(messages.begin(), messages.end(),
                     [](const Message& a, const Message& b) { return a.log_time < b.log_time; });
    for (Message& m : messages) queue.push_back(std::move(m));
    return Status::Ok();
  }

  Status CheckDataEnd(const Record& r) {
    Cursor c(r.content, r.offset + 9, "Data End");
    const uint32_t crc = c.U32("data_section_crc");
    if (!c.ok()) return Bad(where, c);
    if (crc != 0 && crc != data_crc) {
      return ParseError(
          fmt::format("{}: data section CRC mismatch (Data End at offset {}): stored {:08x}, "
                      "computed {:08x}",
                      where, r.offset, crc, data_crc));
    }
    data_end = true;
    return Status::Ok();
  }

  /// A streaming pass's first look: the record headers from `pos` to the end, reading only the
  /// records outside chunks that say what the file holds (Schema, Channel, Metadata, Attachment;
  /// writers put metadata and attachments anywhere, often after the messages) and seeking over
  /// the rest. Stops quietly at the first damage (the pass itself reports it). The records read
  /// here are not read again by the pass (scanned_until).
  void ScanOutsideChunks() {
    uint64_t at = pos;
    while (at < size && size - at >= kRecordHeader) {
      std::vector<uint8_t> head;
      if (!ReadInto(at, kRecordHeader, "record", head).ok()) break;
      const uint64_t len = LeU64(std::span(head).subspan(1));
      if (len > size - at - kRecordHeader) break;
      const auto op = static_cast<Opcode>(head[0]);
      if (op == Opcode::kDataEnd || op == Opcode::kFooter) break;
      if (op == Opcode::kSchema || op == Opcode::kChannel || op == Opcode::kMetadata ||
          op == Opcode::kAttachment) {
        Result<OwnedRecord> r = RecordFrom(at);
        if (!r.ok() || !StreamRecord(r->record).ok()) break;
      }
      at += kRecordHeader + len;
      scanned_until = at;
    }
  }

  /// Reads records until a message is queued, the file ends or it is damaged.
  void FillQueue() {
    while (queue.empty() && !done) {
      if (Status s = ReadNextRecord(); !s.ok()) {
        damage = std::move(s);
        intact_bytes = pos;
        done = true;
      }
    }
  }

  Result<std::optional<Message>> NextStreaming() {
    FillQueue();
    if (queue.empty()) {
      if (!damage.ok()) return damage;
      return std::optional<Message>();
    }
    Message m = std::move(queue.front());
    queue.pop_front();
    return std::optional<Message>(std::move(m));
  }
};

StreamReader::StreamReader(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
StreamReader::~StreamReader() = default;

Result<std::unique_ptr<StreamReader>> StreamReader::Open(const std::filesystem::path& path,
                                                         Mode mode) {
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  impl->where = path.string();
  impl->file = std::fopen(path.c_str(), "rb");
  if (impl->file == nullptr) {
    return IoError(fmt::format("{}: cannot open: {}", impl->where, std::strerror(errno)));
  }
  AVP_ASSIGN_OR_RETURN(
      impl->size, io::CheckReadableFile(path, "MCAP file", std::numeric_limits<uint64_t>::max()));
  AVP_RETURN_IF_ERROR(impl->ReadFileHeader());
  if (mode != Mode::kStreaming) {
    Status indexed = impl->OpenIndexed();
    if (indexed.ok() && impl->chunks.empty() && impl->info.statistics.message_count > 0) {
      indexed = ParseError(fmt::format("{}: its messages are not in indexed chunks", impl->where));
    }
    if (indexed.ok()) {
      impl->indexed = true;
      return std::unique_ptr<StreamReader>(new StreamReader(std::move(impl)));
    }
    if (mode == Mode::kIndexed) return indexed;
    impl->fallback_reason = indexed.message();
    // Start again from the Header: a streaming pass reads everything from there.
    File fresh;
    fresh.profile = impl->info.profile;
    fresh.library = impl->info.library;
    impl->info = std::move(fresh);
    impl->chunks.clear();
    impl->compressions.clear();
  }
  // What the file holds outside its chunks (metadata and attachments wherever they are), then
  // the first chunk: what a bag holds is known before its first message is asked for.
  impl->ScanOutsideChunks();
  impl->FillQueue();
  return std::unique_ptr<StreamReader>(new StreamReader(std::move(impl)));
}

bool StreamReader::indexed() const { return impl_->indexed; }
const File& StreamReader::info() const { return impl_->info; }
const std::string& StreamReader::fallback_reason() const { return impl_->fallback_reason; }
const std::string& StreamReader::chunk_compression() const { return impl_->compressions; }
uint64_t StreamReader::bytes_read() const { return impl_->bytes_read; }
uint64_t StreamReader::file_bytes() const { return impl_->size; }
uint64_t StreamReader::intact_bytes() const {
  return impl_->damage.ok() ? impl_->size : impl_->intact_bytes;
}
const std::filesystem::path& StreamReader::path() const { return impl_->path; }

Result<std::optional<Message>> StreamReader::Next() {
  return impl_->indexed ? impl_->NextIndexed() : impl_->NextStreaming();
}

// ---- Whole files --------------------------------------------------------------------------------

Result<File> ReadIndexed(const std::filesystem::path& path) {
  AVP_ASSIGN_OR_RETURN(std::unique_ptr<StreamReader> reader,
                       StreamReader::Open(path, StreamReader::Mode::kIndexed));
  std::vector<Message> messages;
  while (true) {
    AVP_ASSIGN_OR_RETURN(std::optional<Message> m, reader->Next());
    if (!m) break;
    messages.push_back(std::move(*m));
  }
  File file = reader->info();
  file.messages = std::move(messages);
  return file;
}

namespace {

/// A streamed file's statistics, counted from what was read.
void CountStatistics(File& file) {
  Statistics& s = file.statistics;
  s.message_count = file.messages.size();
  s.schema_count = static_cast<uint16_t>(file.schemas.size());
  s.channel_count = static_cast<uint32_t>(file.channels.size());
  s.chunk_count = file.chunk_count;
  s.attachment_count = static_cast<uint32_t>(file.attachments.size());
  s.metadata_count = static_cast<uint32_t>(file.metadata.size());
  for (size_t i = 0; i < file.messages.size(); ++i) {
    const Message& m = file.messages[i];
    s.message_start_time = i == 0 ? m.log_time : std::min(s.message_start_time, m.log_time);
    s.message_end_time = i == 0 ? m.log_time : std::max(s.message_end_time, m.log_time);
    ++s.channel_message_counts[m.channel_id];
  }
}

}  // namespace

StreamResult ReadStreaming(const std::filesystem::path& path) {
  StreamResult result;
  Result<std::unique_ptr<StreamReader>> reader =
      StreamReader::Open(path, StreamReader::Mode::kStreaming);
  if (!reader.ok()) {
    result.status = reader.status();
    std::error_code ec;
    const uint64_t size = std::filesystem::file_size(path, ec);
    result.intact_bytes = !ec && size >= kMagic.size() ? kMagic.size() : 0;
    return result;
  }
  std::vector<Message> messages;
  while (true) {
    Result<std::optional<Message>> m = (*reader)->Next();
    if (!m.ok()) {
      result.status = m.status();
      break;
    }
    if (!*m) break;
    messages.push_back(std::move(**m));
  }
  result.file = (*reader)->info();
  result.file.messages = std::move(messages);
  result.intact_bytes = (*reader)->intact_bytes();
  CountStatistics(result.file);
  return result;
}

}  // namespace avp::ros::mcap
