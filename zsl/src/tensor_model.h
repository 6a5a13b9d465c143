#pragma once
// Internal to avp_zsl. A network the backends run, wherever it runs: in this process through ONNX
// Runtime (OrtModel, ort_runtime.h) or on an inference server over KServe v2 (RemoteModel,
// remote_model.h). The backends keep everything else (tokenisation, letterbox, NMS, the mask
// chain) and call Run() with the same tensors either way.

#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <avp/core/status.h>

namespace avp::zsl {

struct ModelIo;
struct InputTensor;
struct OutputTensor;
struct TensorInfo;

/// One network: its declared I/O and a thread-safe Run.
class TensorModel {
 public:
  virtual ~TensorModel() = default;
  /// The label every error about it starts with (its manifest role).
  virtual const std::string& label() const = 0;
  /// Graph inputs and outputs with element types and shapes (-1 = dynamic).
  virtual const ModelIo& io() const = 0;
  /// Where it runs: "CPUExecutionProvider", "CUDAExecutionProvider", or
  /// "remote grpc://HOST:PORT/MODEL".
  virtual const std::string& provider() const = 0;
  /// Runs the network (OrtModel::Run's contract: every input bound once by name, types and
  /// shapes checked; `output_names` empty = all outputs in graph order, else those in that order).
  virtual Result<std::vector<OutputTensor>> Run(
      std::span<const InputTensor> inputs,
      std::span<const std::string> output_names = {}) const = 0;

  const std::vector<TensorInfo>& inputs() const;
  const std::vector<TensorInfo>& outputs() const;
};

/// A shared, immutable TensorModel with the same calls (LoadedModel::model).
class ModelRef {
 public:
  ModelRef() = default;
  explicit ModelRef(std::shared_ptr<const TensorModel> model) : model_(std::move(model)) {}

  const TensorModel& get() const { return *model_; }
  const std::shared_ptr<const TensorModel>& shared() const { return model_; }
  const std::string& label() const { return model_->label(); }
  const ModelIo& io() const { return model_->io(); }
  const std::vector<TensorInfo>& inputs() const { return model_->inputs(); }
  const std::vector<TensorInfo>& outputs() const { return model_->outputs(); }
  const std::string& provider() const { return model_->provider(); }
  Result<std::vector<OutputTensor>> Run(std::span<const InputTensor> inputs,
                                        std::span<const std::string> output_names = {}) const {
    return model_->Run(inputs, output_names);
  }

 private:
  std::shared_ptr<const TensorModel> model_;
};

}  // namespace avp::zsl
