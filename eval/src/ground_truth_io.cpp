#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/eval/ground_truth_io.h>

namespace avp::eval {
namespace {

constexpr const char* kFormat = "avp-ground-truth";
constexpr int kVersion = 1;

nlohmann::json Vec3(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

template <typename Map>
std::vector<std::pair<uint16_t, typename Map::mapped_type>> SortedById(const Map& m) {
  std::vector<std::pair<uint16_t, typename Map::mapped_type>> out(m.begin(), m.end());
  std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  return out;
}

Status Bad(const std::string& field, const std::string& requirement, const nlohmann::json& v) {
  return InvalidArgumentError(fmt::format("ground truth: {} must be {}, got {}", field, requirement,
                                          EscapeText(v.dump(), 120)));
}

Result<const nlohmann::json*> Field(const nlohmann::json& j, const std::string& where,
                                    const char* key) {
  if (!j.is_object()) return Bad(where, "an object", j);
  const auto it = j.find(key);
  if (it == j.end()) {
    return InvalidArgumentError(
        fmt::format("ground truth: {}{}missing field '{}'", where, where.empty() ? "" : ": ", key));
  }
  return &*it;
}

std::string Join(const std::string& where, const char* key) {
  return where.empty() ? std::string(key) : where + "." + key;
}

Result<double> Finite(const nlohmann::json& v, const std::string& field) {
  if (!v.is_number() || !std::isfinite(v.get<double>())) return Bad(field, "a finite number", v);
  return v.get<double>();
}

/// An integer in [lo, hi] (JSON integers, or a double with an integral value).
Result<int64_t> Integer(const nlohmann::json& v, const std::string& field, int64_t lo, int64_t hi,
                        const char* range_text) {
  const std::string requirement = fmt::format("an integer in {}", range_text);
  if (v.is_number_unsigned()) {
    const uint64_t u = v.get<uint64_t>();
    if (u > static_cast<uint64_t>(hi)) return Bad(field, requirement, v);
    return static_cast<int64_t>(u);
  }
  if (v.is_number_integer()) {
    const int64_t i = v.get<int64_t>();
    if (i < lo || i > hi) return Bad(field, requirement, v);
    return i;
  }
  if (v.is_number_float()) {
    const double d = v.get<double>();
    if (std::isfinite(d) && d == std::floor(d) && d >= static_cast<double>(lo) &&
        d <= static_cast<double>(hi)) {
      return static_cast<int64_t>(d);
    }
  }
  return Bad(field, requirement, v);
}

Result<const nlohmann::json*> Array(const nlohmann::json& j, const char* key, size_t size_or_0) {
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* v, Field(j, "", key));
  if (!v->is_array() || (size_or_0 != 0 && v->size() != size_or_0)) {
    return Bad(key, size_or_0 ? fmt::format("an array of {}", size_or_0) : "an array", *v);
  }
  return v;
}

Result<Eigen::Vector3d> Vector3(const nlohmann::json& v, const std::string& field) {
  if (!v.is_array() || v.size() != 3) return Bad(field, "an array of 3 finite numbers", v);
  Eigen::Vector3d out;
  for (int i = 0; i < 3; ++i) {
    AVP_ASSIGN_OR_RETURN(out[i], Finite(v[i], fmt::format("{}[{}]", field, i)));
  }
  return out;
}

constexpr int64_t kMaxSize = std::numeric_limits<int64_t>::max();

}  // namespace

nlohmann::json GroundTruthToJson(const GroundTruth& truth) {
  nlohmann::json voxels = nlohmann::json::array();
  for (const VoxelKey& k : truth.SortedKeys()) {
    voxels.push_back({k.x, k.y, k.z, truth.voxels.at(k)});
  }
  nlohmann::json fruits = nlohmann::json::array();
  for (const sim::FruitTruth& f : truth.fruits) {
    fruits.push_back({{"instance_id", f.instance_id},
                      {"name", f.name},
                      {"center_W", Vec3(f.center_W)},
                      {"radii", Vec3(f.radii)}});
  }
  nlohmann::json per_fruit = nlohmann::json::array();
  for (const auto& [id, n] : SortedById(truth.voxels_per_fruit)) per_fruit.push_back({id, n});
  nlohmann::json visible = nlohmann::json::array();
  for (const auto& [id, f] : SortedById(truth.best_visible_fraction)) visible.push_back({id, f});
  nlohmann::json views = nlohmann::json::array();
  for (const ObservationView& v : truth.views) {
    const Eigen::Matrix3d& R = v.X_WC.rotation();
    const Eigen::Vector3d& p = v.X_WC.translation();
    nlohmann::json X = nlohmann::json::array();
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) X.push_back(R(r, c));
      X.push_back(p[r]);
    }
    views.push_back({{"fruit_id", v.fruit_id},
                     {"radius_m", v.radius_m},
                     {"azimuth_deg", v.azimuth_deg},
                     {"elevation_deg", v.elevation_deg},
                     {"X_WC", std::move(X)}});
  }
  return {{"format", kFormat},
          {"version", kVersion},
          {"source", truth.source},
          {"voxel_size_m", truth.voxel_size_m},
          {"voxels", std::move(voxels)},
          {"fruits", std::move(fruits)},
          {"voxels_per_fruit", std::move(per_fruit)},
          {"best_visible_fraction", std::move(visible)},
          {"views_tried", truth.views_tried},
          {"views_reachable", truth.views_reachable},
          {"views", std::move(views)}};
}

