// A backend's start-up from its manifest (design: zero-shot-models.md §7): the files each model
// names checked, the networks loaded in process or on a model server, their contracts checked
// against each other, and one warm-up call each. The manifest itself is read in manifest.cpp.
#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <initializer_list>
#include <set>
#include <sstream>
#include <system_error>
#include <utility>

#include <fmt/format.h>

#include "manifest.h"
#include "ort_handler.h"
#include "remote_model.h"

namespace avp::zsl {

namespace fs = std::filesystem;

// ---- file checks -------------------------------------------------------------------------------

namespace {

Status CheckFile(const std::string& role, const FileRef& ref, const std::string& field,
                 std::string_view what, bool verify_sha256) {
  std::error_code ec;
  if (!fs::is_regular_file(ref.path, ec)) {
    return NotFoundError(fmt::format("{}: {} '{}' does not exist (field models.{}.{})", role, what,
                                     ref.path.string(), role, field));
  }
  if (ref.bytes) {
    const uintmax_t size = fs::file_size(ref.path, ec);
    if (ec)
      return IoError(
          fmt::format("{}: cannot stat '{}': {}", role, ref.path.string(), ec.message()));
    if (size != *ref.bytes) {
      return InvalidArgumentError(
          fmt::format("{}: '{}' has {} bytes; models.{}.{} says {}", role, ref.path.string(), size,
                      role, field == "file" ? "bytes" : field + ".bytes", *ref.bytes));
    }
  }
  if (verify_sha256 && ref.sha256) {
    AVP_ASSIGN_OR_RETURN(const std::string sha, FileSha256(ref.path));
    if (sha != *ref.sha256) {
      return InvalidArgumentError(
          fmt::format("{}: '{}' has sha256 {}; models.{}.{} says {}", role, ref.path.string(), sha,
                      role, field == "file" ? "sha256" : field + ".sha256", *ref.sha256));
    }
  }
  return Status::Ok();
}

}  // namespace

Status CheckFiles(const ModelEntry& entry, bool verify_sha256, bool model_file) {
  if (model_file) {
    AVP_RETURN_IF_ERROR(CheckFile(entry.role, entry.file, "file", "model file", verify_sha256));
  }
  if (entry.text) {
    AVP_RETURN_IF_ERROR(CheckFile(entry.role, entry.text->vocabulary, "text.vocabulary",
                                  "vocabulary file", verify_sha256));
    for (size_t i = 0; i < entry.text->precomputed.size(); ++i) {
      const PrecomputedVocabulary& p = entry.text->precomputed[i];
      AVP_RETURN_IF_ERROR(CheckFile(entry.role, p.embeddings,
                                    fmt::format("text.precomputed[{}].embeddings", i),
                                    "precomputed embeddings", verify_sha256));
      AVP_RETURN_IF_ERROR(CheckFile(entry.role, p.names,
                                    fmt::format("text.precomputed[{}].names", i),
                                    "precomputed names", verify_sha256));
    }
  }
  return Status::Ok();
}

// ---- backends ----------------------------------------------------------------------------------

Result<std::vector<std::string>> BackendRoles(std::string_view backend, const Manifest& manifest) {
  if (backend == kBackendYwes) {
    std::vector<std::string> roles = {kRoleDetector};
    const ModelEntry* detector = manifest.Find(kRoleDetector);
    if (detector == nullptr || detector->contract != kYoloWorldBaked) roles.push_back(kRoleText);
    roles.push_back(kRoleSegmenterEncoder);
    roles.push_back(kRoleSegmenterDecoder);
    return roles;
  }
  if (backend == kBackendLsam) {
    return std::vector<std::string>{kRoleGrounding, kRoleSegmenterEncoder, kRoleSegmenterDecoder};
  }
  return InvalidArgumentError(
      fmt::format("unknown backend '{}' (expected {} or {})", backend, kBackendYwes, kBackendLsam));
}

std::string_view ToString(BackendState state) {
  switch (state) {
    case BackendState::kReady:
      return "READY";
    case BackendState::kMissing:
      return "MISSING";
    case BackendState::kInvalid:
      return "INVALID";
  }
  return "INVALID";
}

std::string LoadedBackend::StateString() const {
  if (state == BackendState::kReady) return "READY";
  return fmt::format("{}({})", ToString(state), reason);
}

const LoadedModel* LoadedBackend::Find(std::string_view role) const {
  auto it = models.find(std::string(role));
  return it == models.end() ? nullptr : &it->second;
}

std::optional<fs::path> ModelDirFromEnvironment() {
  const char* dir = std::getenv(kModelDirEnvVar);
  if (dir == nullptr || *dir == '\0') return std::nullopt;
  return fs::path(dir);
}

namespace {

/// The contracts a role accepts.
std::vector<std::string> ContractsFor(const std::string& role) {
  if (role == kRoleDetector) return {kYoloWorldTxtFeats, kYoloWorldBaked};
  if (role == kRoleText) return {kClipText};
  if (role == kRoleSegmenterEncoder) return {kEvitSamEncoder};
  if (role == kRoleSegmenterDecoder) return {kEvitSamDecoderSingle};
  if (role == kRoleGrounding) return {kGroundingDinoOrt};
  return {};
}

/// The image input of a contract (checked against preprocess.size), or nullptr.
const char* ImageInput(const std::string& contract) {
  if (contract == kYoloWorldTxtFeats || contract == kYoloWorldBaked) return "images";
  if (contract == kEvitSamEncoder) return "input_image";
  if (contract == kGroundingDinoOrt) return "img";
  return nullptr;
}

/// preprocess.size against the model's static image size; fills a size the manifest leaves out.
Status ResolveImageSize(LoadedModel& m) {
  const char* input = ImageInput(m.entry.contract);
  if (input == nullptr) return Status::Ok();
  const TensorInfo* t = m.model.io().FindInput(m.binding.Name(input));
  if (t == nullptr || t->shape.size() != 4) return Status::Ok();  // the contract check reported it
  const int64_t h = t->shape[2];
  const int64_t w = t->shape[3];
  Preprocess& p = m.entry.preprocess;
  const std::string& role = m.entry.role;
  const bool given = p.height > 0 && p.width > 0;
  const bool mismatch =
      (h != kDynamicDim && given && h != p.height) || (w != kDynamicDim && given && w != p.width);
  if (mismatch) {
    const std::string what =
        m.entry.contract == kEvitSamEncoder ? fmt::format(" (S = {})", m.binding.Dim("S")) : "";
    return InvalidArgumentError(
        fmt::format("{}: preprocess.size [{},{}] differs from the model's {} size [{},{}]{}", role,
                    p.height, p.width, t->name, h, w, what));
  }
  if (!given) {
    if (h == kDynamicDim || w == kDynamicDim) {
      return InvalidArgumentError(
          fmt::format("{}: input '{}' has a dynamic size {}; set preprocess.size in the manifest",
                      role, t->name, ShapeToString(t->shape)));
    }
    p.height = static_cast<int>(h);
    p.width = static_cast<int>(w);
  }
  return Status::Ok();
}

Status CrossCheck(std::map<std::string, LoadedModel>& models) {
  auto find = [&](const char* role) -> LoadedModel* {
    auto it = models.find(role);
    return it == models.end() ? nullptr : &it->second;
  };
  for (auto& [role, m] : models) AVP_RETURN_IF_ERROR(ResolveImageSize(m));

  if (LoadedModel* det = find(kRoleDetector)) {
    Postprocess& post = det->entry.postprocess;
    const std::string& out_name = det->binding.Name("output0");
    const TensorInfo* out = det->model.io().FindOutput(out_name);
    const std::string out_shape = out != nullptr ? ShapeToString(out->shape) : "?";
    if (det->entry.contract == kYoloWorldTxtFeats) {
      const int64_t n = det->binding.Dim("N");
      if (n == kDynamicDim && post.n_max == 0) {
        return InvalidArgumentError(
            "detector: txt_feats has a dynamic class dimension N; set postprocess.n_max");
      }
      if (n != kDynamicDim && post.n_max != 0 && post.n_max != n) {
        return InvalidArgumentError(
            fmt::format("detector: postprocess.n_max ({}) differs from the model's N ({}; {} {})",
                        post.n_max, n, out_name, out_shape));
      }
      if (n != kDynamicDim) post.n_max = static_cast<int>(n);
      if (LoadedModel* text = find(kRoleText)) {
        const TensorInfo* emb = text->model.io().FindOutput(text->binding.Name("text_embeds"));
        const int64_t text_width = emb != nullptr && emb->shape.size() == 2 ? emb->shape[1] : 512;
        const TensorInfo* feats = det->model.io().FindInput(det->binding.Name("txt_feats"));
        const int64_t feats_width =
            feats != nullptr && feats->shape.size() == 3 ? feats->shape[2] : 512;
        if (text_width != feats_width) {
          return InvalidArgumentError(fmt::format(
              "detector: txt_feats width {} differs from the text model's text_embeds width {}",
              feats_width, text_width));
        }
        if (text->entry.text && text->entry.text->dim != text_width) {
          return InvalidArgumentError(
              fmt::format("text: text.dim ({}) differs from the model's text_embeds width {}",
                          text->entry.text->dim, text_width));
        }
        if (text->entry.text && text->entry.text->context != 77) {
          return InvalidArgumentError(fmt::format(
              "text: text.context ({}) differs from clip.text/1's 77 input_ids positions",
              text->entry.text->context));
        }
      }
    } else {
      const int64_t nc = det->binding.Dim("NC");
      const auto names = static_cast<int64_t>(post.baked_names.size());
      if (nc != kDynamicDim && nc != names) {
        return InvalidArgumentError(fmt::format(
            "detector: postprocess.baked_names has {} names; the model has NC = {} class rows "
            "({} {})",
            names, nc, out_name, out_shape));
      }
      post.n_max = static_cast<int>(names);
    }
  }

  LoadedModel* enc = find(kRoleSegmenterEncoder);
  LoadedModel* dec = find(kRoleSegmenterDecoder);
  if (enc != nullptr && dec != nullptr) {
    const TensorInfo* produced = enc->model.io().FindOutput("image_embeddings");
    const TensorInfo* consumed = dec->model.io().FindInput("image_embeddings");
    if (produced != nullptr && consumed != nullptr) {
      bool same = produced->shape.size() == consumed->shape.size();
      for (size_t i = 0; same && i < produced->shape.size(); ++i) {
        const int64_t a = produced->shape[i];
        const int64_t b = consumed->shape[i];
        if (a != kDynamicDim && b != kDynamicDim && a != b) same = false;
      }
      if (!same) {
        return InvalidArgumentError(fmt::format(
            "segmenter.decoder: input 'image_embeddings' {} differs from the encoder's output {}",
            ShapeToString(consumed->shape), ShapeToString(produced->shape)));
      }
    }
  }
  if (dec != nullptr) {
    const Postprocess& post = dec->entry.postprocess;
    if (post.low_res != 256) {
      return InvalidArgumentError(fmt::format(
          "segmenter.decoder: postprocess.low_res ({}) differs from the model's 256x256 masks",
          post.low_res));
    }
  }
  if (LoadedModel* gd = find(kRoleGrounding)) {
    const int64_t l = gd->binding.Dim("L");
    const int context = gd->entry.text ? gd->entry.text->context : 256;
    if (context > 256) {
      return InvalidArgumentError(fmt::format(
          "grounding: text.context ({}) exceeds the 256 token slots of 'logits'", context));
    }
    if (l != kDynamicDim && l > context) {
      return InvalidArgumentError(fmt::format(
          "grounding: the model's text length L = {} exceeds text.context ({})", l, context));
    }
  }
  return Status::Ok();
}

/// Zero inputs for a warm-up run: dynamic axes become 1.
Status WarmUp(const LoadedModel& m, double& ms) {
  std::vector<std::vector<float>> f32;
  std::vector<std::vector<int64_t>> i64;
  std::vector<std::vector<uint8_t>> b;
  f32.reserve(m.model.inputs().size());
  i64.reserve(m.model.inputs().size());
  b.reserve(m.model.inputs().size());
  std::vector<InputTensor> inputs;
  for (const TensorInfo& t : m.model.inputs()) {
    std::vector<int64_t> shape = t.shape;
    size_t n = 1;
    for (int64_t& d : shape) {
      if (d == kDynamicDim) d = 1;
      n *= static_cast<size_t>(d);
    }
    switch (t.type) {
      case ElementType::kFloat32:
        f32.emplace_back(n, 0.0f);
        inputs.push_back(InputTensor::Float32(t.name, f32.back(), shape));
        break;
      case ElementType::kInt64:
        i64.emplace_back(n, 0);
        inputs.push_back(InputTensor::Int64(t.name, i64.back(), shape));
        break;
      case ElementType::kBool:
        b.emplace_back(n, uint8_t{1});
        inputs.push_back(InputTensor::Bool(t.name, b.back(), shape));
        break;
      default:
        return Status::Ok();  // not a type Run binds: no warm-up for this model
    }
  }
  const auto start = std::chrono::steady_clock::now();
  Result<std::vector<OutputTensor>> out = m.model.Run(inputs);
  ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  if (!out.ok()) return out.status().WithContext("warm-up");
  return Status::Ok();
}

LoadedBackend Fail(LoadedBackend out, Status status) {
  out.state =
      status.code() == StatusCode::kNotFound ? BackendState::kMissing : BackendState::kInvalid;
  out.reason = status.message();
  out.status = std::move(status);
  out.models.clear();
  return out;
}

}  // namespace

Status CheckBackendFiles(std::string_view backend, const Manifest& manifest, bool verify_sha256,
                         bool remote) {
  AVP_ASSIGN_OR_RETURN(const std::vector<std::string> roles, BackendRoles(backend, manifest));

  // 1. Every role is listed, with a contract that can serve it, and its files are there.
  for (const std::string& role : roles) {
    const ModelEntry* entry = manifest.Find(role);
    const std::vector<std::string> accepted = ContractsFor(role);
    if (entry == nullptr) {
      std::vector<std::string> listed;
      for (const auto& [r, e] : manifest.models) listed.push_back(r);
      return NotFoundError(
          fmt::format("{} needs model role '{}' ({}); {} lists {}", backend, role,
                      fmt::join(accepted, " or "), manifest.file.string(),
                      listed.empty() ? "none" : fmt::format("{}", fmt::join(listed, ", "))));
    }
    if (std::find(accepted.begin(), accepted.end(), entry->contract) == accepted.end()) {
      return InvalidArgumentError(
          fmt::format("{}: contract {} cannot serve this role (expected {})", role, entry->contract,
                      fmt::join(accepted, " or ")));
    }
  }
  for (const std::string& role : roles) {
    Status files = CheckFiles(*manifest.Find(role), verify_sha256, !remote);
    if (!files.ok()) return files;
  }
  return Status::Ok();
}

Status CheckBackendDir(std::string_view backend, const fs::path& model_dir, bool remote) {
  AVP_ASSIGN_OR_RETURN(const Manifest manifest, ReadManifest(model_dir));
  return CheckBackendFiles(backend, manifest, false, remote);
}

LoadedBackend LoadBackend(std::string_view backend, const fs::path& model_dir,
                          const BackendLoadOptions& options) {
  Result<Manifest> manifest = ReadManifest(model_dir);
  if (!manifest.ok()) {
    LoadedBackend out;
    out.backend = std::string(backend);
    out.model_dir = model_dir;
    return Fail(std::move(out), manifest.status());
  }
  return LoadBackend(backend, *manifest, options);
}

LoadedBackend LoadBackend(std::string_view backend, const Manifest& manifest,
                          const BackendLoadOptions& options) {
  LoadedBackend out;
  out.backend = std::string(backend);
  out.model_dir = manifest.dir;
  Result<std::vector<std::string>> roles = BackendRoles(backend, manifest);
  if (!roles.ok()) return Fail(std::move(out), roles.status());
  // With a model server the networks are there, not here: only the text files are needed.
  const bool remote = !options.session.model_server.empty();
  // 1. Every role is listed, with a contract that can serve it, and its files are there.
  if (Status files = CheckBackendFiles(backend, manifest, options.verify_sha256, remote);
      !files.ok()) {
    return Fail(std::move(out), files);
  }

  // 2-3. One session (or one model of the server) per role, checked against its contract and
  // the declared I/O.
  for (const std::string& role : *roles) {
    const ModelEntry& entry = *manifest.Find(role);
    Result<ModelRef> model =
        remote ? ConnectRemoteModel(options.session.model_server, entry.ServedName(), role)
               : LoadBatchedOrtModel(entry.file.path, options.session, role);
    if (!model.ok() && remote) return Fail(std::move(out), model.status());
    if (!model.ok()) {
      Status s = model.status();
      // A file that exists but does not load is INVALID, not MISSING.
      if (s.code() == StatusCode::kNotFound) s = InvalidArgumentError(s.message());
      return Fail(std::move(out), s);
    }
    Result<const Contract*> contract = FindContract(entry.contract);
    if (!contract.ok())
      return Fail(std::move(out), InvalidArgumentError(contract.status().message()));
    ContractCheckOptions check;
    check.transposed_layout = entry.postprocess.layout == DetectionLayout::kAnchorsByAttributes;
    const bool declared = !entry.declared.inputs.empty() || !entry.declared.outputs.empty();
    Result<ContractBinding> binding =
        CheckContract(role, model->io(), **contract, declared ? &entry.declared : nullptr, check);
    if (!binding.ok()) return Fail(std::move(out), binding.status());
    out.models.emplace(role,
                       LoadedModel{entry, std::move(model).value(), std::move(binding).value()});
  }

  // 4. Cross-checks between the models.
  Status cross = CrossCheck(out.models);
  if (!cross.ok()) return Fail(std::move(out), cross);

  // 5. Optional warm-up.
  if (options.warm_up) {
    std::vector<std::string> times;
    for (const std::string& role : *roles) {
      double ms = 0.0;
      Status warm = WarmUp(out.models.at(role), ms);
      if (!warm.ok()) return Fail(std::move(out), warm);
      times.push_back(fmt::format("{} {:.1f} ms", role, ms));
    }
    std::fprintf(stderr, "avp zsl: %s warm-up (%s): %s\n", out.backend.c_str(),
                 out.models.begin()->second.model.provider().c_str(),
                 fmt::format("{}", fmt::join(times, ", ")).c_str());
  }
  out.state = BackendState::kReady;
  out.status = Status::Ok();
  return out;
}

}  // namespace avp::zsl
