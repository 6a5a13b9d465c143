#include "avp/zsl/model_service.h"

#include <utility>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "manifest.h"
#include "ort_handler.h"
#include "ort_runtime.h"
#include "remote_model.h"

namespace avp::zsl {

Result<ModelService> ServeModels(const std::filesystem::path& model_dir,
                                 const ModelServiceOptions& options) {
  if (!options.runtime.model_server.empty()) {
    return InvalidArgumentError(fmt::format(
        "a model service runs its models itself: runtime.model_server ('{}') must be empty",
        options.runtime.model_server));
  }
  if (options.runtime.batching.max_batch != 1) {
    return InvalidArgumentError(fmt::format(
        "a model service batches through server.batching (avp serve models --max-batch): "
        "runtime.batching.max_batch ({}) must be 1",
        options.runtime.batching.max_batch));
  }
  AVP_ASSIGN_OR_RETURN(const Manifest manifest, ReadManifest(model_dir));
  if (manifest.models.empty()) {
    return InvalidArgumentError(fmt::format("{} lists no model to serve", manifest.file.string()));
  }
  const SessionOptions session = ToSessionOptions(options.runtime);
  std::vector<std::shared_ptr<const segmentation_service::TensorModelHandler>> handlers;
  ModelService service;
  for (const auto& [role, entry] : manifest.models) {
    AVP_RETURN_IF_ERROR(CheckFiles(entry, options.verify_sha256));
    AVP_ASSIGN_OR_RETURN(OrtModel model, OrtModel::Load(entry.file.path, session, role));
    const std::string provider = model.provider();
    AVP_ASSIGN_OR_RETURN(std::shared_ptr<const OrtModelHandler> h,
                         OrtModelHandler::Make(entry.ServedName(),
                                               std::make_shared<const OrtModel>(std::move(model))));
    const auto list = [](const std::vector<segmentation_service::TensorSpec>& specs) {
      std::vector<std::string> out;
      for (const segmentation_service::TensorSpec& t : specs) {
        out.push_back(fmt::format("'{}' {} {}", t.name, segmentation_service::ToString(t.datatype),
                                  segmentation_service::ShapeToString(t.shape)));
      }
      return fmt::format("{}", fmt::join(out, ", "));
    };
    service.models.push_back(
        {entry.ServedName(), provider,
         fmt::format("inputs {}; outputs {}", list(h->inputs()), list(h->outputs()))});
    handlers.push_back(std::move(h));
  }
  AVP_ASSIGN_OR_RETURN(service.server,
                       segmentation_service::TensorServer::Start(options.server, handlers));
  return service;
}

}  // namespace avp::zsl
