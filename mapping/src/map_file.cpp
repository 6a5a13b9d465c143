#include <algorithm>
#include <array>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <optional>
#include <string_view>
#include <system_error>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/error.h>
#include <avp/io/file.h>
#include <avp/mapping/map_file.h>

namespace avp::mapping {

namespace {

// ---- Layout constants (docs/map-format.md)
// -------------------------------------------------------
constexpr size_t kMagicBytes = sizeof(kMapFileMagic);
constexpr size_t kVersionEnd = 12;    // magic + u32 version
constexpr size_t kFileBytesEnd = 24;  // + u32 flags + u64 file_bytes
constexpr size_t kCrcBytes = 4;
// The first format: the header held fixed fields for the options (docs/map-format.md); still read.
constexpr uint32_t kMapFileVersionV1 = 1;
// Most options a version 2 header may name (the table has 21).
constexpr uint32_t kMaxHeaderOptions = 1024;
constexpr size_t kCellBytes = 12 + 2 * kNumSemanticClasses;  // 26 with 7 classes
// Smallest block record: key (12) + known bitset (64) + has_semantics (1).
constexpr size_t kMinBlockBytes = 12 + 8 * kBlockWords + 1;

std::array<uint32_t, 256> MakeCrcTable() {
  std::array<uint32_t, 256> table{};
  for (uint32_t n = 0; n < 256; ++n) {
    uint32_t c = n;
    for (int k = 0; k < 8; ++k) c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    table[n] = c;
  }
  return table;
}

// ---- Little-endian writer
// -------------------------------------------------------------------------
class ByteWriter {
 public:
  void U8(uint8_t v) { out_.push_back(v); }
  void U16(uint16_t v) {
    for (int i = 0; i < 2; ++i) out_.push_back(static_cast<uint8_t>(v >> (8 * i)));
  }
  void U32(uint32_t v) {
    for (int i = 0; i < 4; ++i) out_.push_back(static_cast<uint8_t>(v >> (8 * i)));
  }
  void U64(uint64_t v) {
    for (int i = 0; i < 8; ++i) out_.push_back(static_cast<uint8_t>(v >> (8 * i)));
  }
  void I16(int16_t v) { U16(static_cast<uint16_t>(v)); }
  void I32(int32_t v) { U32(static_cast<uint32_t>(v)); }
  void F32(float v) { U32(std::bit_cast<uint32_t>(v)); }
  void F64(double v) { U64(std::bit_cast<uint64_t>(v)); }
  void Bytes(const void* data, size_t n) {
    const auto* p = static_cast<const uint8_t*>(data);
    out_.insert(out_.end(), p, p + n);
  }
  /// Overwrites 8 bytes at `offset` (the file size, known only at the end).
  void PatchU64(size_t offset, uint64_t v) {
    for (int i = 0; i < 8; ++i) out_[offset + i] = static_cast<uint8_t>(v >> (8 * i));
  }
  std::vector<uint8_t>& bytes() { return out_; }

 private:
  std::vector<uint8_t> out_;
};

// ---- Bounds-checked little-endian reader
// ----------------------------------------------------------- Every getter checks the remaining
// size first; on failure the reader remembers the first error
// ("truncated at byte X while reading <what>") and every later read fails too.
class ByteReader {
 public:
  ByteReader(std::span<const uint8_t> bytes, size_t end) : bytes_(bytes), end_(end) {}

  size_t position() const { return pos_; }
  size_t remaining() const { return end_ - pos_; }
  bool ok() const { return error_.empty(); }
  const std::string& error() const { return error_; }

