#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>

#include <fmt/format.h>

#include <avp/core/semantic_class.h>
#include <avp/io/file.h>
#include <avp/io/image_codec.h>
#include <avp/io/overlay.h>
#include <avp/report/run_html.h>
#include <avp/report/svg_plot.h>
#include <avp/report/web_assets.h>

namespace avp::report {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr std::string_view kDataId = "avp-report-data";

/// `v` rounded to `digits` significant digits, so the page's JSON stays short; null when not
/// finite.
json Short(double v, int digits = 6) {
  if (!std::isfinite(v)) return json(nullptr);
  if (v == 0.0) return json(0.0);
  const double scale =
      std::pow(10.0, digits - 1 - static_cast<int>(std::floor(std::log10(std::abs(v)))));
  return json(std::round(v * scale) / scale);
}

/// `v` rounded to `decimals` decimals (positions in metres: 0.1 mm).
json Fixed(double v, int decimals = 4) {
  if (!std::isfinite(v)) return json(nullptr);
  const double scale = std::pow(10.0, decimals);
  return json(std::round(v * scale) / scale);
}

uint32_t PackCell(const mapping::SemanticCell* c) {
  if (c == nullptr || !c->has_label()) return 0;
  const float conf = std::clamp(c->confidence, 0.0f, 1.0f);
  const auto q = static_cast<uint32_t>(std::lround(conf * 255.0f));
  return static_cast<uint32_t>(c->semantic_class) | (q << 8) |
         (static_cast<uint32_t>(c->instance_id) << 16);
}

json PoseJson(const RigidTransform& X) {
  json a = json::array();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) a.push_back(Short(X.rotation()(r, c), 7));
    a.push_back(Fixed(X.translation()(r), 5));
  }
  return a;
}

json IntrinsicsJson(const CameraIntrinsics& K) {
  return {{"width", K.width},
          {"height", K.height},
          {"fx", Short(K.fx)},
          {"fy", Short(K.fy)},
          {"cx", Short(K.cx)},
          {"cy", Short(K.cy)},
          {"min_depth_m", Short(K.min_depth_m)},
          {"max_depth_m", Short(K.max_depth_m)}};
}

/// The median of the valid depths (every 4th pixel of every 4th row), or NaN when none.
double MedianDepth(const DepthImage& depth) {
  std::vector<float> d;
  for (int v = 0; v < depth.height(); v += 4) {
    for (int u = 0; u < depth.width(); u += 4) {
      const float z = depth(u, v);
      if (std::isfinite(z) && z > 0.0f) d.push_back(z);
    }
  }
  if (d.empty()) return std::numeric_limits<double>::quiet_NaN();
  auto mid = d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2);
  std::nth_element(d.begin(), mid, d.end());
  return *mid;
}

/// `image` reduced by an integer factor (box average) to at most `max_width` pixels wide.
ImageRgb8 Reduce(const ImageRgb8& image, int max_width) {
  const int f = std::max(1, (image.width() + max_width - 1) / std::max(1, max_width));
  if (f == 1) return image;
  ImageRgb8 out(image.width() / f, image.height() / f);
  for (int v = 0; v < out.height(); ++v) {
    for (int u = 0; u < out.width(); ++u) {
      for (int c = 0; c < 3; ++c) {
        int sum = 0;
        for (int dv = 0; dv < f; ++dv) {
          for (int du = 0; du < f; ++du) sum += image(u * f + du, v * f + dv, c);
        }
        out(u, v, c) = static_cast<uint8_t>((sum + f * f / 2) / (f * f));
      }
    }
  }
  return out;
}

std::string Hex(const std::array<uint8_t, 3>& rgb) {
  return fmt::format("#{:02x}{:02x}{:02x}", rgb[0], rgb[1], rgb[2]);
}

