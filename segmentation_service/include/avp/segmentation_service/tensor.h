#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

#include <avp/core/status.h>

namespace avp::segmentation_service {

/// The tensor element types of the Open Inference Protocol (KServe v2), by their wire names
/// ("BOOL", "UINT8", ..., "FP32", "FP64", "BYTES").
enum class DataType : uint8_t {
  kBool,
  kUint8,
  kUint16,
  kUint32,
  kUint64,
  kInt8,
  kInt16,
  kInt32,
  kInt64,
  kFp16,
  kFp32,
  kFp64,
  kBf16,
  kBytes,
};

/// The wire name: "BOOL", "UINT8", "UINT16", "UINT32", "UINT64", "INT8", "INT16", "INT32",
/// "INT64", "FP16", "FP32", "FP64", "BF16", "BYTES".
std::string_view ToString(DataType datatype);
/// Inverse of ToString (case-sensitive, as the protocol); nullopt for other names.
std::optional<DataType> DataTypeFromString(std::string_view name);
/// Bytes per element in raw contents; 0 for BYTES (variable length).
size_t ElementSize(DataType datatype);

/// "[480, 640, 3]".
std::string ShapeToString(std::span<const int64_t> shape);

/// One tensor as it crosses the wire, independent of protobuf and gRPC: a name, a datatype, a
/// shape and the raw contents: little-endian, row-major, and for BYTES each element preceded
/// by its length as a 4-byte little-endian unsigned integer.
struct Tensor {
  std::string name;
  DataType datatype = DataType::kUint8;
  std::vector<int64_t> shape;
  std::string data;

  /// Product of the shape (1 for a scalar of shape []); nullopt when a dimension is negative or
  /// the product exceeds 2^40.
  std::optional<int64_t> NumElements() const;
  /// "'rgb' UINT8 [480, 640, 3]".
  std::string Describe() const;

  friend bool operator==(const Tensor&, const Tensor&) = default;
};

/// A request or response parameter (InferParameter): bool, int64, uint64, double or string.
using ParameterValue = std::variant<bool, int64_t, uint64_t, double, std::string>;
using Parameters = std::map<std::string, ParameterValue, std::less<>>;

/// An inference request (ModelInferRequest) without protobuf.
struct InferRequest {
  std::string model_name;
  std::string model_version;
  std::string id;
  Parameters parameters;
  std::vector<Tensor> inputs;
  /// Names of the outputs the client wants; empty = all.
  std::vector<std::string> requested_outputs;

  /// The input named `name`, or nullptr.
  const Tensor* FindInput(std::string_view name) const;
  friend bool operator==(const InferRequest&, const InferRequest&) = default;
};

/// An inference response (ModelInferResponse) without protobuf.
struct InferResponse {
  std::string model_name;
  std::string model_version;
  std::string id;
  Parameters parameters;
  std::vector<Tensor> outputs;

  /// The output named `name`, or nullptr.
  const Tensor* FindOutput(std::string_view name) const;
  friend bool operator==(const InferResponse&, const InferResponse&) = default;
};

/// A tensor of fixed-size elements from host values (little-endian on the wire).
template <typename T>
Tensor MakeTensor(std::string name, DataType datatype, std::vector<int64_t> shape,
                  std::span<const T> values);
/// A BYTES tensor of shape [elements.size()].
Tensor MakeBytesTensor(std::string name, const std::vector<std::string>& elements);

/// The elements of a BYTES tensor; InvalidArgument naming the tensor when a length prefix runs
/// past the end, bytes are left over, or the count differs from the shape.
Result<std::vector<std::string>> ReadBytesElements(const Tensor& tensor);

/// Checks the datatype and that the contents hold exactly the shape's elements (for BYTES: that
/// the elements parse and their count matches). InvalidArgument naming the tensor, e.g. "input
/// 'depth': shape [4, 4] of FP32 needs 64 bytes, got 60".
Status CheckTensor(const Tensor& tensor, std::string_view role);

/// Copies a fixed-size-element tensor's contents into host values. The datatype must have
/// sizeof(T) bytes per element (checked: InvalidArgument naming the tensor).
template <typename T>
Result<std::vector<T>> ReadValues(const Tensor& tensor);

// ---- parameters ---------------------------------------------------------------------------------

/// A parameter as a double: double, int64 or uint64 values, or a decimal string. nullopt when
/// absent; InvalidArgument naming it when of another type or not a number.
Result<std::optional<double>> GetDoubleParameter(const Parameters& parameters,
                                                 std::string_view name);
/// A parameter as an unsigned 64-bit integer: uint64; int64 (read as the same 64 bits, so a
/// client without uint64 parameters can send any value); or a decimal string.
Result<std::optional<uint64_t>> GetUint64Parameter(const Parameters& parameters,
                                                   std::string_view name);
/// A signed 64-bit integer: int64, uint64 up to 2^63 - 1, or a decimal string.
Result<std::optional<int64_t>> GetInt64Parameter(const Parameters& parameters,
                                                 std::string_view name);
/// A string parameter.
Result<std::optional<std::string>> GetStringParameter(const Parameters& parameters,
                                                      std::string_view name);

// ---- template definitions -----------------------------------------------------------------------

namespace internal {
/// Copies n elements of `size` bytes, swapping to or from little-endian on big-endian hosts.
void CopyLittleEndian(void* dst, const void* src, size_t n, size_t size);
}  // namespace internal

template <typename T>
Tensor MakeTensor(std::string name, DataType datatype, std::vector<int64_t> shape,
                  std::span<const T> values) {
  static_assert(std::is_trivially_copyable_v<T>);
  Tensor t;
  t.name = std::move(name);
  t.datatype = datatype;
  t.shape = std::move(shape);
  t.data.resize(values.size() * sizeof(T));
  if (!values.empty()) {
    internal::CopyLittleEndian(t.data.data(), values.data(), values.size(), sizeof(T));
  }
  return t;
}

template <typename T>
Result<std::vector<T>> ReadValues(const Tensor& tensor) {
  static_assert(std::is_trivially_copyable_v<T>);
  if (ElementSize(tensor.datatype) != sizeof(T) || tensor.data.size() % sizeof(T) != 0) {
    return InvalidArgumentError("tensor " + tensor.Describe() + " holds " +
                                std::to_string(tensor.data.size()) + " bytes, not elements of " +
                                std::to_string(sizeof(T)) + " bytes");
  }
  std::vector<T> out(tensor.data.size() / sizeof(T));
  if (!out.empty())
    internal::CopyLittleEndian(out.data(), tensor.data.data(), out.size(), sizeof(T));
  return out;
}

}  // namespace avp::segmentation_service