namespace {

constexpr int64_t kI32Lo = std::numeric_limits<int32_t>::min();
constexpr int64_t kI32Hi = std::numeric_limits<int32_t>::max();

/// "format" and "version" checked, then "source" and "voxel_size_m".
Status ReadHeader(const nlohmann::json& j, GroundTruth& truth) {
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* format, Field(j, "", "format"));
  if (!format->is_string() || format->get<std::string>() != kFormat) {
    return Bad("format", fmt::format("\"{}\"", kFormat), *format);
  }
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* version, Field(j, "", "version"));
  if (!version->is_number_integer() || version->get<int64_t>() != kVersion) {
    return Bad("version", fmt::format("{} (the version this avp reads)", kVersion), *version);
  }
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* source, Field(j, "", "source"));
  if (!source->is_string()) return Bad("source", "a string", *source);
  truth.source = source->get<std::string>();
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* size, Field(j, "", "voxel_size_m"));
  AVP_ASSIGN_OR_RETURN(truth.voxel_size_m, Finite(*size, "voxel_size_m"));
  if (!(truth.voxel_size_m > 0.0)) return Bad("voxel_size_m", "> 0", *size);
  return Status::Ok();
}

/// "voxels": [x, y, z, fruit_id] each, every voxel once.
Status ReadVoxels(const nlohmann::json& j, GroundTruth& truth) {
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* voxels, Array(j, "voxels", 0));
  truth.voxels.reserve(voxels->size());
  for (size_t i = 0; i < voxels->size(); ++i) {
    const nlohmann::json& e = (*voxels)[i];
    const std::string field = fmt::format("voxels[{}]", i);
    if (!e.is_array() || e.size() != 4) return Bad(field, "[x, y, z, fruit_id]", e);
    int64_t xyz[3];
    for (int a = 0; a < 3; ++a) {
      AVP_ASSIGN_OR_RETURN(
          xyz[a], Integer(e[a], fmt::format("{}[{}]", field, a), kI32Lo, kI32Hi, "int32 range"));
    }
    AVP_ASSIGN_OR_RETURN(const int64_t id, Integer(e[3], field + "[3]", 0, 65535, "[0, 65535]"));
    const VoxelKey key{static_cast<int32_t>(xyz[0]), static_cast<int32_t>(xyz[1]),
                       static_cast<int32_t>(xyz[2])};
    if (!truth.voxels.emplace(key, static_cast<uint16_t>(id)).second) {
      return Bad(field, "a voxel listed once", e);
    }
  }
  return Status::Ok();
}