  bool Need(size_t n, std::string_view what) {
    if (!ok()) return false;
    if (n > remaining()) {
      error_ = fmt::format("truncated at byte {} while reading {} ({} bytes needed, {} left)", end_,
                           what, n, remaining());
      return false;
    }
    return true;
  }
  bool U8(uint8_t& v, std::string_view what) {
    if (!Need(1, what)) return false;
    v = bytes_[pos_++];
    return true;
  }
  bool U16(uint16_t& v, std::string_view what) {
    uint64_t x = 0;
    if (!Unsigned(2, x, what)) return false;
    v = static_cast<uint16_t>(x);
    return true;
  }
  bool U32(uint32_t& v, std::string_view what) {
    uint64_t x = 0;
    if (!Unsigned(4, x, what)) return false;
    v = static_cast<uint32_t>(x);
    return true;
  }
  bool U64(uint64_t& v, std::string_view what) { return Unsigned(8, v, what); }
  bool I16(int16_t& v, std::string_view what) {
    uint16_t x = 0;
    if (!U16(x, what)) return false;
    v = static_cast<int16_t>(x);
    return true;
  }
  bool I32(int32_t& v, std::string_view what) {
    uint32_t x = 0;
    if (!U32(x, what)) return false;
    v = static_cast<int32_t>(x);
    return true;
  }
  bool F32(float& v, std::string_view what) {
    uint32_t x = 0;
    if (!U32(x, what)) return false;
    v = std::bit_cast<float>(x);
    return true;
  }
  bool F64(double& v, std::string_view what) {
    uint64_t x = 0;
    if (!U64(x, what)) return false;
    v = std::bit_cast<double>(x);
    return true;
  }
  bool String(size_t n, std::string& v, std::string_view what) {
    if (!Need(n, what)) return false;
    v.assign(reinterpret_cast<const char*>(bytes_.data() + pos_), n);
    pos_ += n;
    return true;
  }

 private:
  bool Unsigned(int n, uint64_t& v, std::string_view what) {
    if (!Need(static_cast<size_t>(n), what)) return false;
    v = 0;
    for (int i = 0; i < n; ++i) v |= static_cast<uint64_t>(bytes_[pos_ + i]) << (8 * i);
    pos_ += static_cast<size_t>(n);
    return true;
  }

  std::span<const uint8_t> bytes_;
  size_t end_;
  size_t pos_ = 0;
  std::string error_;
};

std::string HexPrefix(std::span<const uint8_t> bytes, size_t n) {
  std::string s;
  for (size_t i = 0; i < std::min(n, bytes.size()); ++i) {
    if (i > 0) s += ' ';
    s += fmt::format("{:02x}", bytes[i]);
  }
  return s;
}

Status Corrupt(const std::string& message) { return ParseError(message); }

/// `text` with bytes below 0x20, 0x7f and above as \xNN (a file's bytes in a message never reach
/// a terminal raw), shortened. (The messages it escapes already quote their values: EscapeText
/// would escape those quotes again.)
std::string EscapeControl(std::string_view text) {
  std::string out;
  for (const char c : text.substr(0, 1024)) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u >= 0x7f) {
      out += fmt::format("\\x{:02x}", u);
    } else {
      out += c;
    }
  }
  if (text.size() > 1024) out += fmt::format("...({} bytes)", text.size());
  return out;
}

}  // namespace

uint32_t Crc32(std::span<const uint8_t> bytes, uint32_t crc) {
  static const std::array<uint32_t, 256> kTable = MakeCrcTable();
  uint32_t c = crc ^ 0xFFFFFFFFu;
  for (uint8_t b : bytes) c = kTable[(c ^ b) & 0xFFu] ^ (c >> 8);
  return c ^ 0xFFFFFFFFu;
}

namespace {

/// The map's options as the table names them (MapOptionTable: grid.voxel_size_m, grid.sensor.*,
/// semantics.*): u32 count, then each as u16 key length, key, u16 value length, value (text that
/// reads back to the same bits).
void WriteOptions(const MapOptions& options, ByteWriter& w) {
  const OptionValues values = MapOptionTable().Values(options);
  w.U32(static_cast<uint32_t>(values.size()));
  for (const auto& [key, value] : values) {
    w.U16(static_cast<uint16_t>(key.size()));
    w.Bytes(key.data(), key.size());
    w.U16(static_cast<uint16_t>(value.size()));
    w.Bytes(value.data(), value.size());
  }
}

}  // namespace

