#include "avp/ros/bag/encode.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>

#include <fmt/format.h>

#include <avp/io/mask_codec.h>
#include <avp/mapping/octomap_io.h>
#include <avp/ros/bag/layout.h>
#include <avp/ros/msg/convert.h>
#include <avp/ros/msg/images.h>
#include <avp/ros/msg/markers.h>

namespace avp::ros::bag {
namespace {

using nlohmann::json;

using ros::msg::Rgba;
using ros::msg::Viridis;

json StatusText(const Status& s) { return s.ok() ? std::string() : s.ToString(); }
json Number(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }
json Vector(const Eigen::VectorXd& v) {
  json a = json::array();
  for (Eigen::Index i = 0; i < v.size(); ++i) a.push_back(Number(v[i]));
  return a;
}

Status Field(const json& j, const char* key, const std::string& where) {
  if (!j.is_object() || !j.contains(key)) {
    return InvalidArgumentError(fmt::format("{}: '{}' is missing", where, key));
  }
  return Status::Ok();
}

/// OctoMap's float log-odds of a probability (octomap::logodds).
float OctomapLogOdds(double p) { return static_cast<float>(std::log(p / (1.0 - p))); }

/// 3 bits per level, z y x, the most significant level first: sorted codes are OcTree's
/// depth-first child order (child index = x | y << 1 | z << 2 at each level).
uint64_t Interleave(uint32_t x, uint32_t y, uint32_t z, int bits) {
  uint64_t code = 0;
  for (int b = bits - 1; b >= 0; --b) {
    code = (code << 3) | (((z >> b) & 1u) << 2) | (((y >> b) & 1u) << 1) | ((x >> b) & 1u);
  }
  return code;
}

/// Writes OcTree::writeBinaryNode's bytes, depth first, from the grid's blocks sorted by their
/// Morton code: an 8^3 block is the subtree of a depth-13 node; each node's 2 bytes hold 2 bits
/// per child (0 absent, 1 free leaf, 2 occupied leaf, 3 inner) and come before its children's.
class BinaryTreeWriter {
 public:
  /// A block as masks in Morton order: bit m of `known` / `occupied` is the voxel of local Morton
  /// code m (8 consecutive codes are the 8 children of a depth-15 node).
  struct Block {
    uint64_t code = 0;  ///< 13-level Morton code of the block
    std::array<uint8_t, 64> known{}, occupied{};
  };
  explicit BinaryTreeWriter(const std::vector<Block>& blocks) : blocks_(blocks) {}
  std::string Write() {
    if (!blocks_.empty()) Emit(0, blocks_.size(), 0);
    return std::move(out_);
  }

 private:
  static constexpr int kInner = 3, kFree = 1, kOccupied = 2, kAbsent = 0;

  /// The node's 2 bytes at `at`, or, at depths 1..15 when its 8 children are equal leaves, the
  /// leaf it collapses to (OcTree::prune), its bytes dropped.
  int Close(size_t at, const std::array<int, 8>& kind, int depth) {
    if (depth >= 1 && (kind[0] == kFree || kind[0] == kOccupied) &&
        std::all_of(kind.begin(), kind.end(), [&](int k) { return k == kind[0]; })) {
      out_.resize(at);
      return kind[0];
    }
    uint8_t bytes[2] = {0, 0};
    for (int c = 0; c < 8; ++c) {
      bytes[c / 4] =
          static_cast<uint8_t>(bytes[c / 4] | (kind[static_cast<size_t>(c)] << (2 * (c % 4))));
    }
    out_[at] = static_cast<char>(bytes[0]);
    out_[at + 1] = static_cast<char>(bytes[1]);
    return kInner;
  }
  /// Emits a child and returns its kind; a leaf leaves no bytes.
  template <class F>
  int Child(F&& emit) {
    const size_t before = out_.size();
    const int k = emit();
    if (k != kInner) out_.resize(before);
    return k;
  }

