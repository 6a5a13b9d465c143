#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include <avp/core/status.h>

namespace avp::ros::msg {

/// Plain CDR (OMG CDR as XCDR1 encodes final structs), as rmw_cyclonedds and rmw_fastrtps put ROS 2
/// messages on the wire: a 4-byte encapsulation header (`00 01 00 00` little-endian, `00 00 00 00`
/// big-endian), then the fields in declaration order, each primitive aligned to its size (8-byte
/// types to 8) relative to the end of that header. Strings: uint32 length counting the NUL, the
/// bytes, the NUL. Sequences: uint32 count, then the elements (no alignment when empty). Booleans
/// take one byte, 0 or 1. No padding at the end of a sample.
enum class Endianness { kLittle, kBig };

/// The largest sample CdrReader accepts, encapsulation header included (256 MiB): an RGB-D frame
/// or a point cloud fits many times over, and a corrupted length cannot make the decoder allocate
/// more than a small multiple of it.
inline constexpr size_t kMaxSampleBytes = size_t{256} << 20;
inline constexpr size_t kEncapsulationHeaderBytes = 4;

/// Types CdrWriter::Write / CdrReader::Read take: the ROS 2 primitives that have a fixed size.
template <class T>
concept CdrPrimitive = std::is_arithmetic_v<T> &&
    (sizeof(T) == 1 || sizeof(T) == 2 || sizeof(T) == 4 || sizeof(T) == 8);

/// Appends CDR to a growing byte buffer; starts with the encapsulation header.
class CdrWriter {
 public:
  explicit CdrWriter(Endianness endianness = Endianness::kLittle);

  /// Pads with zero bytes to a multiple of `n` bytes from the end of the encapsulation header.
  void Align(size_t n);

  /// One primitive, aligned to its size; `bool` as one byte 0 / 1.
  template <CdrPrimitive T>
  void Write(T value) {
    Align(sizeof(T));
    if constexpr (std::is_same_v<T, bool>) {
      bytes_.push_back(value ? 1 : 0);
    } else {
      AppendSwapped(&value, sizeof(T), 1);
    }
  }

  /// uint32 length (counting the NUL), the bytes, a NUL. @throws avp::Error past 4 GiB.
  void WriteString(std::string_view s);
  /// A sequence's uint32 element count. @throws avp::Error past UINT32_MAX elements.
  void WriteSequenceLength(size_t count);
  /// Consecutive primitives (the elements of a fixed array or of a sequence after its count),
  /// aligned to the element size when there is at least one.
  template <CdrPrimitive T>
  void WriteArray(std::span<const T> values) {
    if (values.empty()) return;
    if constexpr (std::is_same_v<T, bool>) {
      for (const bool b : values) Write(b);
    } else {
      Align(sizeof(T));
      AppendSwapped(values.data(), sizeof(T), values.size());
    }
  }

  Endianness endianness() const { return endianness_; }
  /// Bytes written so far, encapsulation header included.
  size_t size() const { return bytes_.size(); }
  const std::vector<uint8_t>& bytes() const& { return bytes_; }
  std::vector<uint8_t> Finish() && { return std::move(bytes_); }

 private:
  void AppendSwapped(const void* data, size_t element_size, size_t count);

  Endianness endianness_;
  std::vector<uint8_t> bytes_;
};

/// Reads CDR from a byte span it does not own. Every read checks the remaining bytes first and
/// returns an error Status naming what was read and the byte offset (counted from the sample's
/// first byte, the encapsulation header included); nothing is allocated before its size has been
/// checked against the bytes that remain. Accepts both byte orders (`00 01` and `00 00`) and
/// ignores the two option bytes and any trailing bytes, as CDR readers do.
class CdrReader {
 public:
  /// Checks the size cap and the encapsulation header: plain CDR in either byte order. Refuses
  /// parameter lists (PL_CDR) and XCDR2, which no ROS 2 RMW writes for final types.
  static Result<CdrReader> Open(std::span<const uint8_t> bytes);

  Status Align(size_t n);

  template <CdrPrimitive T>
  Status Read(T& out) {
    AVP_RETURN_IF_ERROR(Align(sizeof(T)));
    AVP_RETURN_IF_ERROR(Need(sizeof(T), PrimitiveName<T>()));
    if constexpr (std::is_same_v<T, bool>) {
      const uint8_t b = bytes_[offset_];
      if (b > 1) return BadBool(b);
      out = b == 1;
    } else {
      CopySwapped(&out, sizeof(T), 1);
    }
    offset_ += sizeof(T);
    return Status::Ok();
  }

  /// A string: its length is checked against the remaining bytes and `max_chars` (the bound of a
  /// `string<=N`, 0 = unbounded) before anything is copied; it must end in a NUL. A length of 0,
  /// which some old writers send for "", reads as "".
  Status ReadString(std::string& out, size_t max_chars = 0);

  /// A sequence's element count; refuses a count whose elements, at `min_element_bytes` each,
  /// cannot fit in the remaining bytes (or exceed `max_count` when that is not 0), so callers may
  /// reserve `count` elements of a primitive type.
  Status ReadSequenceLength(uint32_t& count, size_t min_element_bytes, std::string_view what,
                            size_t max_count = 0);

  /// `out.size()` consecutive primitives (aligned when there is at least one).
  template <CdrPrimitive T>
  Status ReadArray(std::span<T> out) {
    if (out.empty()) return Status::Ok();
    if constexpr (std::is_same_v<T, bool>) {
      for (bool& b : out) AVP_RETURN_IF_ERROR(Read(b));
      return Status::Ok();
    } else {
      AVP_RETURN_IF_ERROR(Align(sizeof(T)));
      AVP_RETURN_IF_ERROR(Need(out.size() * sizeof(T), PrimitiveName<T>()));
      CopySwapped(out.data(), sizeof(T), out.size());
      offset_ += out.size() * sizeof(T);
      return Status::Ok();
    }
  }

  Endianness endianness() const { return endianness_; }
  /// Offset of the next byte from the first byte of the sample.
  size_t offset() const { return offset_; }
  size_t remaining() const { return bytes_.size() - offset_; }

  /// "float64" for double, and so on: the ROS name of a primitive type, for messages.
  template <CdrPrimitive T>
  static constexpr std::string_view PrimitiveName() {
    if constexpr (std::is_same_v<T, bool>) return "bool";
    if constexpr (std::is_same_v<T, float>) return "float32";
    if constexpr (std::is_same_v<T, double>) return "float64";
    if constexpr (std::is_same_v<T, int8_t>) return "int8";
    if constexpr (std::is_same_v<T, uint8_t>) return "uint8";
    if constexpr (std::is_same_v<T, int16_t>) return "int16";
    if constexpr (std::is_same_v<T, uint16_t>) return "uint16";
    if constexpr (std::is_same_v<T, int32_t>) return "int32";
    if constexpr (std::is_same_v<T, uint32_t>) return "uint32";
    if constexpr (std::is_same_v<T, int64_t>) return "int64";
    if constexpr (std::is_same_v<T, uint64_t>) return "uint64";
    return "primitive";
  }

 private:
  CdrReader(std::span<const uint8_t> bytes, Endianness endianness)
      : bytes_(bytes), endianness_(endianness), offset_(kEncapsulationHeaderBytes) {}

  /// An error unless `n` bytes remain.
  Status Need(size_t n, std::string_view what) const;
  Status BadBool(uint8_t b) const;
  void CopySwapped(void* out, size_t element_size, size_t count) const;

  std::span<const uint8_t> bytes_;
  Endianness endianness_;
  size_t offset_;
};

}  // namespace avp::ros::msg
