// Arrangements: a scene file's plant placed like each of the paper's tomato scenarios
// (docs/scene-format.md, "Arrangements"). Nothing here knows how a plant was made: the plant is
// every object that is neither ground nor background, its fruit are the fruit-class objects.
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/options.h>
#include <avp/core/text.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>

namespace avp::sim {

namespace {

bool IsPlant(const SceneObject& o) {
  return o.semantic_class != SemanticClass::kGround &&
         o.semantic_class != SemanticClass::kBackground;
}

/// The rotation by `deg` about the world z axis.
Eigen::Matrix3d Rz(double deg) {
  return Eigen::AngleAxisd(DegToRad(deg), Eigen::Vector3d::UnitZ()).toRotationMatrix();
}

/// The plant's turn by `yaw_deg` about the vertical axis through `center`, then `offset`.
RigidTransform PlantMotion(const Eigen::Vector3d& center, double yaw_deg,
                           const Eigen::Vector3d& offset) {
  if (yaw_deg == 0.0) return RigidTransform(offset);
  const Eigen::Vector3d axis(center.x(), center.y(), 0.0);
  const Eigen::Matrix3d R = Rz(yaw_deg);
  return RigidTransform(R, axis + offset - R * axis);
}

void MoveObject(SceneObject& o, const RigidTransform& X) {
  if (auto* mesh = std::get_if<TriangleMesh>(&o.shape)) {
    mesh->Transform(X);
  } else {
    Ellipsoid& e = std::get<Ellipsoid>(o.shape);
    e.center_W = X * e.center_W;
    e.R_WE = X.rotation() * e.R_WE;
  }
}

/// Which fields an item sets, for "set twice" errors.
struct Field {
  const char* name;
  std::string item;  ///< the item that set it; empty: not set
};

Status SetField(std::vector<Field>& fields, const char* name, std::string_view item,
                std::string_view spec) {
  for (Field& f : fields) {
    if (std::string_view(f.name) != name) continue;
    if (!f.item.empty()) {
      return InvalidArgumentError(fmt::format("arrangement {}: {} is set twice (by '{}' and by {})",
                                              QuoteText(spec), name, f.item, QuoteText(item)));
    }
    f.item = std::string(item);
    return Status::Ok();
  }
  return InternalError(fmt::format("arrangement field {}", name));
}

struct NumberKey {
  const char* key;
  const char* unit;
  double min, max;
};

constexpr NumberKey kNumberKeys[] = {
    {"plant-x", "m", -10.0, 10.0},       {"plant-y", "m", -10.0, 10.0},
    {"plant-z", "m", -10.0, 10.0},       {"plant-yaw", "deg", -360.0, 360.0},
    {"start-yaw", "deg", -180.0, 180.0}, {"cluster-gap", "m", 0.0, 1.0},
};

std::string KnownItems() {
  std::vector<std::string> known = ArrangementNames();
  for (const NumberKey& k : kNumberKeys) known.push_back(fmt::format("{}=<{}>", k.key, k.unit));
  return fmt::format("{}", fmt::join(known, ", "));
}

std::string FormatPoint2(const Eigen::Vector3d& p) {
  return fmt::format("({:.3f}, {:.3f})", p.x(), p.y());
}

}  // namespace

bool Arrangement::IsIdentity() const {
  return plant_offset_m.isZero(0.0) && plant_yaw_deg == 0.0 && !occluding_yaw && !single_cluster &&
         start_yaw_deg == 0.0;
}

const std::vector<std::string>& ArrangementNames() {
  static const std::vector<std::string> names = {"reference", "full-occlusion", "single-cluster",
                                                 "unoriented-start"};
  return names;
}

Result<Arrangement> ParseArrangement(std::string_view spec) {
  Arrangement a;
  a.spec = std::string(spec);
  if (spec.empty()) return a;
  std::vector<Field> fields = {{"plant-x", {}},    {"plant-y", {}},   {"plant-z", {}},
                               {"plant-yaw", {}},  {"start-yaw", {}}, {"single-cluster", {}},
                               {"cluster-gap", {}}};
  size_t start = 0;
  while (start <= spec.size()) {
    size_t end = spec.find('+', start);
    if (end == std::string_view::npos) end = spec.size();
    const std::string_view item = spec.substr(start, end - start);
    start = end + 1;
    if (item.empty()) {
      return InvalidArgumentError(fmt::format(
          "arrangement {} has an empty item (items are joined by '+')", QuoteText(spec)));
    }
    if (item == kPaperArrangements) {
      return InvalidArgumentError(fmt::format(
          "arrangement {}: 'paper' stands for the four arrangements {} and is taken only in an "
          "avp bench scenario list (scene.yaml@paper); name one of them",
          QuoteText(spec), fmt::join(ArrangementNames(), ", ")));
    }
    const size_t eq = item.find('=');
    if (eq == std::string_view::npos) {
      if (item == "reference") continue;
      if (item == "full-occlusion") {
        AVP_RETURN_IF_ERROR(SetField(fields, "plant-yaw", item, spec));
        a.occluding_yaw = true;
      } else if (item == "single-cluster") {
        AVP_RETURN_IF_ERROR(SetField(fields, "single-cluster", item, spec));
        a.single_cluster = true;
      } else if (item == "unoriented-start") {
        AVP_RETURN_IF_ERROR(SetField(fields, "plant-y", item, spec));
        AVP_RETURN_IF_ERROR(SetField(fields, "start-yaw", item, spec));
        a.plant_offset_m.y() = 0.4;
        a.start_yaw_deg = 20.0;
      } else {
        return InvalidArgumentError(fmt::format(
            "unknown arrangement {}{} (known: {})", QuoteText(item),
            item.size() == spec.size() ? std::string() : fmt::format(" in {}", QuoteText(spec)),
            KnownItems()));
      }
      continue;
    }
    const std::string_view key = item.substr(0, eq);
    const std::string_view text = item.substr(eq + 1);
    const auto k = std::find_if(std::begin(kNumberKeys), std::end(kNumberKeys),
                                [&](const NumberKey& n) { return key == n.key; });
    if (k == std::end(kNumberKeys)) {
      return InvalidArgumentError(fmt::format("arrangement {}: unknown key {} (known: {})",
                                              QuoteText(spec), QuoteText(key), KnownItems()));
    }
    const std::optional<double> v = options_internal::ParseReal(text);
    if (!v || !std::isfinite(*v) || *v < k->min || *v > k->max) {
      return InvalidArgumentError(
          fmt::format("arrangement {}: {} ({}) must be a number in [{}, {}] {}", QuoteText(spec),
                      k->key, QuoteText(text), k->min, k->max, k->unit));
    }
    AVP_RETURN_IF_ERROR(SetField(fields, k->key, item, spec));
    const std::string_view name = k->key;
    if (name == "plant-x") a.plant_offset_m.x() = *v;
    if (name == "plant-y") a.plant_offset_m.y() = *v;
    if (name == "plant-z") a.plant_offset_m.z() = *v;
    if (name == "plant-yaw") a.plant_yaw_deg = *v;
    if (name == "start-yaw") a.start_yaw_deg = *v;
    if (name == "cluster-gap") a.cluster_gap_m = *v;
  }
  if (!fields[6].item.empty() && !a.single_cluster) {
    return InvalidArgumentError(fmt::format(
        "arrangement {}: cluster-gap applies only with single-cluster", QuoteText(spec)));
  }
  return a;
}

std::vector<std::vector<uint16_t>> FruitClusters(const Scene& scene, double gap_m) {
  const std::vector<FruitTruth> fruits = scene.Fruits();
  const size_t n = fruits.size();
  // Union-find over the fruit (n is at most a few thousand: the pairwise test is cheap).
  std::vector<size_t> parent(n);
  std::iota(parent.begin(), parent.end(), size_t{0});
  const auto find = [&](size_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  for (size_t i = 0; i < n; ++i) {
    for (size_t j = i + 1; j < n; ++j) {
      const double reach = fruits[i].mean_radius_m() + fruits[j].mean_radius_m() + gap_m;
      if ((fruits[i].center_W - fruits[j].center_W).norm() <= reach) {
        const size_t a = find(i), b = find(j);
        parent[std::max(a, b)] = std::min(a, b);
      }
    }
  }
  std::vector<std::vector<uint16_t>> clusters;
  std::vector<size_t> cluster_of_root(n, std::numeric_limits<size_t>::max());
  for (size_t i = 0; i < n; ++i) {  // fruits are in id order: clusters by their first id
    const size_t r = find(i);
    if (cluster_of_root[r] == std::numeric_limits<size_t>::max()) {
      cluster_of_root[r] = clusters.size();
      clusters.emplace_back();
    }
    clusters[cluster_of_root[r]].push_back(fruits[i].instance_id);
  }
  return clusters;
}

namespace {

/// Pixels of class fruit in a rendered frame.
size_t FruitPixels(const RenderedFrame& frame) {
  size_t pixels = 0;
  for (uint8_t c : frame.class_ids.data()) {
    if (c == static_cast<uint8_t>(SemanticClass::kFruit)) ++pixels;
  }
  return pixels;
}

/// 1. The arm's start: joint 1 and the start camera with it.
Status TurnArmStart(Scene& scene, const Arrangement& arrangement, std::vector<std::string>& done) {
  if (arrangement.start_yaw_deg == 0.0) return Status::Ok();
  if (scene.start_joints_rad.empty()) {
    return InvalidArgumentError(
        fmt::format("scene {} has no start joints to turn by start-yaw {} deg",
                    QuoteText(scene.name), arrangement.start_yaw_deg));
  }
  scene.start_joints_rad[0] += DegToRad(arrangement.start_yaw_deg);
  scene.X_WC_start =
      RigidTransform(Rz(-arrangement.start_yaw_deg), Eigen::Vector3d::Zero()) * scene.X_WC_start;
  done.push_back(
      fmt::format("arm joint 1 turned by {} deg at the start", arrangement.start_yaw_deg));
  return Status::Ok();
}

/// The cluster to keep: the largest, the one whose centroid is nearest the start camera among
/// equals.
size_t LargestNearestCluster(const Scene& scene,
                             const std::vector<std::vector<uint16_t>>& clusters) {
  const std::vector<FruitTruth> fruits = scene.Fruits();
  const Eigen::Vector3d eye = scene.X_WC_start.translation();
  const auto centroid_distance = [&](const std::vector<uint16_t>& cluster) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (uint16_t id : cluster) {
      for (const FruitTruth& f : fruits) {
        if (f.instance_id == id) c += f.center_W;
      }
    }
    return (c / static_cast<double>(cluster.size()) - eye).norm();
  };
  size_t best = 0;
  double best_distance = centroid_distance(clusters[0]);
  for (size_t i = 1; i < clusters.size(); ++i) {
    const double d = centroid_distance(clusters[i]);
    if (clusters[i].size() > clusters[best].size() ||
        (clusters[i].size() == clusters[best].size() && d < best_distance)) {
      best = i;
      best_distance = d;
    }
  }
  return best;
}

/// 2. One fruit cluster kept (single-cluster).
Status KeepOneFruitCluster(Scene& scene, const Arrangement& arrangement, ArrangementReport& report,
                           std::vector<std::string>& done) {
  if (!arrangement.single_cluster) return Status::Ok();
  const std::vector<std::vector<uint16_t>> clusters =
      FruitClusters(scene, arrangement.cluster_gap_m);
  if (clusters.empty()) {
    return InvalidArgumentError(fmt::format(
        "scene {} has no fruit: single-cluster keeps one fruit cluster", QuoteText(scene.name)));
  }
  const std::vector<uint16_t>& keep = clusters[LargestNearestCluster(scene, clusters)];
  const size_t before = scene.objects.size();
  std::erase_if(scene.objects, [&](const SceneObject& o) {
    return o.semantic_class == SemanticClass::kFruit &&
           std::find(keep.begin(), keep.end(), o.instance_id) == keep.end();
  });
  report.fruits_removed = before - scene.objects.size();
  done.push_back(fmt::format(
      "kept the {} fruit of the largest of {} fruit clusters (surface gaps <= {} m), removed {}",
      keep.size(), clusters.size(), arrangement.cluster_gap_m, report.fruits_removed));
  scene.UpdatePlantBounds();
  return Status::Ok();
}

/// 3. The turn that hides the most fruit from the start camera (of 0, 15, ..., 345 deg), with the
/// fruit pixels of each in the report.
double OccludingYaw(const Scene& scene, const Arrangement& arrangement,
                    const CameraIntrinsics& camera, const Eigen::Vector3d& center,
                    ArrangementReport& report, std::vector<std::string>& done) {
  // The plant alone (ground and background stay where they are and never stand between the
  // camera and the plant), moved; the start camera turned the other way about the plant's axis
  // sees what the turned plant would show it.
  Scene plant;
  plant.name = scene.name;
  for (const SceneObject& o : scene.objects) {
    if (IsPlant(o)) plant.objects.push_back(o);
  }
  const RigidTransform move(arrangement.plant_offset_m);
  for (SceneObject& o : plant.objects) MoveObject(o, move);
  const Eigen::Vector3d moved_center = center + arrangement.plant_offset_m;
  const RgbdRenderer renderer(plant);
  double yaw = arrangement.plant_yaw_deg;
  size_t best_pixels = std::numeric_limits<size_t>::max();
  const int steps = static_cast<int>(std::lround(360.0 / kOcclusionYawStepDeg));
  for (int k = 0; k < steps; ++k) {
    const double candidate = kOcclusionYawStepDeg * k;
    const RigidTransform X_WC =
        PlantMotion(moved_center, -candidate, Eigen::Vector3d::Zero()) * scene.X_WC_start;
    const size_t pixels = FruitPixels(renderer.Render(camera, X_WC));
    report.fruit_pixels_by_yaw.push_back(pixels);
    if (pixels < best_pixels) {  // strictly fewer: ties keep the smaller yaw
      best_pixels = pixels;
      yaw = candidate;
    }
  }
  done.push_back(fmt::format(
      "plant turned {} deg about the vertical through {} (the yaw of 0, 15, ..., 345 that "
      "leaves the fewest fruit pixels in the start view: {}, {} at 0 deg)",
      yaw, FormatPoint2(center), best_pixels, report.fruit_pixels_by_yaw.front()));
  return yaw;
}

/// 4. The plant turned by `yaw` about the vertical through `center`, then moved.
void MovePlant(Scene& scene, const Arrangement& arrangement, const Eigen::Vector3d& center,
               double yaw, std::vector<std::string>& done) {
  if (yaw == 0.0 && arrangement.plant_offset_m.isZero(0.0)) return;
  const RigidTransform X = PlantMotion(center, yaw, arrangement.plant_offset_m);
  for (SceneObject& o : scene.objects) {
    if (IsPlant(o)) MoveObject(o, X);
  }
  if (!arrangement.plant_offset_m.isZero(0.0)) {
    done.push_back(fmt::format("plant moved by ({}, {}, {}) m", arrangement.plant_offset_m.x(),
                               arrangement.plant_offset_m.y(), arrangement.plant_offset_m.z()));
  }
}

}  // namespace

size_t CountFruitPixels(const Scene& scene, const CameraIntrinsics& camera,
                        const RigidTransform& X_WC) {
  const RgbdRenderer renderer(scene);
  return FruitPixels(renderer.Render(camera, X_WC));
}

Result<ArrangementReport> ApplyArrangement(Scene& scene, const Arrangement& arrangement,
                                           const CameraIntrinsics& camera) {
  ArrangementReport report;
  report.fruits_kept = scene.Fruits().size();
  if (arrangement.spec.empty() && arrangement.IsIdentity()) return report;
  scene.UpdatePlantBounds();
  if (scene.plant_bounds.IsEmpty()) {
    return InvalidArgumentError(
        fmt::format("scene {} has no plant to arrange (every object is ground or background)",
                    QuoteText(scene.name)));
  }
  std::vector<std::string> done;
  AVP_RETURN_IF_ERROR(TurnArmStart(scene, arrangement, done));
  AVP_RETURN_IF_ERROR(KeepOneFruitCluster(scene, arrangement, report, done));
  report.fruits_kept = scene.Fruits().size();

  // 3. The turn (fixed, or the one hiding the most fruit from the start camera), 4. the move.
  const Eigen::Vector3d center = scene.plant_bounds.center();
  double yaw = arrangement.plant_yaw_deg;
  if (arrangement.occluding_yaw) {
    yaw = OccludingYaw(scene, arrangement, camera, center, report, done);
  } else if (yaw != 0.0) {
    done.push_back(fmt::format("plant turned {} deg about the vertical through {}", yaw,
                               FormatPoint2(center)));
  }
  report.plant_yaw_deg = yaw;
  MovePlant(scene, arrangement, center, yaw, done);
  scene.UpdatePlantBounds();

  if (done.empty()) done.push_back("as the file places it");
  report.summary =
      fmt::format("arrangement {}: {}", arrangement.spec.empty() ? "custom" : arrangement.spec,
                  fmt::join(done, "; "));
  if (!arrangement.spec.empty()) scene.name += "@" + arrangement.spec;
  scene.description += scene.description.empty() ? report.summary : " (" + report.summary + ")";
  return report;
}

}  // namespace avp::sim