/// The masks picture (masks drawn over the colour image, reduced, JPEG) and each instance.
json MasksJson(const robot::Observation& obs, const Segmentation* seg,
               const RunReportOptions& options) {
  const ImageRgb8& rgb = obs.frame.rgb;
  if (rgb.empty()) return json(nullptr);
  json instances = json::array();
  ImageRgb8 picture;
  if (seg != nullptr && seg->ValidateFor(rgb.width(), rgb.height()).ok()) {
    picture = io::DrawSegmentationOverlay(rgb, *seg);
    const auto colors = io::OverlayColors(*seg);
    for (size_t i = 0; i < seg->instances.size(); ++i) {
      const InstanceMask& m = seg->instances[i];
      size_t pixels = 0;
      for (const uint8_t p : m.mask.data()) pixels += p != 0 ? 1 : 0;
      instances.push_back({{"class", std::string(ToString(m.semantic_class))},
                           {"label", m.label},
                           {"score", Short(m.confidence, 4)},
                           {"pixels", pixels},
                           {"color", Hex(colors[i])}});
    }
  } else {
    picture = rgb;
  }
  const ImageRgb8 small = Reduce(picture, options.mask_image_width);
  Result<std::vector<uint8_t>> jpeg = io::EncodeJpeg(small, options.mask_jpeg_quality);
  json out{{"width", small.width()}, {"height", small.height()}, {"instances", instances}};
  if (jpeg.ok()) {
    out["jpeg"] =
        Base64Encode(std::string_view(reinterpret_cast<const char*>(jpeg->data()), jpeg->size()));
  } else {
    out["jpeg"] = nullptr;
    out["error"] = jpeg.status().ToString();
  }
  return out;
}

json PlanJson(const pipeline::StepRecord& step, const planning::PlanResult& plan,
              const RunReportOptions& options) {
  const size_t kept = std::min(plan.ranked.size(), options.max_candidates);
  std::vector<std::string> sources;
  json eye = json::array(), dir = json::array(), utility = json::array(), gain = json::array(),
       cost = json::array(), source = json::array();
  for (size_t i = 0; i < kept; ++i) {
    const planning::ViewCandidate& c = plan.ranked[i];
    const Eigen::Vector3d p = c.X_WC.translation();
    const Eigen::Vector3d z = c.X_WC.rotation().col(2);
    for (int k = 0; k < 3; ++k) {
      eye.push_back(Fixed(p(k)));
      dir.push_back(Fixed(z(k), 3));
    }
    utility.push_back(Short(c.utility));
    gain.push_back(Short(c.gain));
    cost.push_back(Short(c.cost));
    auto it = std::find(sources.begin(), sources.end(), c.source);
    if (it == sources.end()) it = sources.insert(sources.end(), c.source);
    source.push_back(it - sources.begin());
  }
  return {{"status", plan.status.ok() ? std::string("OK") : plan.status.ToString()},
          {"generated", plan.generated},
          {"reachable", plan.reachable},
          {"ranked", plan.ranked.size()},
          {"kept", kept},
          {"chosen_rank", step.chosen_rank},
          {"refused_moves", step.refused_moves},
          {"stop", plan.stop},
          {"stop_reason", plan.stop_reason},
          {"sources", sources},
          {"candidates",
           {{"eye", eye},
            {"dir", dir},
            {"utility", utility},
            {"gain", gain},
            {"cost", cost},
            {"source", source}}}};
}

/// The move after a view (docs/motion.md): the camera's path (x, y, z per trajectory point, mm
/// precision), and its contacts with the true world and the straight line's (null: unknown).
json MoveJson(const pipeline::MotionRecord& m) {
  json path = json::array();
  for (const Eigen::Vector3d& p : m.camera_path_W) {
    for (int k = 0; k < 3; ++k) path.push_back(Fixed(p(k)));
  }
  const auto total = [](const std::optional<robot::MotionContacts>& c) {
    return c ? json(c->total()) : json(nullptr);
  };
  return {{"planned", m.planned},
          {"straight", m.straight},
          {"execution_s", Short(m.execution_s)},
          {"planning_ms", Short(m.planning_ms)},
          {"rejected", m.rejected.size()},
          {"path", std::move(path)},
          {"contacts", total(m.contacts)},
          {"first_contact", m.contacts ? json(m.contacts->first) : json(nullptr)},
          {"straight_line_contacts", total(m.straight_line_contacts)}};
}

/// What fusion during motion did along the move (null when it did not run).
json MovingFramesJson(const pipeline::MovingFramesRecord& f) {
  if (!f.streamed) return nullptr;
  return {{"fused", f.fused},
          {"segmented", f.segmented},
          {"dropped", f.dropped},
          {"failed", f.failed},
          {"known_delta", f.known_delta},
          {"target_delta", f.target_delta},
          {"map_rate_hz", Short(f.map_rate_hz())}};
}