  /// Depths 0..12: blocks [lo, hi) share the code's levels above `depth`.
  int Emit(size_t lo, size_t hi, int depth) {
    if (depth == 13) return EmitBlock(blocks_[lo]);
    const size_t at = out_.size();
    out_.append(2, '\0');
    std::array<int, 8> kind{};
    const int shift = 3 * (12 - depth);
    for (size_t i = lo; i < hi;) {
      const auto child = static_cast<size_t>((blocks_[i].code >> shift) & 7u);
      size_t j = i + 1;
      while (j < hi && static_cast<size_t>((blocks_[j].code >> shift) & 7u) == child) ++j;
      kind[child] = Child([&] { return Emit(i, j, depth + 1); });
      i = j;
    }
    return Close(at, kind, depth);
  }

  /// Depth 13 (the block), 14 (8 groups of 64 voxels), 15 (8 voxels: one mask byte).
  int EmitBlock(const Block& b) {
    const size_t at = out_.size();
    out_.append(2, '\0');
    std::array<int, 8> kind{};
    for (int s = 0; s < 8; ++s) {
      bool any = false;
      for (int g = 0; g < 8; ++g) any = any || b.known[static_cast<size_t>(8 * s + g)] != 0;
      if (any) kind[static_cast<size_t>(s)] = Child([&] { return EmitSub(b, s); });
    }
    return Close(at, kind, 13);
  }
  int EmitSub(const Block& b, int s) {
    const size_t at = out_.size();
    out_.append(2, '\0');
    std::array<int, 8> kind{};
    for (int g = 0; g < 8; ++g) {
      const auto m = static_cast<size_t>(8 * s + g);
      if (b.known[m] != 0) kind[static_cast<size_t>(g)] = Child([&] { return EmitGroup(b, m); });
    }
    return Close(at, kind, 14);
  }
  int EmitGroup(const Block& b, size_t m) {
    const size_t at = out_.size();
    out_.append(2, '\0');
    std::array<int, 8> kind{};
    for (int v = 0; v < 8; ++v) {
      if (((b.known[m] >> v) & 1u) == 0) continue;
      kind[static_cast<size_t>(v)] = ((b.occupied[m] >> v) & 1u) != 0 ? kOccupied : kFree;
    }
    return Close(at, kind, 15);
  }