Result<std::vector<uint8_t>> SerializeMap(const SemanticMap& map, const MapSaveOptions& options) {
  if (options.note.size() > kMaxMapNoteBytes) {
    return InvalidArgumentError(fmt::format("map note has {} bytes; at most {} fit in a map file",
                                            options.note.size(), kMaxMapNoteBytes));
  }
  const OccupancyGrid& grid = map.grid();
  const GridOptions& go = grid.options();
  const float occupied = grid.occupied_log_odds();

  // The blocks written: every block with a known voxel or semantic payload, sorted by key. Blocks
  // allocated but never reached (the parallel integrator allocates ahead) are left out, and the
  // order does not depend on the order of allocation, so the same voxels give the same bytes
  // whatever the number of threads that integrated them.
  std::vector<const OccupancyBlock*> blocks;
  blocks.reserve(grid.num_blocks());
  grid.ForEachBlock([&](const OccupancyBlock& b) {
    if (b.known.any() || b.semantics != nullptr) blocks.push_back(&b);
  });
  std::sort(blocks.begin(), blocks.end(),
            [](const OccupancyBlock* a, const OccupancyBlock* b) { return a->key < b->key; });

  // Counts first (they go into the header).
  uint64_t known = 0, occupied_voxels = 0, cells = 0, labelled = 0;
  grid.ForEachBlock([&](const OccupancyBlock& b) {
    b.known.ForEachSet([&](int i) {
      ++known;
      if (b.log_odds[static_cast<size_t>(i)] >= occupied) ++occupied_voxels;
    });
    if (b.semantics) {
      for (const SemanticCell& c : *b.semantics) {
        if (c == SemanticCell{}) continue;
        ++cells;
        if (c.has_label()) ++labelled;
      }
    }
  });

  ByteWriter w;
  w.Bytes(kMapFileMagic, kMagicBytes);
  w.U32(kMapFileVersion);
  w.U32(0);  // flags (reserved)
  w.U64(0);  // file_bytes, patched below
  w.U8(go.roi.has_value() ? 1 : 0);
  for (int i = 0; i < 3; ++i) w.F64(go.roi ? go.roi->min()[i] : 0.0);
  for (int i = 0; i < 3; ++i) w.F64(go.roi ? go.roi->max()[i] : 0.0);
  w.U8(static_cast<uint8_t>(kNumSemanticClasses));
  w.U64(blocks.size());
  w.U64(known);
  w.U64(occupied_voxels);
  w.U64(cells);
  w.U64(labelled);
  WriteOptions(map.options(), w);
  w.U32(static_cast<uint32_t>(options.note.size()));
  w.Bytes(options.note.data(), options.note.size());

  for (const OccupancyBlock* block : blocks) {
    const OccupancyBlock& b = *block;
    w.I32(b.key.x);
    w.I32(b.key.y);
    w.I32(b.key.z);
    for (uint64_t word : b.known.words) w.U64(word);
    b.known.ForEachSet([&](int i) { w.F32(b.log_odds[static_cast<size_t>(i)]); });
    w.U8(b.semantics ? 1 : 0);
    if (!b.semantics) continue;
    BlockBits present;
    for (int i = 0; i < kBlockVoxels; ++i) {
      if (!((*b.semantics)[static_cast<size_t>(i)] == SemanticCell{})) present.set(i);
    }
    for (uint64_t word : present.words) w.U64(word);
    present.ForEachSet([&](int i) {
      const SemanticCell& c = (*b.semantics)[static_cast<size_t>(i)];
      w.U8(c.semantic_class);
      w.U8(c.flags);
      w.U16(c.instance_id);
      w.U16(c.observations);
      w.U16(c.misses);
      w.F32(c.confidence);
      for (int16_t v : c.class_log_odds) w.I16(v);
    });
  }

  const uint64_t total = w.bytes().size() + kCrcBytes;
  w.PatchU64(16, total);
  w.U32(Crc32(w.bytes()));
  return std::move(w.bytes());
}

