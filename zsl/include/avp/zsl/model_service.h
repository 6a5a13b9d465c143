#pragma once
// `avp serve models`: the ONNX networks of a model directory (its manifest.json) served through
// ONNX Runtime over KServe v2 / the Open Inference Protocol (gRPC), each model named by its
// manifest role ("detector", "text", "segmenter.encoder", "segmenter.decoder", "grounding"), so
// that ywes and lsam can run them remotely (RuntimeOptions::model_server) as they would on
// Triton (docs/zero-shot-models.md, "The networks on an inference server").

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <avp/core/status.h>
#include <avp/segmentation_service/tensor_service.h>
#include <avp/zsl/zsl.h>

namespace avp::zsl {

struct ModelServiceOptions {
  segmentation_service::TensorServerOptions server;
  /// The sessions' device and threads (model_server must be empty: a server runs its own).
  RuntimeOptions runtime;
  /// Check each file's sha256 against the manifest before loading it.
  bool verify_sha256 = false;
};

/// A running model service and what it serves.
struct ModelService {
  std::unique_ptr<segmentation_service::TensorServer> server;
  struct Served {
    std::string name;      ///< the role
    std::string provider;  ///< where it runs ("CPUExecutionProvider")
    std::string io;        ///< "inputs 'images' FP32 [1, 3, 640, 640], ...; outputs ..."
  };
  /// The models served, in role order.
  std::vector<Served> models;
};

/// Reads `model_dir`/manifest.json, loads every model it lists (sizes and, on request, sha256
/// checked) and serves them. Errors: the manifest's (NotFound, ParseError, InvalidArgument naming
/// the field), a model that does not load (naming its role and file), the server's
/// (InvalidArgument for options, IoError when it cannot listen); FailedPrecondition in a build
/// without ONNX Runtime.
Result<ModelService> ServeModels(const std::filesystem::path& model_dir,
                                 const ModelServiceOptions& options);

}  // namespace avp::zsl