  const std::vector<Block>& blocks_;
  std::string out_;
};

}  // namespace

Result<std::string> OctomapBinaryTree(const mapping::OccupancyGrid& grid) {
  const mapping::SensorModel& sensor = grid.sensor_model();
  // OcTree's settings (ConfigureTree): values clamped on insertion, then maximum likelihood.
  const float clamp_min = OctomapLogOdds(sensor.clamp_min);
  const float clamp_max = OctomapLogOdds(sensor.clamp_max);
  const float threshold = OctomapLogOdds(sensor.occupied_threshold);
  // Local index (x | y << 3 | z << 6) of each 3-level Morton code within a block.
  static const std::array<uint16_t, mapping::kBlockVoxels> kLocalOfMorton = [] {
    std::array<uint16_t, mapping::kBlockVoxels> t{};
    for (uint32_t i = 0; i < mapping::kBlockVoxels; ++i) {
      t[Interleave(i & 7u, (i >> 3) & 7u, (i >> 6) & 7u, 3)] = static_cast<uint16_t>(i);
    }
    return t;
  }();
  constexpr int32_t kBlockMin = mapping::kOctomapMinKey >> mapping::kBlockShift;
  constexpr int32_t kBlockMax = mapping::kOctomapMaxKey >> mapping::kBlockShift;
  std::vector<BinaryTreeWriter::Block> blocks;
  blocks.reserve(grid.num_blocks());
  Status outside = Status::Ok();
  grid.ForEachBlock([&](const mapping::OccupancyBlock& b) {
    if (!b.known.any()) return;
    const mapping::BlockKey& k = b.key;
    if (k.x < kBlockMin || k.x > kBlockMax || k.y < kBlockMin || k.y > kBlockMax ||
        k.z < kBlockMin || k.z > kBlockMax) {
      if (outside.ok()) {
        outside = OutOfRangeError(fmt::format(
            "the map has voxels outside OctoMap's 16-bit key range (block {} {} {}): it "
            "cannot be written as an OctoMap",
            k.x, k.y, k.z));
      }
      return;
    }
    const auto off = static_cast<uint32_t>(-kBlockMin);
    BinaryTreeWriter::Block& out = blocks.emplace_back();
    out.code = Interleave(static_cast<uint32_t>(k.x) + off, static_cast<uint32_t>(k.y) + off,
                          static_cast<uint32_t>(k.z) + off, 16 - mapping::kBlockShift);
    for (size_t m = 0; m < static_cast<size_t>(mapping::kBlockVoxels); ++m) {
      const int i = kLocalOfMorton[m];
      if (!b.known.test(i)) continue;
      const float v = std::min(std::max(b.log_odds[static_cast<size_t>(i)], clamp_min), clamp_max);
      const float ml = v >= threshold ? clamp_max : clamp_min;
      out.known[m / 8] = static_cast<uint8_t>(out.known[m / 8] | (1u << (m % 8)));
      if (ml >= threshold) {
        out.occupied[m / 8] = static_cast<uint8_t>(out.occupied[m / 8] | (1u << (m % 8)));
      }
    }
  });
  AVP_RETURN_IF_ERROR(outside);
  std::sort(blocks.begin(), blocks.end(),
            [](const auto& a, const auto& b) { return a.code < b.code; });
  return BinaryTreeWriter(blocks).Write();
}

InstanceImage InstanceIdImage(const Segmentation& s) {
  InstanceImage ids(s.width, s.height, 0);
  std::vector<float> best(ids.num_pixels(), -std::numeric_limits<float>::infinity());
  const size_t n = std::min<size_t>(s.instances.size(), 0xFFFE);
  for (size_t i = 0; i < n; ++i) {
    const InstanceMask& m = s.instances[i];
    if (!m.mask.SameSizeAs(ids)) continue;
    const auto mask = m.mask.data();
    auto out = ids.data();
    for (size_t p = 0; p < mask.size(); ++p) {
      if (mask[p] != 0 && m.confidence > best[p]) {
        best[p] = m.confidence;
        out[p] = static_cast<uint16_t>(i + 1);
      }
    }
  }
  return ids;
}

json InstancesToJson(const Segmentation& s) {
  json instances = json::array();
  for (const InstanceMask& m : s.instances) {
    json box = nullptr;
    if (m.box) box = {m.box->x0, m.box->y0, m.box->x1, m.box->y1};
    instances.push_back(
        {{"class", std::string(ToString(m.semantic_class))},
         {"label", m.label},
         {"score", m.confidence},
         {"mask_score", m.mask_score},
         {"box", box},
         {"mask",
          {{"size", {m.mask.height(), m.mask.width()}}, {"counts", io::MaskToRle(m.mask)}}}});
  }
  json timings = json::array();
  for (const StageTiming& t : s.timings) timings.push_back({{"stage", t.stage}, {"ms", t.ms}});
  return {{"width", s.width}, {"height", s.height}, {"instances", instances}, {"timings", timings}};
}

Result<Segmentation> InstancesFromJson(const json& j) {
  const std::string where = "instances JSON";
  AVP_RETURN_IF_ERROR(Field(j, "width", where));
  AVP_RETURN_IF_ERROR(Field(j, "height", where));
  AVP_RETURN_IF_ERROR(Field(j, "instances", where));
  try {
    Segmentation s;
    s.width = j.at("width").get<int>();
    s.height = j.at("height").get<int>();
    const json& list = j.at("instances");
    if (!list.is_array()) return InvalidArgumentError(where + ": 'instances' is not an array");
    for (size_t i = 0; i < list.size(); ++i) {
      const json& e = list[i];
      const std::string at = fmt::format("{}: instance {}", where, i);
      for (const char* key : {"class", "score", "mask"}) AVP_RETURN_IF_ERROR(Field(e, key, at));
      InstanceMask m;
      const std::string cls = e.at("class").get<std::string>();
      const std::optional<SemanticClass> c = SemanticClassFromString(cls);
      if (!c) return InvalidArgumentError(fmt::format("{}: unknown class '{}'", at, cls));
      m.semantic_class = *c;
      m.confidence = e.at("score").get<float>();
      m.label = e.value("label", std::string());
      m.mask_score = e.value("mask_score", -1.0f);
      if (e.contains("box") && !e.at("box").is_null()) {
        const auto b = e.at("box").get<std::vector<float>>();
        if (b.size() != 4) {
          return InvalidArgumentError(fmt::format("{}: 'box' has {} numbers, not 4", at, b.size()));
        }
        m.box = PixelBox{b[0], b[1], b[2], b[3]};
      }
      const json& mask = e.at("mask");
      AVP_RETURN_IF_ERROR(Field(mask, "size", at + " mask"));
      AVP_RETURN_IF_ERROR(Field(mask, "counts", at + " mask"));
      const auto size = mask.at("size").get<std::vector<int>>();
      if (size.size() != 2) {
        return InvalidArgumentError(fmt::format("{}: mask 'size' is not [height, width]", at));
      }
      const auto counts = mask.at("counts").get<std::vector<uint32_t>>();
      Result<MaskImage> bits = io::RleToMask(counts, size[1], size[0]);
      if (!bits.ok()) return bits.status().WithContext(at);
      m.mask = std::move(*bits);
      s.instances.push_back(std::move(m));
    }
    if (j.contains("timings") && j.at("timings").is_array()) {
      for (const json& t : j.at("timings")) {
        s.timings.push_back({t.value("stage", std::string()), t.value("ms", 0.0)});
      }
    }
    return s;
  } catch (const json::exception& e) {
    return InvalidArgumentError(fmt::format("{}: {}", where, e.what()));
  }
}

json PoseToJson(const RigidTransform& X) {
  const Eigen::Matrix3d& R = X.rotation();
  const Eigen::Vector3d& p = X.translation();
  return json::array({R(0, 0), R(0, 1), R(0, 2), p.x(), R(1, 0), R(1, 1), R(1, 2), p.y(), R(2, 0),
                      R(2, 1), R(2, 2), p.z()});
}

Result<RigidTransform> PoseFromJson(const json& j) {
  if (!j.is_array() || j.size() != 12) {
    return InvalidArgumentError(
        fmt::format("pose: expected 12 numbers (3x4 row-major), got {}", j.dump()));
  }
  double v[12];
  for (size_t i = 0; i < 12; ++i) {
    if (!j[i].is_number() || !std::isfinite(j[i].get<double>())) {
      return InvalidArgumentError(
          fmt::format("pose: element {} ({}) is not a finite number", i, j[i].dump()));
    }
    v[i] = j[i].get<double>();
  }
  Eigen::Matrix3d R;
  R << v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10];
  if (!IsRotationMatrix(R, 1e-6)) {
    return InvalidArgumentError(fmt::format("pose: {} is not a rotation", j.dump()));
  }
  return RigidTransform(R, Eigen::Vector3d(v[3], v[7], v[11]));
}