/// One entry of "fruits": instance_id, name, center_W, radii (>= 0).
Result<sim::FruitTruth> ReadFruit(const nlohmann::json& e, const std::string& where) {
  sim::FruitTruth f;
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* id, Field(e, where, "instance_id"));
  AVP_ASSIGN_OR_RETURN(const int64_t id_value,
                       Integer(*id, Join(where, "instance_id"), 0, 65535, "[0, 65535]"));
  f.instance_id = static_cast<uint16_t>(id_value);
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* name, Field(e, where, "name"));
  if (!name->is_string()) return Bad(Join(where, "name"), "a string", *name);
  f.name = name->get<std::string>();
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* c, Field(e, where, "center_W"));
  AVP_ASSIGN_OR_RETURN(f.center_W, Vector3(*c, Join(where, "center_W")));
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* r, Field(e, where, "radii"));
  AVP_ASSIGN_OR_RETURN(f.radii, Vector3(*r, Join(where, "radii")));
  if (f.radii.minCoeff() < 0.0) return Bad(Join(where, "radii"), "radii >= 0", *r);
  return f;
}

/// "voxels_per_fruit": [fruit_id, count] each, every fruit once.
Status ReadVoxelsPerFruit(const nlohmann::json& j, GroundTruth& truth) {
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* per_fruit, Array(j, "voxels_per_fruit", 0));
  for (size_t i = 0; i < per_fruit->size(); ++i) {
    const nlohmann::json& e = (*per_fruit)[i];
    const std::string field = fmt::format("voxels_per_fruit[{}]", i);
    if (!e.is_array() || e.size() != 2) return Bad(field, "[fruit_id, count]", e);
    AVP_ASSIGN_OR_RETURN(const int64_t id, Integer(e[0], field + "[0]", 0, 65535, "[0, 65535]"));
    AVP_ASSIGN_OR_RETURN(const int64_t n, Integer(e[1], field + "[1]", 0, kMaxSize, ">= 0"));
    if (!truth.voxels_per_fruit.emplace(static_cast<uint16_t>(id), static_cast<size_t>(n)).second) {
      return Bad(field, "a fruit listed once", e);
    }
  }
  return Status::Ok();
}

/// "best_visible_fraction": [fruit_id, fraction in [0, 1]] each, every fruit once.
Status ReadBestVisibleFractions(const nlohmann::json& j, GroundTruth& truth) {
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* visible, Array(j, "best_visible_fraction", 0));
  for (size_t i = 0; i < visible->size(); ++i) {
    const nlohmann::json& e = (*visible)[i];
    const std::string field = fmt::format("best_visible_fraction[{}]", i);
    if (!e.is_array() || e.size() != 2) return Bad(field, "[fruit_id, fraction]", e);
    AVP_ASSIGN_OR_RETURN(const int64_t id, Integer(e[0], field + "[0]", 0, 65535, "[0, 65535]"));
    AVP_ASSIGN_OR_RETURN(const double f, Finite(e[1], field + "[1]"));
    if (f < 0.0 || f > 1.0) return Bad(field + "[1]", "a fraction in [0, 1]", e[1]);
    if (!truth.best_visible_fraction.emplace(static_cast<uint16_t>(id), f).second) {
      return Bad(field, "a fruit listed once", e);
    }
  }
  return Status::Ok();
}

