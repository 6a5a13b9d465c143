// Fuzz target: the request path of the segmentation service, as SegmentationServer's ModelInfer
// runs it on a worker: a serialized inference::ModelInferRequest -> FromProto ->
// DecodeSegmentationRequest (every tensor, parameter and image checked and decoded) -> the
// requested outputs checked -> a cheap backend ("color", or "oracle" when the model name says so
// and simulator labels came with the request) -> EncodeSegmentation -> the response as protobuf.
// Property: a request that decodes is segmented without error by "color" and "oracle" (when it
// has labels), the result is valid for the frame, and its response encodes and decodes again.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include <google/protobuf/stubs/logging.h>

#include <avp/segmentation/segmenter_registry.h>
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

const avp::segmentation::SegmenterRegistry& Registry() {
  static const auto* registry =
      new avp::segmentation::SegmenterRegistry(avp::segmentation::BuiltinSegmenters());
  return *registry;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  inference::ModelInferRequest proto;
  if (!proto.ParseFromArray(data, static_cast<int>(size))) return 0;
  avp::Result<InferRequest> request = internal::FromProto(proto);
  if (!request.ok()) return 0;
  avp::Result<DecodedSegmentationRequest> decoded = DecodeSegmentationRequest(*request);
  if (!decoded.ok()) return 0;
  const auto& outs = SegmentationOutputs();
  for (const std::string& name : request->requested_outputs) {
    if (std::none_of(outs.begin(), outs.end(),
                     [&](const TensorSpec& s) { return s.name == name; })) {
      return 0;  // INVALID_ARGUMENT on the server
    }
  }
  const bool oracle = request->model_name.starts_with("oracle") && decoded->labels.has_value();
  const std::string backend =
      oracle ? request->model_name == "oracle-perfect" ? "oracle-perfect" : "oracle" : "color";
  auto segmenter = Registry().Make(backend, decoded->seed.value_or(0));
  if (!segmenter.ok()) avp::fuzz::Fail("cannot build " + backend);
  const avp::segmentation::SegmentationRequest req = decoded->request();
  avp::Result<avp::Segmentation> seg = (*segmenter)->Segment(req);
  if (!seg.ok()) {
    // The backends refuse what they cannot use (e.g. a prompt naming no class they know); that
    // is an answer, not a fault. Everything else must have been refused by the decoder.
    if (seg.status().code() == avp::StatusCode::kInvalidArgument ||
        seg.status().code() == avp::StatusCode::kResourceExhausted) {
      return 0;
    }
    avp::fuzz::Fail(backend + " failed on a decoded request: " + seg.status().ToString());
  }
  avp::Status valid = seg->ValidateFor(decoded->frame.rgb.width(), decoded->frame.rgb.height());
  if (!valid.ok())
    avp::fuzz::Fail(backend + " returned an invalid segmentation: " + valid.ToString());
  avp::Result<InferResponse> response = EncodeSegmentation(*seg, decoded->mask_format);
  if (!response.ok())
    avp::fuzz::Fail("the segmentation does not encode: " + response.status().ToString());
  inference::ModelInferResponse wire;
  internal::ToProto(*response, &wire);
  std::string bytes;
  if (!wire.SerializeToString(&bytes)) avp::fuzz::Fail("the response does not serialize");
  inference::ModelInferResponse parsed;
  if (!parsed.ParseFromString(bytes)) avp::fuzz::Fail("the response does not parse");
  avp::Result<InferResponse> back = internal::FromProto(parsed);
  if (!back.ok() || !DecodeSegmentation(*back).ok()) {
    avp::fuzz::Fail("the response does not decode on the client");
  }
  return 0;
}