json StepToJson(const pipeline::StepRecord& s, const planning::PlanResult* plan, int64_t stamp_ns) {
  json metrics = json::array();
  for (const auto& [name, value] : s.metrics) metrics.push_back({name, Number(value)});
  const std::vector<planning::ViewCandidate>& ranked =
      plan != nullptr ? plan->ranked : s.top_candidates;
  json candidates = json::array();
  for (size_t i = 0; i < ranked.size(); ++i) {
    const planning::ViewCandidate& c = ranked[i];
    candidates.push_back({{"rank", i},
                          {"X_WC", PoseToJson(c.X_WC)},
                          {"q", Vector(c.q)},
                          {"reachable", c.reachable},
                          {"gain", Number(c.gain)},
                          {"cost", Number(c.cost)},
                          {"utility", Number(c.utility)},
                          {"source", c.source}});
  }
  const mapping::IntegrationStats& in = s.integration;
  return {{"view", s.view},
          {"views_total", s.views_total},
          {"stamp_ns", stamp_ns},
          {"X_WC", PoseToJson(s.X_WC)},
          {"q", Vector(s.q)},
          {"capture_status", StatusText(s.capture_status)},
          {"segment_status", StatusText(s.segment_status)},
          {"integrate_status", StatusText(s.integrate_status)},
          {"plan_status", StatusText(s.plan_status)},
          {"move_status", StatusText(s.move_status)},
          {"masks", s.masks},
          {"masks_without_depth", s.masks_without_depth},
          {"integration",
           {{"pixels", in.pixels},
            {"invalid_depth", in.invalid_depth},
            {"beyond_max_range", in.beyond_max_range},
            {"rejected_points", in.rejected_points},
            {"endpoints", in.endpoints},
            {"occupied_updates", in.occupied_updates},
            {"free_updates", in.free_updates},
            {"masked_endpoints", in.masked_endpoints}}},
          {"known_voxels", s.known_voxels},
          {"occupied_voxels", s.occupied_voxels},
          {"target_voxels", s.target_voxels},
          {"instances", s.instances},
          {"known_delta", s.known_delta},
          {"target_delta", s.target_delta},
          {"metrics", metrics},
          {"planned", s.planned},
          {"plan_stop", plan != nullptr && plan->stop},
          {"plan_stop_reason", plan != nullptr ? plan->stop_reason : std::string()},
          {"candidates_generated", s.candidates_generated},
          {"candidates_reachable", s.candidates_reachable},
          {"candidates", candidates},
          {"chosen_rank", s.chosen_rank},
          {"refused_moves", s.refused_moves},
          {"joint_path_length", Number(s.joint_path_length)},
          {"times",
           {{"capture_ms", s.times.capture_ms},
            {"segment_ms", s.times.segment_ms},
            {"integrate_ms", s.times.integrate_ms},
            {"metrics_ms", s.times.metrics_ms},
            {"plan_ms", s.times.plan_ms},
            {"move_ms", s.times.move_ms},
            {"total_ms", s.times.total_ms}}}};
}