/// A view's "X_WC": 12 numbers, 3x4 [R | p] row-major, R a rotation.
Result<RigidTransform> ReadViewPose(const nlohmann::json& X, const std::string& x_field) {
  if (!X.is_array() || X.size() != 12) {
    return Bad(x_field, "an array of 12 numbers (3x4 [R | p], row-major)", X);
  }
  Eigen::Matrix3d R;
  Eigen::Vector3d p;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) {
      AVP_ASSIGN_OR_RETURN(const double value,
                           Finite(X[r * 4 + c], fmt::format("{}[{}]", x_field, r * 4 + c)));
      if (c < 3) {
        R(r, c) = value;
      } else {
        p[r] = value;
      }
    }
  }
  if (!IsRotationMatrix(R, 1e-6)) {
    return Bad(x_field, "a rigid transform (orthonormal rotation, det +1)", X);
  }
  return RigidTransform(R, p);
}

/// One entry of "views": fruit_id, radius_m, azimuth_deg, elevation_deg, X_WC.
Result<ObservationView> ReadView(const nlohmann::json& e, const std::string& where) {
  ObservationView v;
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* id, Field(e, where, "fruit_id"));
  AVP_ASSIGN_OR_RETURN(const int64_t id_value,
                       Integer(*id, Join(where, "fruit_id"), 0, 65535, "[0, 65535]"));
  v.fruit_id = static_cast<uint16_t>(id_value);
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* radius, Field(e, where, "radius_m"));
  AVP_ASSIGN_OR_RETURN(v.radius_m, Finite(*radius, Join(where, "radius_m")));
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* az, Field(e, where, "azimuth_deg"));
  AVP_ASSIGN_OR_RETURN(v.azimuth_deg, Finite(*az, Join(where, "azimuth_deg")));
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* el, Field(e, where, "elevation_deg"));
  AVP_ASSIGN_OR_RETURN(v.elevation_deg, Finite(*el, Join(where, "elevation_deg")));
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* X, Field(e, where, "X_WC"));
  AVP_ASSIGN_OR_RETURN(v.X_WC, ReadViewPose(*X, Join(where, "X_WC")));
  return v;
}

/// "views_tried", "views_reachable" (<= views_tried) and "views".
Status ReadViews(const nlohmann::json& j, GroundTruth& truth) {
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* tried, Field(j, "", "views_tried"));
  AVP_ASSIGN_OR_RETURN(const int64_t tried_n, Integer(*tried, "views_tried", 0, kMaxSize, ">= 0"));
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* reachable, Field(j, "", "views_reachable"));
  AVP_ASSIGN_OR_RETURN(const int64_t reachable_n,
                       Integer(*reachable, "views_reachable", 0, tried_n, "[0, views_tried]"));
  truth.views_tried = static_cast<size_t>(tried_n);
  truth.views_reachable = static_cast<size_t>(reachable_n);
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* views, Array(j, "views", 0));
  truth.views.reserve(views->size());
  for (size_t i = 0; i < views->size(); ++i) {
    AVP_ASSIGN_OR_RETURN(ObservationView v, ReadView((*views)[i], fmt::format("views[{}]", i)));
    truth.views.push_back(std::move(v));
  }
  return Status::Ok();
}

}  // namespace

Result<GroundTruth> GroundTruthFromJson(const nlohmann::json& j) {
  if (!j.is_object()) return Bad("the document", "a JSON object", j);
  GroundTruth truth;
  AVP_RETURN_IF_ERROR(ReadHeader(j, truth));
  AVP_RETURN_IF_ERROR(ReadVoxels(j, truth));
  AVP_ASSIGN_OR_RETURN(const nlohmann::json* fruits, Array(j, "fruits", 0));
  for (size_t i = 0; i < fruits->size(); ++i) {
    AVP_ASSIGN_OR_RETURN(sim::FruitTruth f, ReadFruit((*fruits)[i], fmt::format("fruits[{}]", i)));
    truth.fruits.push_back(std::move(f));
  }
  AVP_RETURN_IF_ERROR(ReadVoxelsPerFruit(j, truth));
  AVP_RETURN_IF_ERROR(ReadBestVisibleFractions(j, truth));
  AVP_RETURN_IF_ERROR(ReadViews(j, truth));
  return truth;
}

}  // namespace avp::eval
