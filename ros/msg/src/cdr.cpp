#include "avp/ros/msg/cdr.h"

#include <algorithm>
#include <limits>

#include <fmt/format.h>

#include <avp/core/error.h>

namespace avp::ros::msg {
namespace {

constexpr bool kHostLittle = std::endian::native == std::endian::little;

bool NeedsSwap(Endianness e) { return (e == Endianness::kLittle) != kHostLittle; }

void SwapInPlace(uint8_t* p, size_t element_size, size_t count) {
  for (size_t i = 0; i < count; ++i, p += element_size) std::reverse(p, p + element_size);
}

}  // namespace

// ---- CdrWriter ---------------------------------------------------------------------------------

CdrWriter::CdrWriter(Endianness endianness) : endianness_(endianness) {
  bytes_ = {0x00, static_cast<uint8_t>(endianness == Endianness::kLittle ? 0x01 : 0x00), 0x00,
            0x00};
}

void CdrWriter::Align(size_t n) {
  const size_t pos = bytes_.size() - kEncapsulationHeaderBytes;
  const size_t pad = (n - pos % n) % n;
  bytes_.insert(bytes_.end(), pad, 0);
}

void CdrWriter::AppendSwapped(const void* data, size_t element_size, size_t count) {
  const size_t start = bytes_.size();
  const auto* p = static_cast<const uint8_t*>(data);
  bytes_.insert(bytes_.end(), p, p + element_size * count);
  if (element_size > 1 && NeedsSwap(endianness_)) {
    SwapInPlace(bytes_.data() + start, element_size, count);
  }
}

void CdrWriter::WriteString(std::string_view s) {
  AVP_THROW_UNLESS(s.size() < std::numeric_limits<uint32_t>::max(), s.size());
  Write(static_cast<uint32_t>(s.size() + 1));
  bytes_.insert(bytes_.end(), s.begin(), s.end());
  bytes_.push_back(0);
}

void CdrWriter::WriteSequenceLength(size_t count) {
  AVP_THROW_UNLESS(count <= std::numeric_limits<uint32_t>::max(), count);
  Write(static_cast<uint32_t>(count));
}

// ---- CdrReader ---------------------------------------------------------------------------------

Result<CdrReader> CdrReader::Open(std::span<const uint8_t> bytes) {
  if (bytes.size() > kMaxSampleBytes) {
    return InvalidArgumentError(
        fmt::format("sample of {} bytes exceeds the cap of {} bytes (kMaxSampleBytes)",
                    bytes.size(), kMaxSampleBytes));
  }
  if (bytes.size() < kEncapsulationHeaderBytes) {
    return InvalidArgumentError(fmt::format(
        "sample of {} bytes is shorter than the 4-byte encapsulation header", bytes.size()));
  }
  const uint16_t kind = static_cast<uint16_t>((bytes[0] << 8) | bytes[1]);
  switch (kind) {
    case 0x0000:
      return CdrReader(bytes, Endianness::kBig);
    case 0x0001:
      return CdrReader(bytes, Endianness::kLittle);
    case 0x0002:
    case 0x0003:
      return InvalidArgumentError(fmt::format(
          "encapsulation {:02x} {:02x} is a parameter list (PL_CDR); ROS 2 topics use plain CDR "
          "(00 01 little-endian, 00 00 big-endian)",
          bytes[0], bytes[1]));
    case 0x0006:
    case 0x0007:
    case 0x0008:
    case 0x0009:
    case 0x000a:
    case 0x000b:
      return InvalidArgumentError(fmt::format(
          "encapsulation {:02x} {:02x} is XCDR2, which ROS 2 does not use for its final types; "
          "only plain CDR (XCDR1: 00 01 little-endian, 00 00 big-endian) is read",
          bytes[0], bytes[1]));
    default:
      return InvalidArgumentError(fmt::format(
          "unknown encapsulation {:02x} {:02x}; expected plain CDR (00 01 little-endian, 00 00 "
          "big-endian)",
          bytes[0], bytes[1]));
  }
}

Status CdrReader::Need(size_t n, std::string_view what) const {
  if (n <= remaining()) return Status::Ok();
  return InvalidArgumentError(fmt::format("{} of {} bytes at offset {} exceeds the {} remaining",
                                          what, n, offset_, remaining()));
}

Status CdrReader::BadBool(uint8_t b) const {
  return InvalidArgumentError(
      fmt::format("bool at offset {} is {}, not 0 or 1", offset_, static_cast<int>(b)));
}

Status CdrReader::Align(size_t n) {
  const size_t pos = offset_ - kEncapsulationHeaderBytes;
  const size_t pad = (n - pos % n) % n;
  if (pad > remaining()) {
    return InvalidArgumentError(
        fmt::format("alignment padding of {} bytes at offset {} exceeds "
                    "the {} remaining",
                    pad, offset_, remaining()));
  }
  offset_ += pad;
  return Status::Ok();
}

void CdrReader::CopySwapped(void* out, size_t element_size, size_t count) const {
  std::memcpy(out, bytes_.data() + offset_, element_size * count);
  if (element_size > 1 && NeedsSwap(endianness_)) {
    SwapInPlace(static_cast<uint8_t*>(out), element_size, count);
  }
}

Status CdrReader::ReadString(std::string& out, size_t max_chars) {
  uint32_t length = 0;
  AVP_RETURN_IF_ERROR(Read(length));
  const size_t start = offset_ - 4;
  if (length > remaining()) {
    return InvalidArgumentError(fmt::format(
        "string of {} bytes at offset {} exceeds the {} remaining", length, start, remaining()));
  }
  if (length == 0) {
    out.clear();
    return Status::Ok();
  }
  if (max_chars != 0 && length - 1 > max_chars) {
    return InvalidArgumentError(
        fmt::format("string of {} characters at offset {} exceeds its bound of {}", length - 1,
                    start, max_chars));
  }
  const uint8_t* p = bytes_.data() + offset_;
  if (p[length - 1] != 0) {
    return InvalidArgumentError(
        fmt::format("string of {} bytes at offset {} does not end in a NUL byte", length, start));
  }
  out.assign(reinterpret_cast<const char*>(p), length - 1);
  offset_ += length;
  return Status::Ok();
}

Status CdrReader::ReadSequenceLength(uint32_t& count, size_t min_element_bytes,
                                     std::string_view what, size_t max_count) {
  uint32_t n = 0;
  AVP_RETURN_IF_ERROR(Read(n));
  const size_t start = offset_ - 4;
  if (max_count != 0 && n > max_count) {
    return InvalidArgumentError(fmt::format(
        "sequence of {} {} at offset {} exceeds its bound of {}", n, what, start, max_count));
  }
  // 64-bit arithmetic: n < 2^32 and min_element_bytes is a small constant.
  const uint64_t needed = uint64_t{n} * min_element_bytes;
  if (needed > remaining()) {
    if (min_element_bytes == 1) {
      return InvalidArgumentError(
          fmt::format("sequence of {} {} at offset {} exceeds the {} "
                      "remaining",
                      n, what, start, remaining()));
    }
    return InvalidArgumentError(
        fmt::format("sequence of {} {} (at least {} bytes) at offset {} exceeds the {} remaining",
                    n, what, needed, start, remaining()));
  }
  count = n;
  return Status::Ok();
}

}  // namespace avp::ros::msg