ros::msg::MarkerArray CandidateMarkers(const std::vector<planning::ViewCandidate>& ranked,
                                       int chosen_rank, int view, const ros::msg::Header& header) {
  ros::msg::MarkerArray out;
  out.markers.push_back(ros::msg::DeleteAllMarker(header));
  if (ranked.empty()) return out;
  double lo = ranked.front().utility, hi = lo;
  for (const planning::ViewCandidate& c : ranked) {
    if (!std::isfinite(c.utility)) continue;
    lo = std::min(lo, c.utility);
    hi = std::max(hi, c.utility);
  }
  for (size_t i = 0; i < ranked.size(); ++i) {
    const planning::ViewCandidate& c = ranked[i];
    const bool chosen = static_cast<int>(i) == chosen_rank;
    const double t = hi > lo ? (c.utility - lo) / (hi - lo) : 1.0;
    out.markers.push_back(ros::msg::ViewArrowMarker(
        header, chosen ? "chosen" : "candidates", static_cast<int>(i), c.X_WC, chosen ? 0.15 : 0.08,
        chosen ? ros::msg::Vector3{0.015, 0.03, 0.04} : ros::msg::Vector3{0.008, 0.016, 0.024},
        chosen ? Rgba(1.0, 0.1, 0.6) : Viridis(t)));
  }
  if (chosen_rank >= 0 && static_cast<size_t>(chosen_rank) < ranked.size()) {
    const planning::ViewCandidate& c = ranked[static_cast<size_t>(chosen_rank)];
    out.markers.push_back(ros::msg::TextMarker(
        header, "chosen_text", 0, c.X_WC.translation() + Eigen::Vector3d(0, 0, 0.06),
        fmt::format("after view {}: rank {} of {}, utility {:.3g}, gain {:.3g}, cost {:.3g} "
                    "rad [{}]",
                    view + 1, chosen_rank, ranked.size(), c.utility, c.gain, c.cost, c.source),
        0.03, Rgba(1, 1, 1, 1)));
  }
  return out;
}

}  // namespace avp::ros::bag
