#include <algorithm>
#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <utility>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/segmentation_service/tensor.h>

namespace avp::segmentation_service {

namespace {

struct DataTypeInfo {
  DataType datatype;
  std::string_view name;
  size_t size;
};

constexpr std::array<DataTypeInfo, 14> kDataTypes = {{
    {DataType::kBool, "BOOL", 1},
    {DataType::kUint8, "UINT8", 1},
    {DataType::kUint16, "UINT16", 2},
    {DataType::kUint32, "UINT32", 4},
    {DataType::kUint64, "UINT64", 8},
    {DataType::kInt8, "INT8", 1},
    {DataType::kInt16, "INT16", 2},
    {DataType::kInt32, "INT32", 4},
    {DataType::kInt64, "INT64", 8},
    {DataType::kFp16, "FP16", 2},
    {DataType::kFp32, "FP32", 4},
    {DataType::kFp64, "FP64", 8},
    {DataType::kBf16, "BF16", 2},
    {DataType::kBytes, "BYTES", 0},
}};

constexpr int64_t kMaxElements = int64_t{1} << 40;

uint32_t ReadU32Le(const char* p) {
  uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<uint8_t>(p[i]);
  return v;
}

void AppendU32Le(std::string& out, uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}

std::string DescribeParameter(const ParameterValue& value) {
  return std::visit(
      [](const auto& v) -> std::string {
        using V = std::decay_t<decltype(v)>;
        if constexpr (std::is_same_v<V, bool>) return fmt::format("bool {}", v);
        if constexpr (std::is_same_v<V, int64_t>) return fmt::format("int64 {}", v);
        if constexpr (std::is_same_v<V, uint64_t>) return fmt::format("uint64 {}", v);
        if constexpr (std::is_same_v<V, double>) return fmt::format("double {}", v);
        if constexpr (std::is_same_v<V, std::string>) return fmt::format("string \"{}\"", v);
      },
      value);
}

template <typename T>
std::optional<T> ParseInteger(std::string_view s) {
  T v{};
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size()) return std::nullopt;
  return v;
}

const ParameterValue* Find(const Parameters& parameters, std::string_view name) {
  const auto it = parameters.find(name);
  return it == parameters.end() ? nullptr : &it->second;
}

}  // namespace

std::string_view ToString(DataType datatype) {
  for (const DataTypeInfo& info : kDataTypes) {
    if (info.datatype == datatype) return info.name;
  }
  return "UNKNOWN";
}

std::optional<DataType> DataTypeFromString(std::string_view name) {
  for (const DataTypeInfo& info : kDataTypes) {
    if (info.name == name) return info.datatype;
  }
  return std::nullopt;
}

size_t ElementSize(DataType datatype) {
  for (const DataTypeInfo& info : kDataTypes) {
    if (info.datatype == datatype) return info.size;
  }
  return 0;
}

std::string ShapeToString(std::span<const int64_t> shape) {
  return fmt::format("[{}]", fmt::join(shape, ", "));
}

std::optional<int64_t> Tensor::NumElements() const {
  int64_t n = 1;
  for (const int64_t d : shape) {
    if (d < 0) return std::nullopt;
    if (d != 0 && n > kMaxElements / d) return std::nullopt;
    n *= d;
  }
  return n;
}

std::string Tensor::Describe() const {
  return fmt::format("'{}' {} {}", name, ToString(datatype), ShapeToString(shape));
}

const Tensor* InferRequest::FindInput(std::string_view name) const {
  for (const Tensor& t : inputs) {
    if (t.name == name) return &t;
  }
  return nullptr;
}

const Tensor* InferResponse::FindOutput(std::string_view name) const {
  for (const Tensor& t : outputs) {
    if (t.name == name) return &t;
  }
  return nullptr;
}

Tensor MakeBytesTensor(std::string name, const std::vector<std::string>& elements) {
  Tensor t;
  t.name = std::move(name);
  t.datatype = DataType::kBytes;
  t.shape = {static_cast<int64_t>(elements.size())};
  size_t total = 0;
  for (const std::string& e : elements) total += 4 + e.size();
  t.data.reserve(total);
  for (const std::string& e : elements) {
    AppendU32Le(t.data, static_cast<uint32_t>(e.size()));
    t.data += e;
  }
  return t;
}

Result<std::vector<std::string>> ReadBytesElements(const Tensor& tensor) {
  if (tensor.datatype != DataType::kBytes) {
    return InvalidArgumentError(
        fmt::format("tensor {}: expected BYTES elements", tensor.Describe()));
  }
  const std::optional<int64_t> n = tensor.NumElements();
  if (!n) {
    return InvalidArgumentError(
        fmt::format("tensor {}: the shape has a negative or huge dimension", tensor.Describe()));
  }
  std::vector<std::string> out;
  size_t pos = 0;
  const std::string& d = tensor.data;
  while (pos < d.size()) {
    if (d.size() - pos < 4) {
      return InvalidArgumentError(
          fmt::format("tensor {}: element {} has a truncated 4-byte length prefix ({} bytes left)",
                      tensor.Describe(), out.size(), d.size() - pos));
    }
    const uint32_t len = ReadU32Le(d.data() + pos);
    pos += 4;
    if (len > d.size() - pos) {
      return InvalidArgumentError(
          fmt::format("tensor {}: element {} claims {} bytes but only {} are left",
                      tensor.Describe(), out.size(), len, d.size() - pos));
    }
    out.emplace_back(d.data() + pos, len);
    pos += len;
  }
  if (static_cast<int64_t>(out.size()) != *n) {
    return InvalidArgumentError(
        fmt::format("tensor {}: the shape needs {} BYTES elements, the contents hold {}",
                    tensor.Describe(), *n, out.size()));
  }
  return out;
}

