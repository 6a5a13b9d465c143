#pragma once
// Internal to avp_zsl: a network on a KServe v2 / Open Inference Protocol server (avp serve
// models, Triton, OpenVINO Model Server, KServe), run through segmentation_service::TensorClient
// with the tensors the in-process OrtModel takes and gives (docs/zero-shot-models.md, "The networks
// on an inference server").

#include <memory>
#include <string>
#include <string_view>

#include <avp/core/status.h>
#include <avp/segmentation_service/tensor.h>
#include <avp/segmentation_service/tensor_service.h>

#include "ort_runtime.h"

namespace avp::zsl {

/// The model `model` of the server at `server` ("grpc://HOST:PORT"), labelled `label` (its
/// manifest role; `model` when empty) in errors.
/// Reads its ModelMetadata once (the I/O the contracts are checked against). Errors: the address
/// (InvalidArgument), a server that cannot be reached (Unavailable), no such model (NotFound), a
/// datatype avp does not use (InvalidArgument); each names the model and the server.
Result<ModelRef> ConnectRemoteModel(std::string_view server, const std::string& model,
                                    const std::string& label = "", double deadline_s = 60.0);

/// A network run in this process through `handler` (e.g. an segmentation_service::BatchingHandler
/// in front of an OrtModel), with the same tensor conversions as a remote one; `io` and `provider`
/// are the network's own. Thread-safe as `handler` is.
ModelRef HandlerModel(std::shared_ptr<const segmentation_service::TensorModelHandler> handler,
                      std::string label, ModelIo io, std::string provider);

/// KServe datatype <-> ONNX element type (FP32 <-> float32, INT64 <-> int64, INT32, BOOL, FP16,
/// FP64, UINT8, INT8, INT16). kOther / kUndefined for the rest, nullopt the other way.
ElementType ElementTypeOf(segmentation_service::DataType datatype);
std::optional<segmentation_service::DataType> DataTypeOf(ElementType type);

/// An input as the wire carries it (little-endian, row-major; bool as one byte).
Result<segmentation_service::Tensor> ToWire(const InputTensor& input);
/// An output as OrtModel::Run gives it: FP32 into f32; INT64, INT32 and BOOL into i64 (bool 0/1).
/// InvalidArgument naming the tensor for another datatype or contents that do not fill the shape.
Result<OutputTensor> FromWire(const segmentation_service::Tensor& tensor);
/// The other way, for a server: f32 as FP32, i64 as INT64 / INT32 / BOOL after `type`.
Result<segmentation_service::Tensor> ToWire(const OutputTensor& output);

}  // namespace avp::zsl