namespace {

// ---- Reading (DeserializeMap's stages)
// ---------------------------------------------------------------

/// The fixed part of a file, checked before anything else is read.
struct FileFrame {
  uint32_t version = 0;
  uint64_t file_bytes = 0;
  uint32_t crc32 = 0;  ///< the stored (and verified) checksum
  size_t body = 0;     ///< bytes before the checksum
};

/// Magic: a shorter file whose bytes match the magic so far is truncated, otherwise not ours.
Status CheckMagic(std::span<const uint8_t> bytes, ByteReader& header) {
  const size_t size = bytes.size();
  if (size == 0) return Corrupt("truncated at byte 0: the file is empty");
  const bool magic_prefix_ok =
      std::memcmp(bytes.data(), kMapFileMagic, std::min(size, kMagicBytes)) == 0;
  if (!magic_prefix_ok) {
    return Corrupt(fmt::format(
        "bad magic: not an avp map file (starts with {}; expected 89 41 56 50 4d 41 50 0a, "
        "\"\\x89AVPMAP\\n\")",
        HexPrefix(bytes, kMagicBytes)));
  }
  if (!header.Need(kMagicBytes, "the magic")) return Corrupt(header.error());
  std::string magic;
  (void)header.String(kMagicBytes, magic, "the magic");
  return Status::Ok();
}

/// Magic, version, declared size against the real size, checksum over everything before the last
/// 4 bytes, and flags, in that order (the first failure is reported).
Result<FileFrame> CheckFileFrame(std::span<const uint8_t> bytes) {
  const size_t size = bytes.size();
  ByteReader header(bytes, size);
  AVP_RETURN_IF_ERROR(CheckMagic(bytes, header));
  FileFrame frame;
  if (!header.U32(frame.version, "the format version")) return Corrupt(header.error());
  if (frame.version != kMapFileVersion && frame.version != kMapFileVersionV1) {
    return Corrupt(
        fmt::format("unsupported map file version {} (this build reads versions {} and {})",
                    frame.version, kMapFileVersionV1, kMapFileVersion));
  }
  uint32_t flags = 0;
  if (!header.U32(flags, "the flags") || !header.U64(frame.file_bytes, "the file size")) {
    return Corrupt(header.error());
  }
  if (frame.file_bytes != size) {
    if (size < frame.file_bytes) {
      return Corrupt(fmt::format("truncated at byte {}: the header declares {} bytes", size,
                                 frame.file_bytes));
    }
    return Corrupt(
        fmt::format("file has {} bytes but its header declares {} ({} unexpected "
                    "bytes at the end, or a corrupted size field)",
                    size, frame.file_bytes, size - frame.file_bytes));
  }
  if (size < kFileBytesEnd + kCrcBytes) {
    return Corrupt(fmt::format("truncated at byte {}: too short for a map file", size));
  }
  frame.body = size - kCrcBytes;
  for (size_t i = 0; i < kCrcBytes; ++i) {
    frame.crc32 |= static_cast<uint32_t>(bytes[frame.body + i]) << (8 * i);
  }
  const uint32_t computed_crc = Crc32(bytes.first(frame.body));
  if (frame.crc32 != computed_crc) {
    return Corrupt(fmt::format(
        "checksum mismatch: stored CRC-32 0x{:08x}, computed 0x{:08x} (the file is corrupted)",
        frame.crc32, computed_crc));
  }
  if (flags != 0) {
    return Corrupt(fmt::format("unknown flags 0x{:08x} (this build knows none)", flags));
  }
  return frame;
}

/// Voxel counts of a map: declared in the header, or counted while reading the blocks.
struct VoxelCounts {
  uint64_t known = 0, occupied = 0, cells = 0, labelled = 0;
  bool operator==(const VoxelCounts&) const = default;
};

/// The header after the fixed part, as stored: the map's options (the fields with no direct
/// MapOptions counterpart are kept raw until ValidateHeader), the counts and the note.
struct MapHeader {
  MapOptions options;  ///< without policy, remove_outliers_each_frame and roi
  uint8_t has_roi = 0, policy = 0, remove_outliers = 0, num_classes = 0;
  double roi[6] = {};  ///< min x, y, z, max x, y, z (m)
  uint64_t num_blocks = 0;
  VoxelCounts counts;
  std::string note;
};

/// The class count, the block count and the voxel counts (both versions; a truncation shows in
/// r.ok()).
void ReadClassesAndCounts(ByteReader& r, MapHeader& h) {
  r.U8(h.num_classes, "the number of semantic classes");
  r.U64(h.num_blocks, "the block count");
  r.U64(h.counts.known, "the known voxel count");
  r.U64(h.counts.occupied, "the occupied voxel count");
  r.U64(h.counts.cells, "the semantic cell count");
  r.U64(h.counts.labelled, "the labelled voxel count");
}

/// The note and its length (both versions): the first truncation, or a length over
/// kMaxMapNoteBytes, is an error.
Status ReadNote(ByteReader& r, MapHeader& h) {
  uint32_t note_bytes = 0;
  if (!r.U32(note_bytes, "the note length")) return Corrupt(r.error());
  if (note_bytes > kMaxMapNoteBytes) {
    return Corrupt(
        fmt::format("note length {} exceeds the maximum {}", note_bytes, kMaxMapNoteBytes));
  }
  if (!r.String(note_bytes, h.note, "the note")) return Corrupt(r.error());
  return Status::Ok();
}

/// Reads a version 1 header after the fixed part (the reader stands at kFileBytesEnd): fixed
/// fields for the options of that time (the others keep their defaults). The first truncation, or
/// a note longer than kMaxMapNoteBytes, is an error.
Result<MapHeader> ReadHeaderV1(ByteReader& r) {
  MapHeader h;
  GridOptions& go = h.options.grid;
  SemanticOptions& so = h.options.semantics;
  r.F64(go.voxel_size_m, "voxel_size_m");
  r.U8(h.has_roi, "the ROI flag");
  for (double& v : h.roi) r.F64(v, "the ROI");
  r.F64(go.sensor.hit, "sensor.hit");
  r.F64(go.sensor.miss, "sensor.miss");
  r.F64(go.sensor.clamp_min, "sensor.clamp_min");
  r.F64(go.sensor.clamp_max, "sensor.clamp_max");
  r.F64(go.sensor.occupied_threshold, "sensor.occupied_threshold");
  r.U8(h.policy, "the fusion policy");
  r.F32(so.reference_penalty, "reference_penalty");
  r.F32(so.class_log_odds_min, "class_log_odds_min");
  r.F32(so.class_log_odds_max, "class_log_odds_max");
  r.F32(so.miss_log_odds, "miss_log_odds");
  r.F32(so.label_threshold, "label_threshold");
  r.F32(so.instance_join_fraction, "instance_join_fraction");
  r.F32(so.instance_merge_fraction, "instance_merge_fraction");
  r.I32(so.outlier_min_neighbours, "outlier_min_neighbours");
  r.U8(h.remove_outliers, "remove_outliers_each_frame");
  ReadClassesAndCounts(r, h);
  AVP_RETURN_IF_ERROR(ReadNote(r, h));
  return h;
}

/// The option section of a version 2 header (WriteOptions), applied over the defaults: an unknown
/// key or a value the table does not take is an error naming it.
Status ReadOptions(ByteReader& r, MapOptions& options) {
  uint32_t count = 0;
  if (!r.U32(count, "the option count")) return Corrupt(r.error());
  if (count > kMaxHeaderOptions) {
    return Corrupt(fmt::format("option count {} exceeds the maximum {}", count, kMaxHeaderOptions));
  }
  for (uint32_t i = 0; i < count; ++i) {
    uint16_t key_bytes = 0, value_bytes = 0;
    std::string key, value;
    if (!r.U16(key_bytes, "an option name length") || !r.String(key_bytes, key, "an option name") ||
        !r.U16(value_bytes, "an option value length") ||
        !r.String(value_bytes, value, "an option value")) {
      return Corrupt(r.error());
    }
    // Names and values come from the file: shown with their control bytes escaped.
    if (const Status s = MapOptionTable().Set(options, key, value); !s.ok()) {
      return Corrupt("invalid header: " + EscapeControl(s.message()));
    }
  }
  return Status::Ok();
}

/// Reads a version 2 header after the fixed part: the ROI, the class count, the counts, the
/// options (by name, ReadOptions) and the note.
Result<MapHeader> ReadHeaderV2(ByteReader& r) {
  MapHeader h;
  r.U8(h.has_roi, "the ROI flag");
  for (double& v : h.roi) r.F64(v, "the ROI");
  ReadClassesAndCounts(r, h);
  if (!r.ok()) return Corrupt(r.error());
  AVP_RETURN_IF_ERROR(ReadOptions(r, h.options));
  h.policy = static_cast<uint8_t>(h.options.semantics.policy);
  h.remove_outliers = h.options.semantics.remove_outliers_each_frame ? 1 : 0;
  AVP_RETURN_IF_ERROR(ReadNote(r, h));
  return h;
}

/// Checks the header's raw fields (every problem is reported; the block count against the
/// `remaining` bytes, before anything is allocated) and returns its complete, validated options.
Result<MapOptions> ValidateHeader(const MapHeader& h, size_t remaining) {
  std::vector<std::string> errors;
  if (h.has_roi > 1) errors.push_back(fmt::format("ROI flag ({}) must be 0 or 1", h.has_roi));
  if (h.policy > static_cast<uint8_t>(FusionPolicy::kBayesian)) {
    errors.push_back(
        fmt::format("fusion policy ({}) is unknown (0 reference-max, 1 bayesian)", h.policy));
  }
  if (h.remove_outliers > 1) {
    errors.push_back(
        fmt::format("remove_outliers_each_frame ({}) must be 0 or 1", h.remove_outliers));
  }
  if (h.num_classes != kNumSemanticClasses) {
    errors.push_back(fmt::format("the file has {} semantic classes, this build knows {}",
                                 h.num_classes, kNumSemanticClasses));
  }
  const double* roi = h.roi;
  if (h.has_roi == 1) {
    bool finite = true;
    for (double v : h.roi) finite = finite && std::isfinite(v);
    if (!finite || roi[0] > roi[3] || roi[1] > roi[4] || roi[2] > roi[5]) {
      errors.push_back(fmt::format("ROI [{}, {}, {}] - [{}, {}, {}] is not a finite box", roi[0],
                                   roi[1], roi[2], roi[3], roi[4], roi[5]));
    }
  }
  // Every block needs at least kMinBlockBytes: bound the count before anything is allocated.
  if (h.num_blocks > remaining / kMinBlockBytes) {
    errors.push_back(fmt::format("block count {} cannot fit in the {} bytes that remain",
                                 h.num_blocks, remaining));
  }
  if (!errors.empty()) {
    return Corrupt(fmt::format("invalid header: {}", fmt::join(errors, "; ")));
  }
  MapOptions options = h.options;
  options.semantics.policy = static_cast<FusionPolicy>(h.policy);
  options.semantics.remove_outliers_each_frame = h.remove_outliers == 1;
  if (h.has_roi == 1) {
    options.grid.roi =
        Box3(Eigen::Vector3d(roi[0], roi[1], roi[2]), Eigen::Vector3d(roi[3], roi[4], roi[5]));
  }
  if (Status s = options.Validate(); !s.ok()) {
    return Corrupt("invalid map options in the header: " + s.message());
  }
  return options;
}

/// Where a block record lies, for error messages.
struct BlockPlace {
  uint64_t n = 0;      ///< 1-based position
  uint64_t count = 0;  ///< blocks in the file
  size_t start = 0;    ///< byte offset of the record
  BlockKey key;

