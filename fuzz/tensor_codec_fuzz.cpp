// Fuzz target: the tensor codec as a client meets it: a serialized inference::ModelInferResponse
// (what a segmentation server, or anything pretending to be one, sends back) -> FromProto ->
// every output through CheckTensor, ReadBytesElements / ReadValues, every parameter through the
// typed getters -> DecodeSegmentation (segmentation_service/tensor.h, segmentation_codec.h).
// Property: a Segmentation that decodes is valid, and encoding it decodes to the same instances.

#include <cstddef>
#include <cstdint>
#include <string>

#include <google/protobuf/stubs/logging.h>

#include <avp/segmentation_service/segmentation_codec.h>
#include <avp/segmentation_service/tensor.h>

#include "fuzz_target.h"
#include "grpc_predict_v2.pb.h"
#include "proto_convert.h"

namespace {

using namespace avp::segmentation_service;

// protobuf logs every string field with invalid UTF-8 it parses: quiet, so that findings stand out.
void IgnoreProtobufLog(google::protobuf::LogLevel, const char*, int, const std::string&) {}
[[maybe_unused]] const bool kQuietProtobuf =
    (google::protobuf::SetLogHandler(&IgnoreProtobufLog), true);

void ReadTensor(const Tensor& t) {
  if (!CheckTensor(t, "output").ok()) return;
  switch (t.datatype) {
    case DataType::kBytes:
      (void)ReadBytesElements(t);
      break;
    case DataType::kBool:
    case DataType::kUint8:
      (void)ReadValues<uint8_t>(t);
      break;
    case DataType::kInt8:
      (void)ReadValues<int8_t>(t);
      break;
    case DataType::kUint16:
    case DataType::kFp16:
    case DataType::kBf16:
      (void)ReadValues<uint16_t>(t);
      break;
    case DataType::kInt16:
      (void)ReadValues<int16_t>(t);
      break;
    case DataType::kUint32:
      (void)ReadValues<uint32_t>(t);
      break;
    case DataType::kInt32:
      (void)ReadValues<int32_t>(t);
      break;
    case DataType::kFp32:
      (void)ReadValues<float>(t);
      break;
    case DataType::kUint64:
      (void)ReadValues<uint64_t>(t);
      break;
    case DataType::kInt64:
      (void)ReadValues<int64_t>(t);
      break;
    case DataType::kFp64:
      (void)ReadValues<double>(t);
      break;
  }
  // A datatype of the wrong element size must be refused, not read.
  if (ElementSize(t.datatype) != 4 && ReadValues<float>(t).ok()) {
    avp::fuzz::Fail("ReadValues<float> accepted " + t.Describe());
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  inference::ModelInferResponse proto;
  if (!proto.ParseFromArray(data, static_cast<int>(size))) return 0;
  avp::Result<InferResponse> response = internal::FromProto(proto);
  if (!response.ok()) return 0;
  for (const Tensor& t : response->outputs) {
    ReadTensor(t);
    (void)t.NumElements();
    (void)t.Describe();
  }
  for (const auto& [name, value] : response->parameters) {
    (void)GetDoubleParameter(response->parameters, name);
    (void)GetUint64Parameter(response->parameters, name);
    (void)GetInt64Parameter(response->parameters, name);
    (void)GetStringParameter(response->parameters, name);
  }
  avp::Result<avp::Segmentation> seg = DecodeSegmentation(*response);
  if (!seg.ok()) return 0;
  avp::Status valid = seg->Validate();
  if (!valid.ok()) avp::fuzz::Fail("a decoded segmentation does not validate: " + valid.ToString());
  avp::Result<InferResponse> encoded = EncodeSegmentation(*seg);
  if (!encoded.ok())
    avp::fuzz::Fail("a decoded segmentation does not encode: " + encoded.status().ToString());
  inference::ModelInferResponse wire;
  internal::ToProto(*encoded, &wire);
  avp::Result<InferResponse> back = internal::FromProto(wire);
  if (!back.ok()) avp::fuzz::Fail("an encoded response does not convert back");
  avp::Result<avp::Segmentation> again = DecodeSegmentation(*back);
  if (!again.ok() || again->instances.size() != seg->instances.size()) {
    avp::fuzz::Fail("encode -> decode changed the number of instances");
  }
  // The compact forms of the same masks decode to the same instance count.
  for (const MaskFormat f : {MaskFormat::kRle, MaskFormat::kInstanceIds}) {
    avp::Result<InferResponse> compact = EncodeSegmentation(*seg, f);
    if (!compact.ok()) {
      if (f == MaskFormat::kInstanceIds && seg->instances.size() > 65535) continue;
      avp::fuzz::Fail("a decoded segmentation does not encode compactly: " +
                      compact.status().ToString());
    }
    avp::Result<avp::Segmentation> c = DecodeSegmentation(*compact);
    if (!c.ok() || c->instances.size() != seg->instances.size()) {
      avp::fuzz::Fail("compact encode -> decode changed the number of instances");
    }
  }
  return 0;
}
