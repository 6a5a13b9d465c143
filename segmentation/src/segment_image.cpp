#include <algorithm>
#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <system_error>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <avp/core/camera.h>
#include <avp/core/rgbd_frame.h>
#include <avp/core/text.h>
#include <avp/io/file.h>
#include <avp/io/image_codec.h>
#include <avp/io/mask_codec.h>
#include <avp/io/overlay.h>
#include <avp/segmentation/segment_image.h>
#include <avp/segmentation/segmenter.h>

namespace avp::segmentation {

namespace {

bool IsZslBackend(const std::string& spec) { return spec == "ywes" || spec == "lsam"; }

size_t Area(const MaskImage& mask) {
  const auto d = mask.data();
  return static_cast<size_t>(std::count_if(d.begin(), d.end(), [](uint8_t v) { return v != 0; }));
}

}  // namespace

Status SegmentOptions::Validate() const {
  std::vector<std::string> bad;
  if (image.empty()) bad.push_back("image is empty: give --image PATH");
  if (backend.empty()) bad.push_back("backend is empty");
  if (!(threshold >= 0.0f && threshold <= 1.0f)) {
    bad.push_back(fmt::format("threshold ({}) must be in [0, 1]", threshold));
  }
  if (out_dir.empty()) bad.push_back("out_dir is empty");
  if (bad.empty()) return Status::Ok();
  std::string message = "invalid segment options: ";
  for (size_t i = 0; i < bad.size(); ++i) message += (i > 0 ? "; " : "") + bad[i];
  return InvalidArgumentError(message);
}

Result<std::string> SegmenterSpecFor(const SegmentOptions& options) {
  if (options.models.empty()) return options.backend;
  if (!IsZslBackend(options.backend)) {
    return InvalidArgumentError(fmt::format(
        "--models applies to the ywes and lsam backends, not {} (a \"ywes://DIR\" spec names "
        "its directory itself)",
        QuoteText(options.backend)));
  }
  return options.backend + "://" + options.models.string();
}

Result<SegmentResult> SegmentWith(const SegmenterRegistry& segmenters, const std::string& spec,
                                  const OptionValues& segmenter_options, uint64_t seed,
                                  const SegmentationRequest& request) {
  if (request.frame == nullptr) return InvalidArgumentError("SegmentWith: no frame");
  AVP_ASSIGN_OR_RETURN(const AnyOptions values, segmenters.Options(spec, segmenter_options));
  AVP_ASSIGN_OR_RETURN(std::unique_ptr<Segmenter> segmenter,
                       segmenters.Make(spec, values, {.seed = seed}));
  SegmentResult result;
  result.spec = spec;
  result.backend = std::string(segmenter->name());
  result.width = request.frame->rgb.width();
  result.height = request.frame->rgb.height();
  const auto start = std::chrono::steady_clock::now();
  Result<Segmentation> seg = segmenter->Segment(request);
  result.total_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  if (!seg.ok()) return seg.status().WithContext(fmt::format("segmenter '{}'", spec));
  AVP_RETURN_IF_ERROR(seg->ValidateFor(result.width, result.height)
                          .WithContext(fmt::format("segmenter '{}' returned", spec)));
  result.segmentation = std::move(seg).value();
  return result;
}

Result<SegmentResult> SegmentImageToFolder(const SegmentOptions& options,
                                           const SegmenterRegistry& segmenters) {
  AVP_RETURN_IF_ERROR(options.Validate());
  AVP_ASSIGN_OR_RETURN(const std::string spec, SegmenterSpecFor(options));
  // Outputs never overwrite inputs: the overlay or the JSON may not be the image read.
  for (const char* name : {"overlay.png", "instances.json"}) {
    AVP_RETURN_IF_ERROR(io::CheckOutputIsNotInput(options.out_dir / name, "segment output",
                                                  options.image, "image"));
  }
  AVP_RETURN_IF_ERROR(io::CheckReadableFile(options.image, "image").status());
  AVP_ASSIGN_OR_RETURN(ImageRgb8 image, io::ReadImageFile(options.image));
  RgbdFrame frame;
  frame.K = CameraIntrinsics::FromHorizontalFov(image.width(), image.height(), 60.0);
  frame.depth_m = DepthImage(image.width(), image.height(), 0.0f);
  frame.rgb = std::move(image);
  SegmentationRequest request;
  request.frame = &frame;
  request.prompt = options.prompt;
  request.score_threshold = options.threshold;

  AVP_ASSIGN_OR_RETURN(
      SegmentResult result,
      SegmentWith(segmenters, spec, options.segmenter_options, options.seed, request));
  result.image = options.image;

  const std::filesystem::path overlay = options.out_dir / "overlay.png";
  const std::filesystem::path json = options.out_dir / "instances.json";
  std::error_code ec;
  std::filesystem::create_directories(options.out_dir, ec);
  if (ec) {
    return IoError(fmt::format("cannot create output folder '{}': {}", options.out_dir.string(),
                               ec.message()));
  }
  AVP_RETURN_IF_ERROR(
      io::WritePngFile(io::DrawSegmentationOverlay(frame.rgb, result.segmentation), overlay));
  result.files.push_back(overlay);
  AVP_RETURN_IF_ERROR(io::WriteFileAtomic(json, SegmentationJson(result, options), "instances"));
  result.files.push_back(json);
  return result;
}

std::string SegmentationJson(const SegmentResult& result, const SegmentOptions& options) {
  using nlohmann::json;
  json timings = json::array();
  for (const StageTiming& t : result.segmentation.timings) {
    timings.push_back({{"stage", t.stage}, {"ms", t.ms}});
  }
  json instances = json::array();
  for (size_t i = 0; i < result.segmentation.instances.size(); ++i) {
    const InstanceMask& m = result.segmentation.instances[i];
    json polygons = json::array();
    for (const auto& polygon : io::MaskToPolygons(m.mask)) {
      json points = json::array();
      for (const auto& p : polygon) points.push_back({p[0], p[1]});
      polygons.push_back(std::move(points));
    }
    json item = {
        {"index", i},
        {"label", m.label},
        {"class", std::string(ToString(m.semantic_class))},
        {"score", m.confidence},
        {"mask_score", m.mask_score >= 0.0f ? json(m.mask_score) : json(nullptr)},
        {"box", m.box ? json::array({m.box->x0, m.box->y0, m.box->x1, m.box->y1}) : json(nullptr)},
        {"area", Area(m.mask)},
        {"rle", {{"size", {m.mask.height(), m.mask.width()}}, {"counts", io::MaskToRle(m.mask)}}},
        {"polygons", std::move(polygons)}};
    instances.push_back(std::move(item));
  }
  const json doc = {
      {"backend", result.backend},
      {"spec", result.spec},
      {"prompt", options.prompt},
      {"threshold", options.threshold},
      {"image",
       {{"path", result.image.string()}, {"width", result.width}, {"height", result.height}}},
      {"total_ms", result.total_ms},
      {"timings", std::move(timings)},
      {"instances", std::move(instances)}};
  // Invalid UTF-8 in the prompt or a label is replaced (U+FFFD), not thrown.
  return doc.dump(2, ' ', false, json::error_handler_t::replace) + "\n";
}

std::string FormatSegmentSummary(const SegmentResult& result) {
  const Segmentation& seg = result.segmentation;
  std::string out = fmt::format("{}: {} instance{} in {}x{} ({})\n", result.backend,
                                seg.instances.size(), seg.instances.size() == 1 ? "" : "s",
                                result.width, result.height, result.image.string());
  for (size_t i = 0; i < seg.instances.size(); ++i) {
    const InstanceMask& m = seg.instances[i];
    out += fmt::format("  #{} {}  score {:.3f}", i,
                       m.label.empty() ? ToString(m.semantic_class) : std::string_view(m.label),
                       m.confidence);
    if (m.mask_score >= 0.0f) out += fmt::format("  mask {:.3f}", m.mask_score);
    if (m.box) {
      out += fmt::format("  box ({:.0f}, {:.0f})-({:.0f}, {:.0f})", m.box->x0, m.box->y0, m.box->x1,
                         m.box->y1);
    }
    out += fmt::format("  area {} px\n", Area(m.mask));
  }
  std::string stages;
  for (const StageTiming& t : seg.timings) {
    stages += fmt::format("{}{} {:.1f}", stages.empty() ? "" : ", ", t.stage, t.ms);
  }
  out += fmt::format("  timings (ms): {}{}total {:.1f}\n", stages, stages.empty() ? "" : "; ",
                     result.total_ms);
  return out;
}

}  // namespace avp::segmentation