  std::string Describe() const {
    return fmt::format("block {} of {} at byte {}, key ({}, {}, {})", n, count, start, key.x, key.y,
                       key.z);
  }
};

/// A block's known voxels and their log-odds into the grid (the block is allocated even without
/// known voxels, so the allocation order is kept). `place.key` is read here.
Status ReadBlockOccupancy(ByteReader& r, BlockPlace& place, OccupancyGrid& grid,
                          VoxelCounts& seen) {
  constexpr int32_t kMaxBlockCoord = kMaxKeyMagnitude >> kBlockShift;
  BlockKey& bk = place.key;
  BlockBits known_bits;
  r.I32(bk.x, "a block key");
  r.I32(bk.y, "a block key");
  r.I32(bk.z, "a block key");
  for (uint64_t& word : known_bits.words) r.U64(word, "a block's known bitset");
  if (!r.ok()) return Corrupt(r.error());
  if (std::abs(int64_t{bk.x}) >= kMaxBlockCoord || std::abs(int64_t{bk.y}) >= kMaxBlockCoord ||
      std::abs(int64_t{bk.z}) >= kMaxBlockCoord) {
    return Corrupt(fmt::format("{}: key out of range (|coordinate| must be < {})", place.Describe(),
                               kMaxBlockCoord));
  }
  if (grid.Lookup(bk) >= 0) {
    return Corrupt(fmt::format("{}: the block appears twice", place.Describe()));
  }
  const size_t count = static_cast<size_t>(known_bits.count());
  if (!r.Need(4 * count, "a block's log-odds")) return Corrupt(r.error());
  grid.GetOrCreateBlock(bk);
  const float occupied_log_odds = grid.occupied_log_odds();
  std::string bad;
  known_bits.ForEachSet([&](int i) {
    float v = 0.0f;
    r.F32(v, "a log-odds");
    if (!bad.empty()) return;
    const VoxelKey k = KeyOf(bk, i);
    if (!(v >= grid.clamp_min_log_odds() && v <= grid.clamp_max_log_odds())) {
      bad = fmt::format(
          "voxel ({}, {}, {}) has a log-odds ({}) outside the sensor model's clamping range "
          "[{}, {}]",
          k.x, k.y, k.z, v, grid.clamp_min_log_odds(), grid.clamp_max_log_odds());
    } else if (!grid.SetLogOdds(k, v)) {
      bad = fmt::format("voxel ({}, {}, {}) lies outside the map's ROI", k.x, k.y, k.z);
    } else {
      ++seen.known;
      if (*grid.LogOdds(k) >= occupied_log_odds) ++seen.occupied;
    }
  });
  if (!r.ok()) return Corrupt(r.error());
  if (!bad.empty()) return Corrupt(fmt::format("{}: {}", place.Describe(), bad));
  return Status::Ok();
}

/// One semantic cell record into the grid; the problem as text ("" when none).
std::string StoreSemanticCell(const SemanticCell& c, const VoxelKey& k, OccupancyGrid& grid,
                              VoxelCounts& seen) {
  if (c.semantic_class >= kNumSemanticClasses) {
    return fmt::format("voxel ({}, {}, {}) has an unknown semantic class {}", k.x, k.y, k.z,
                       c.semantic_class);
  }
  if (!(c.confidence >= 0.0f && c.confidence <= 1.0f)) {
    return fmt::format("voxel ({}, {}, {}) has a confidence ({}) outside [0, 1]", k.x, k.y, k.z,
                       c.confidence);
  }
  SemanticCell* cell = grid.MutableSemantic(k);
  if (cell == nullptr) {
    return fmt::format("semantic voxel ({}, {}, {}) lies outside the map's ROI", k.x, k.y, k.z);
  }
  *cell = c;
  ++seen.cells;
  if (c.has_label()) ++seen.labelled;
  return {};
}

/// A block's semantics flag and, when set, its semantic cells into the grid.
Status ReadBlockSemantics(ByteReader& r, const BlockPlace& place, OccupancyGrid& grid,
                          VoxelCounts& seen) {
  const BlockKey& bk = place.key;
  uint8_t has_semantics = 0;
  if (!r.U8(has_semantics, "a block's semantics flag")) return Corrupt(r.error());
  if (has_semantics > 1) {
    return Corrupt(
        fmt::format("{}: semantics flag ({}) must be 0 or 1", place.Describe(), has_semantics));
  }
  if (has_semantics == 0) return Status::Ok();
  BlockBits present;
  for (uint64_t& word : present.words) r.U64(word, "a block's semantic bitset");
  if (!r.ok()) return Corrupt(r.error());
  const size_t num_cells = static_cast<size_t>(present.count());
  if (!r.Need(kCellBytes * num_cells, "a block's semantic cells")) return Corrupt(r.error());
  if (num_cells == 0) {
    // An allocated but empty semantic payload: allocate it again so the maps match exactly.
    for (int i = 0; i < kBlockVoxels; ++i) {
      if (grid.MutableSemantic(KeyOf(bk, i)) != nullptr) break;
    }
    return Status::Ok();
  }
  std::string bad;
  present.ForEachSet([&](int i) {
    SemanticCell c;
    r.U8(c.semantic_class, "a semantic cell");
    r.U8(c.flags, "a semantic cell");
    r.U16(c.instance_id, "a semantic cell");
    r.U16(c.observations, "a semantic cell");
    r.U16(c.misses, "a semantic cell");
    r.F32(c.confidence, "a semantic cell");
    for (int16_t& v : c.class_log_odds) r.I16(v, "a semantic cell");
    if (!bad.empty() || !r.ok()) return;
    bad = StoreSemanticCell(c, KeyOf(bk, i), grid, seen);
  });
  if (!r.ok()) return Corrupt(r.error());
  if (!bad.empty()) return Corrupt(fmt::format("{}: {}", place.Describe(), bad));
  return Status::Ok();
}

/// Reads the `num_blocks` block records into the grid and counts what they hold.
Result<VoxelCounts> ReadBlocks(ByteReader& r, uint64_t num_blocks, OccupancyGrid& grid) {
  VoxelCounts seen;
  for (uint64_t n = 0; n < num_blocks; ++n) {
    BlockPlace place{n + 1, num_blocks, r.position(), BlockKey{}};
    AVP_RETURN_IF_ERROR(ReadBlockOccupancy(r, place, grid, seen));
    AVP_RETURN_IF_ERROR(ReadBlockSemantics(r, place, grid, seen));
  }
  return seen;
}

/// After the blocks: no byte may remain before the checksum, and the header's counts must match
/// the blocks'.
Status CheckBlocksMatchHeader(const ByteReader& r, const VoxelCounts& declared,
                              const VoxelCounts& seen) {
  if (r.remaining() != 0) {
    return Corrupt(fmt::format("{} unexpected bytes after the last block (at byte {})",
                               r.remaining(), r.position()));
  }
  if (!(seen == declared)) {
    return Corrupt(fmt::format(
        "the counts in the header (known {}, occupied {}, semantic cells {}, labelled {}) do not "
        "match the blocks (known {}, occupied {}, semantic cells {}, labelled {})",
        declared.known, declared.occupied, declared.cells, declared.labelled, seen.known,
        seen.occupied, seen.cells, seen.labelled));
  }
  return Status::Ok();
}

}  // namespace

