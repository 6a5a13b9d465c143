#pragma once
// Internal to avp_zsl: an OrtModel as an segmentation_service::TensorModelHandler (KServe v2
// tensors in and out), which `avp serve models` serves and the in-process batching
// (LoadBatchedOrtModel) puts an segmentation_service::BatchingHandler in front of.

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <avp/core/status.h>
#include <avp/segmentation_service/tensor_service.h>

#include "ort_runtime.h"

namespace avp::zsl {

/// One ONNX network as a tensor model handler, named `name`.
class OrtModelHandler final : public segmentation_service::TensorModelHandler {
 public:
  /// Errors: InvalidArgument naming a tensor whose element type has no KServe datatype.
  static Result<std::shared_ptr<const OrtModelHandler>> Make(std::string name,
                                                             std::shared_ptr<const OrtModel> model);

  const std::string& name() const override { return name_; }
  std::string platform() const override { return "onnxruntime_onnx"; }
  const std::vector<segmentation_service::TensorSpec>& inputs() const override { return inputs_; }
  const std::vector<segmentation_service::TensorSpec>& outputs() const override { return outputs_; }
  const OrtModel& model() const { return *model_; }
  const std::shared_ptr<const OrtModel>& shared_model() const { return model_; }

  /// Runs the model on FP32, INT64 and BOOL inputs (checked against inputs() by the caller:
  /// datatype, rank, static dimensions, a size that fills the shape).
  Result<segmentation_service::InferResponse> Infer(
      const segmentation_service::InferRequest& request) const override;

 private:
  OrtModelHandler(std::string name, std::shared_ptr<const OrtModel> model)
      : name_(std::move(name)), model_(std::move(model)) {}
  std::string name_;
  std::shared_ptr<const OrtModel> model_;
  std::vector<segmentation_service::TensorSpec> inputs_, outputs_;
};

/// LoadOrtModel with dynamic batching (options.batching.max_batch > 1): a network whose inputs
/// and outputs all have a dynamic leading axis is loaded once per process for a file and its
/// settings, and every caller gets the same batched model while any of them holds it, so that
/// concurrent calls from several backend instances stack (segmentation_service::BatchingHandler).
/// Any other network is loaded as LoadOrtModel does, for the caller alone.
Result<ModelRef> LoadBatchedOrtModel(const std::filesystem::path& file,
                                     const SessionOptions& options, std::string label);

namespace internal {
/// The batched networks alive in this process: label, file and what each batcher has done.
struct BatchedModelInfo {
  std::string label;
  std::filesystem::path file;
  segmentation_service::BatchingOptions options;
  segmentation_service::BatchingStats stats;
};
std::vector<BatchedModelInfo> BatchedModels();
}  // namespace internal

}  // namespace avp::zsl