void PutU16(std::string& out, uint32_t v) {
  out.push_back(static_cast<char>(v & 0xff));
  out.push_back(static_cast<char>((v >> 8) & 0xff));
}

constexpr char kBase64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

std::string EscapeScript(std::string_view text) {
  // "</" inside a script element could end it ("</script"); "<\/" means the same in JSON
  // strings and in JavaScript strings, templates and regular expressions.
  std::string out;
  out.reserve(text.size());
  for (size_t i = 0; i < text.size(); ++i) {
    if (text[i] == '<' && i + 1 < text.size() && text[i + 1] == '/') {
      out += "<\\/";
      ++i;
    } else {
      out.push_back(text[i]);
    }
  }
  return out;
}

}  // namespace

std::string Base64Encode(std::string_view bytes) {
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 3 <= bytes.size(); i += 3) {
    const uint32_t n = static_cast<uint32_t>(static_cast<uint8_t>(bytes[i])) << 16 |
                       static_cast<uint32_t>(static_cast<uint8_t>(bytes[i + 1])) << 8 |
                       static_cast<uint8_t>(bytes[i + 2]);
    out.push_back(kBase64[(n >> 18) & 63]);
    out.push_back(kBase64[(n >> 12) & 63]);
    out.push_back(kBase64[(n >> 6) & 63]);
    out.push_back(kBase64[n & 63]);
  }
  const size_t rest = bytes.size() - i;
  if (rest > 0) {
    uint32_t n = static_cast<uint32_t>(static_cast<uint8_t>(bytes[i])) << 16;
    if (rest == 2) n |= static_cast<uint32_t>(static_cast<uint8_t>(bytes[i + 1])) << 8;
    out.push_back(kBase64[(n >> 18) & 63]);
    out.push_back(kBase64[(n >> 12) & 63]);
    out.push_back(rest == 2 ? kBase64[(n >> 6) & 63] : '=');
    out.push_back('=');
  }
  return out;
}

Result<std::string> Base64Decode(std::string_view text) {
  std::string out;
  out.reserve(text.size() / 4 * 3);
  uint32_t acc = 0;
  int bits = 0;
  size_t pad = 0;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    int v = -1;
    if (c >= 'A' && c <= 'Z') v = c - 'A';
    if (c >= 'a' && c <= 'z') v = c - 'a' + 26;
    if (c >= '0' && c <= '9') v = c - '0' + 52;
    if (c == '+') v = 62;
    if (c == '/') v = 63;
    if (c == '=' && i + 2 >= text.size() && text.size() % 4 == 0) {
      ++pad;
      continue;
    }
    if (v < 0 || pad > 0) {
      return InvalidArgumentError(fmt::format("base64: byte {} at offset {} is not base64",
                                              static_cast<int>(static_cast<uint8_t>(c)), i));
    }
    acc = (acc << 6) | static_cast<uint32_t>(v);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(static_cast<char>((acc >> bits) & 0xff));
    }
  }
  if (text.size() % 4 != 0) {
    return InvalidArgumentError(
        fmt::format("base64: length {} is not a multiple of 4", text.size()));
  }
  return out;
}

RunReportCollector::RunReportCollector(RunReportOptions options) : options_(options) {}