Result<SemanticMap> DeserializeMap(std::span<const uint8_t> bytes, MapFileInfo* info) {
  AVP_ASSIGN_OR_RETURN(const FileFrame frame, CheckFileFrame(bytes));
  // From here on the reader stops before the checksum.
  ByteReader r(bytes, frame.body);
  {
    std::string skip;
    (void)r.String(kFileBytesEnd, skip, "the fixed header");
  }
  AVP_ASSIGN_OR_RETURN(MapHeader header,
                       frame.version == kMapFileVersionV1 ? ReadHeaderV1(r) : ReadHeaderV2(r));
  AVP_ASSIGN_OR_RETURN(const MapOptions options, ValidateHeader(header, r.remaining()));
  // Each block takes some 2.3 KB in memory whatever the file holds: bounded before allocating.
  AVP_RETURN_IF_ERROR(MaxMapBlocks().Check("blocks of the map", header.num_blocks));
  std::optional<SemanticMap> loaded;
  try {
    loaded.emplace(options);
  } catch (const Error& e) {
    return Corrupt(fmt::format("invalid map options in the header: {}", e.what()));
  }
  OccupancyGrid& grid = loaded->grid();
  AVP_ASSIGN_OR_RETURN(const VoxelCounts seen, ReadBlocks(r, header.num_blocks, grid));
  AVP_RETURN_IF_ERROR(CheckBlocksMatchHeader(r, header.counts, seen));

  // The bookkeeping of a fresh map: no pending changes, instance ids from the cells.
  grid.ClearChanges();
  loaded->semantics().ResetFromGrid(grid);
  if (info != nullptr) {
    info->version = frame.version;
    info->file_bytes = frame.file_bytes;
    info->crc32 = frame.crc32;
    info->num_blocks = header.num_blocks;
    info->known_voxels = header.counts.known;
    info->occupied_voxels = header.counts.occupied;
    info->semantic_cells = header.counts.cells;
    info->labelled_voxels = header.counts.labelled;
    info->note = std::move(header.note);
  }
  return std::move(*loaded);
}

Status SaveMap(const SemanticMap& map, const std::filesystem::path& path,
               const MapSaveOptions& options) {
  AVP_ASSIGN_OR_RETURN(const std::vector<uint8_t> bytes, SerializeMap(map, options));
  return io::WriteFileAtomic(
      path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()),
      "map file");
}

Result<SemanticMap> LoadMap(const std::filesystem::path& path, MapFileInfo* info) {
  // Missing, a folder, over max_file_bytes: told apart before reading.
  AVP_ASSIGN_OR_RETURN(const std::string bytes, io::ReadFileBounded(path, "map file"));
  Result<SemanticMap> map = DeserializeMap(
      std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()), info);
  if (!map.ok()) return map.status().WithContext(fmt::format("map file '{}'", path.string()));
  return map;
}

const Limit& MaxMapBlocks() {
  static const Limit limit("max_map_blocks", uint64_t{1} << 21, "blocks",
                           "8^3-voxel blocks of one map read from a file (about 2.3 KB each)");
  return limit;
}

namespace {
// Registered when the program starts, so `avp --limit max_map_blocks=N` knows it.
[[maybe_unused]] const Limit& kRegisterMaxMapBlocks = MaxMapBlocks();
}  // namespace

}  // namespace avp::mapping
