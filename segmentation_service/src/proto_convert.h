#pragma once

// Conversions between the protobuf messages of grpc_predict_v2.proto and avp's protobuf-free
// InferRequest / InferResponse, and between gRPC and avp statuses. Private to avp_interop.

#include <string_view>
#include <vector>

#include <grpcpp/support/status.h>

#include <avp/core/status.h>
#include <avp/segmentation_service/segmentation_codec.h>  // TensorSpec
#include <avp/segmentation_service/tensor.h>

#include "grpc_predict_v2.pb.h"

namespace avp::segmentation_service::internal {

/// Moves the tensors' bytes into raw_input_contents (one entry per input, in order).
void ToProto(InferRequest request, inference::ModelInferRequest* out);
/// Inputs from raw_input_contents, or from each input's typed `contents` when there are no raw
/// contents. InvalidArgument naming the tensor: unknown datatype, raw contents whose count
/// differs from the inputs', raw and typed contents mixed, typed contents of the wrong field or
/// count, values out of the datatype's range.
Result<InferRequest> FromProto(const inference::ModelInferRequest& request);

void ToProto(InferResponse response, inference::ModelInferResponse* out);
/// As FromProto for requests, for outputs and raw_output_contents.
Result<InferResponse> FromProto(const inference::ModelInferResponse& response);

/// Parameters both ways; parameters with no value set are skipped.
Parameters FromProto(const google::protobuf::Map<std::string, inference::InferParameter>& in);
void ToProto(const Parameters& in,
             google::protobuf::Map<std::string, inference::InferParameter>* out);

/// "host:port", an IPv6 host in brackets ("[::1]:8001"): the address gRPC listens on or dials.
std::string HostPort(const std::string& host, int port);

/// Whether a server can listen on (host, port), asked of the system before gRPC is (whose own
/// failure is a raw log line): `host` must resolve (getaddrinfo) and one of its addresses bind.
/// InvalidArgument naming `who` and the host that does not resolve, IoError naming the address and
/// the system's reason (address in use, not an address of this machine).
Status CheckCanListen(std::string_view who, const std::string& host, int port);

/// A ModelMetadata response's inputs and outputs. InvalidArgument "<who>: ModelMetadata lists
/// tensor 'x' with unknown datatype 'Y'".
Status TensorSpecsFromProto(const google::protobuf::RepeatedPtrField<
                                inference::ModelMetadataResponse::TensorMetadata>& tensors,
                            std::string_view who, std::vector<TensorSpec>* out);

/// avp status -> gRPC status: InvalidArgument/ParseError -> INVALID_ARGUMENT, NotFound ->
/// NOT_FOUND, FailedPrecondition -> FAILED_PRECONDITION, OutOfRange -> OUT_OF_RANGE, the rest ->
/// INTERNAL; the message is kept.
grpc::Status ToGrpcStatus(const Status& status);

}  // namespace avp::segmentation_service::internal