Status CheckTensor(const Tensor& tensor, std::string_view role) {
  const std::optional<int64_t> n = tensor.NumElements();
  if (!n) {
    return InvalidArgumentError(
        fmt::format("{} {}: the shape has a negative or huge dimension", role, tensor.Describe()));
  }
  if (tensor.datatype == DataType::kBytes) {
    return ReadBytesElements(tensor).status().WithContext(role);
  }
  const size_t need = static_cast<size_t>(*n) * ElementSize(tensor.datatype);
  if (tensor.data.size() != need) {
    return InvalidArgumentError(fmt::format("{} '{}': shape {} of {} needs {} bytes, got {}", role,
                                            tensor.name, ShapeToString(tensor.shape),
                                            ToString(tensor.datatype), need, tensor.data.size()));
  }
  return Status::Ok();
}

namespace internal {

void CopyLittleEndian(void* dst, const void* src, size_t n, size_t size) {
  if constexpr (std::endian::native == std::endian::little) {
    std::memcpy(dst, src, n * size);
  } else {
    auto* d = static_cast<unsigned char*>(dst);
    const auto* s = static_cast<const unsigned char*>(src);
    for (size_t i = 0; i < n; ++i) {
      for (size_t b = 0; b < size; ++b) d[i * size + b] = s[i * size + (size - 1 - b)];
    }
  }
}

}  // namespace internal

// ---- parameters ---------------------------------------------------------------------------------

Result<std::optional<double>> GetDoubleParameter(const Parameters& parameters,
                                                 std::string_view name) {
  const ParameterValue* p = Find(parameters, name);
  if (p == nullptr) return std::optional<double>();
  if (const auto* d = std::get_if<double>(p)) return std::optional<double>(*d);
  if (const auto* i = std::get_if<int64_t>(p)) {
    return std::optional<double>(static_cast<double>(*i));
  }
  if (const auto* u = std::get_if<uint64_t>(p)) {
    return std::optional<double>(static_cast<double>(*u));
  }
  if (const auto* s = std::get_if<std::string>(p)) {
    // std::from_chars for double is in GCC 11+; strtod would depend on the locale.
    double v = 0.0;
    const auto [end, ec] = std::from_chars(s->data(), s->data() + s->size(), v);
    if (ec == std::errc() && end == s->data() + s->size()) return std::optional<double>(v);
  }
  return InvalidArgumentError(
      fmt::format("parameter '{}' ({}) must be a number", name, DescribeParameter(*p)));
}

Result<std::optional<uint64_t>> GetUint64Parameter(const Parameters& parameters,
                                                   std::string_view name) {
  const ParameterValue* p = Find(parameters, name);
  if (p == nullptr) return std::optional<uint64_t>();
  if (const auto* u = std::get_if<uint64_t>(p)) return std::optional<uint64_t>(*u);
  if (const auto* i = std::get_if<int64_t>(p)) {
    return std::optional<uint64_t>(std::bit_cast<uint64_t>(*i));
  }
  if (const auto* s = std::get_if<std::string>(p)) {
    if (const auto v = ParseInteger<uint64_t>(*s)) return std::optional<uint64_t>(*v);
  }
  return InvalidArgumentError(fmt::format(
      "parameter '{}' ({}) must be an unsigned 64-bit integer (uint64, int64 holding its 64 "
      "bits, or a decimal string)",
      name, DescribeParameter(*p)));
}

Result<std::optional<int64_t>> GetInt64Parameter(const Parameters& parameters,
                                                 std::string_view name) {
  const ParameterValue* p = Find(parameters, name);
  if (p == nullptr) return std::optional<int64_t>();
  if (const auto* i = std::get_if<int64_t>(p)) return std::optional<int64_t>(*i);
  if (const auto* u = std::get_if<uint64_t>(p)) {
    if (*u <= static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) {
      return std::optional<int64_t>(static_cast<int64_t>(*u));
    }
  }
  if (const auto* s = std::get_if<std::string>(p)) {
    if (const auto v = ParseInteger<int64_t>(*s)) return std::optional<int64_t>(*v);
  }
  return InvalidArgumentError(fmt::format("parameter '{}' ({}) must be a signed 64-bit integer",
                                          name, DescribeParameter(*p)));
}

Result<std::optional<std::string>> GetStringParameter(const Parameters& parameters,
                                                      std::string_view name) {
  const ParameterValue* p = Find(parameters, name);
  if (p == nullptr) return std::optional<std::string>();
  if (const auto* s = std::get_if<std::string>(p)) return std::optional<std::string>(*s);
  return InvalidArgumentError(
      fmt::format("parameter '{}' ({}) must be a string", name, DescribeParameter(*p)));
}

}  // namespace avp::segmentation_service