void RunReportCollector::OnView(const pipeline::StepRecord& step, const pipeline::StepData& data,
                                const mapping::SemanticMap& map) {
  voxel_size_m_ = map.voxel_size_m();
  const mapping::OccupancyGrid& grid = map.grid();
  const float occupied = grid.occupied_log_odds();
  std::unordered_map<VoxelKey, uint32_t, VoxelKeyHash> now;
  now.reserve(occupied_.size() + 4096);
  // Block by block: the semantic cell is the block's own (no lookup per voxel).
  grid.ForEachBlock([&](const mapping::OccupancyBlock& b) {
    b.known.ForEachSet([&](int i) {
      if (b.log_odds[i] < occupied) return;
      now.emplace(mapping::KeyOf(b.key, i), PackCell(b.semantics ? &(*b.semantics)[i] : nullptr));
    });
  });
  Step s;
  for (const auto& [k, v] : now) {
    const auto it = occupied_.find(k);
    if (it == occupied_.end() || it->second != v) s.set.push_back({k, v});
  }
  for (const auto& [k, v] : occupied_) {
    if (!now.contains(k)) s.removed.push_back(k);
  }
  std::sort(s.set.begin(), s.set.end(),
            [](const VoxelSet& a, const VoxelSet& b) { return a.key < b.key; });
  std::sort(s.removed.begin(), s.removed.end());
  s.occupied = now.size();
  occupied_ = std::move(now);

  json camera{{"X_WC", PoseJson(step.X_WC)}, {"K", nullptr}, {"median_depth_m", nullptr}};
  json masks = nullptr;
  if (data.observation != nullptr) {
    camera["K"] = IntrinsicsJson(data.observation->frame.K);
    camera["median_depth_m"] = Fixed(MedianDepth(data.observation->frame.depth_m));
    masks = MasksJson(*data.observation, data.segmentation, options_);
  }
  json metrics = json::object();
  for (const auto& [name, value] : step.metrics) metrics[name] = Short(value);
  json errors = json::object();
  if (!step.capture_status.ok()) errors["capture"] = step.capture_status.ToString();
  if (!step.segment_status.ok()) errors["segment"] = step.segment_status.ToString();
  if (!step.integrate_status.ok()) errors["integrate"] = step.integrate_status.ToString();
  if (!step.move_status.ok()) errors["move"] = step.move_status.ToString();
  s.json = {{"view", step.view + 1},
            {"occupied_voxels", step.occupied_voxels},
            {"known_voxels", step.known_voxels},
            {"target_voxels", step.target_voxels},
            {"instances", step.instances},
            {"masks", step.masks},
            {"masks_without_depth", step.masks_without_depth},
            {"camera", camera},
            {"image", masks},
            {"plan", data.plan != nullptr ? PlanJson(step, *data.plan, options_) : json(nullptr)},
            {"motion", MoveJson(step.motion)},
            {"moving_frames", MovingFramesJson(step.motion_frames)},
            {"metrics", metrics},
            {"errors", errors},
            {"step_ms", Short(step.times.total_ms, 4)}};
  steps_.push_back(std::move(s));
}

std::vector<size_t> RunReportCollector::OccupiedVoxelsPerStep() const {
  std::vector<size_t> out;
  for (const Step& s : steps_) out.push_back(s.occupied);
  return out;
}

Result<json> RunReportCollector::Data(const RunReportInfo& info) const {
  // Keys are stored as 16-bit offsets from the smallest key any step sets.
  constexpr int32_t kMax = std::numeric_limits<int32_t>::max();
  constexpr int32_t kMin = std::numeric_limits<int32_t>::min();
  VoxelKey lo{kMax, kMax, kMax};
  VoxelKey hi{kMin, kMin, kMin};
  for (const Step& s : steps_) {
    for (const VoxelSet& v : s.set) {
      lo = {std::min(lo.x, v.key.x), std::min(lo.y, v.key.y), std::min(lo.z, v.key.z)};
      hi = {std::max(hi.x, v.key.x), std::max(hi.y, v.key.y), std::max(hi.z, v.key.z)};
    }
  }
  if (lo.x > hi.x) lo = hi = VoxelKey{};
  const int64_t extent =
      std::max({static_cast<int64_t>(hi.x) - lo.x, static_cast<int64_t>(hi.y) - lo.y,
                static_cast<int64_t>(hi.z) - lo.z});
  if (extent > 65535) {
    return InvalidArgumentError(fmt::format(
        "run report: the occupied voxels span {} voxels along an axis (at most 65535)", extent));
  }
  const auto offset = [&](std::string& out, const VoxelKey& k) {
    PutU16(out, static_cast<uint32_t>(k.x - lo.x));
    PutU16(out, static_cast<uint32_t>(k.y - lo.y));
    PutU16(out, static_cast<uint32_t>(k.z - lo.z));
  };
  json steps = json::array();
  for (const Step& s : steps_) {
    std::string set;
    set.reserve(s.set.size() * 10);
    for (const VoxelSet& v : s.set) {
      offset(set, v.key);
      set.push_back(static_cast<char>(v.value & 0xff));         // class
      set.push_back(static_cast<char>((v.value >> 8) & 0xff));  // confidence * 255
      PutU16(set, v.value >> 16);                               // instance
    }
    std::string removed;
    removed.reserve(s.removed.size() * 6);
    for (const VoxelKey& k : s.removed) offset(removed, k);
    json j = s.json;
    j["voxels"] = {{"set", s.set.size()},
                   {"removed", s.removed.size()},
                   {"set_b64", Base64Encode(set)},
                   {"removed_b64", Base64Encode(removed)},
                   {"occupied", s.occupied}};
    steps.push_back(std::move(j));
  }
  json classes = json::array();
  for (int c = 0; c < kNumSemanticClasses; ++c) {
    classes.push_back(std::string(ToString(static_cast<SemanticClass>(c))));
  }
  json facts = json::array();
  for (const auto& [k, v] : info.facts) facts.push_back({k, v});
  size_t found = 0, missed = 0;
  if (info.fruits.is_array()) {
    for (const json& f : info.fruits) (f.value("found", false) ? found : missed) += 1;
  }
  return json{{"format", "avp-run-report"},
              {"version", 1},
              {"title", info.title},
              {"facts", facts},
              {"voxel_size_m", voxel_size_m_},
              {"origin_key", {lo.x, lo.y, lo.z}},
              {"voxel_record",
               "set: 10 bytes little-endian (dx u16, dy u16, dz u16, class u8, confidence*255 u8, "
               "instance u16); removed: 6 bytes (dx, dy, dz u16); key = origin_key + d"},
              {"classes", classes},
              {"fruits", info.fruits.is_array() ? info.fruits : json(nullptr)},
              {"expected",
               {{"voxels", steps_.empty() ? 0 : steps_.back().occupied},
                {"frustums", steps_.size()},
                {"fruit_found", found},
                {"fruit_missed", missed}}},
              {"steps", steps}};
}

std::string RunReportHtml(const json& data, std::string_view viewer_js, std::string_view title) {
  std::string html;
  const std::string data_text = EscapeScript(data.dump());
  const std::string js = EscapeScript(viewer_js);
  html.reserve(data_text.size() + js.size() + 4096);
  html += "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n";
  html += "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n";
  html += "<meta name=\"generator\" content=\"avp run report\">\n";
  html += "<title>" + EscapeXml(title) + " — avp run report</title>\n";
  html += "</head>\n<body>\n<div id=\"avp-report\"></div>\n";
  html += "<noscript>This report needs JavaScript (its 3D view is drawn with WebGL).</noscript>\n";
  html += fmt::format("<script type=\"application/json\" id=\"{}\">", kDataId);
  html += data_text;
  html += "</script>\n<script>\n";
  html += js;
  html += "\n</script>\n</body>\n</html>\n";
  return html;
}

Status WriteRunReportHtml(const fs::path& path, const RunReportCollector& collector,
                          const RunReportInfo& info) {
  AVP_ASSIGN_OR_RETURN(const json data, collector.Data(info));
  return io::WriteFileAtomic(path, RunReportHtml(data, RunViewerJs(), info.title), "run report");
}

Result<json> ReadRunReportData(const fs::path& html) {
  AVP_ASSIGN_OR_RETURN(const std::string text, io::ReadFileBounded(html, "run report"));
  const std::string open = fmt::format("<script type=\"application/json\" id=\"{}\">", kDataId);
  const size_t begin = text.find(open);
  if (begin == std::string::npos) {
    return NotFoundError(fmt::format("{}: no run report data ({})", html.string(), open));
  }
  const size_t start = begin + open.size();
  const size_t end = text.find("</script>", start);
  if (end == std::string::npos) {
    return ParseError(
        fmt::format("{}: the run report data at offset {} has no end", html.string(), start));
  }
  json data = json::parse(text.begin() + static_cast<std::ptrdiff_t>(start),
                          text.begin() + static_cast<std::ptrdiff_t>(end), nullptr, false);
  if (data.is_discarded()) {
    return ParseError(
        fmt::format("{}: the run report data at offset {} is not JSON", html.string(), start));
  }
  return data;
}

}  // namespace avp::report
