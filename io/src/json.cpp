#include <cmath>
#include <limits>

#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/io/file.h>
#include <avp/io/json.h>

namespace avp::io {

nlohmann::json ToJson(const CameraIntrinsics& K) {
  return {{"width", K.width},
          {"height", K.height},
          {"fx", K.fx},
          {"fy", K.fy},
          {"cx", K.cx},
          {"cy", K.cy},
          {"min_depth_m", K.min_depth_m},
          {"max_depth_m", K.max_depth_m},
          {"K", {{K.fx, 0.0, K.cx}, {0.0, K.fy, K.cy}, {0.0, 0.0, 1.0}}},
          {"distortion_model", "none"},
          {"pixel_convention", "pixel (u, v) centre at continuous coordinates (u, v)"}};
}

nlohmann::json ToJson(const RigidTransform& X) {
  const Eigen::Quaterniond q = X.quaternion();
  const Eigen::Vector3d rpy = X.rpy();
  const Eigen::Matrix4d M = X.ToMatrix4();
  nlohmann::json matrix = nlohmann::json::array();
  for (int r = 0; r < 4; ++r) matrix.push_back({M(r, 0), M(r, 1), M(r, 2), M(r, 3)});
  return {{"translation_m", {X.translation().x(), X.translation().y(), X.translation().z()}},
          {"quaternion_wxyz", {q.w(), q.x(), q.y(), q.z()}},
          {"rpy_rad", {rpy.x(), rpy.y(), rpy.z()}},
          {"matrix", matrix}};
}

namespace {

Result<double> Number(const nlohmann::json& j, const char* key, const char* context) {
  if (!j.is_object() || !j.contains(key)) {
    return InvalidArgumentError(fmt::format("{}: missing field '{}'", context, key));
  }
  const nlohmann::json& v = j.at(key);
  if (!v.is_number() || !std::isfinite(v.get<double>())) {
    return InvalidArgumentError(fmt::format("{}: field '{}' must be a finite number, got {}",
                                            context, key, EscapeText(v.dump())));
  }
  return v.get<double>();
}

Result<std::vector<double>> Numbers(const nlohmann::json& j, const char* key, size_t n,
                                    const char* context) {
  if (!j.is_object() || !j.contains(key)) {
    return InvalidArgumentError(fmt::format("{}: missing field '{}'", context, key));
  }
  const nlohmann::json& v = j.at(key);
  if (!v.is_array() || v.size() != n) {
    return InvalidArgumentError(fmt::format("{}: field '{}' must be an array of {} numbers, got {}",
                                            context, key, n, EscapeText(v.dump())));
  }
  std::vector<double> out;
  for (const auto& x : v) {
    if (!x.is_number() || !std::isfinite(x.get<double>())) {
      return InvalidArgumentError(fmt::format("{}: field '{}' must hold finite numbers, got {}",
                                              context, key, EscapeText(v.dump())));
    }
    out.push_back(x.get<double>());
  }
  return out;
}

}  // namespace

Result<CameraIntrinsics> IntrinsicsFromJson(const nlohmann::json& j) {
  constexpr const char* kContext = "camera intrinsics";
  CameraIntrinsics K;
  AVP_ASSIGN_OR_RETURN(const double width, Number(j, "width", kContext));
  AVP_ASSIGN_OR_RETURN(const double height, Number(j, "height", kContext));
  // Range-checked before the cast: converting a double outside int's range is undefined.
  constexpr double kMaxInt = std::numeric_limits<int>::max();
  if (width != std::floor(width) || height != std::floor(height) || std::abs(width) > kMaxInt ||
      std::abs(height) > kMaxInt) {
    return InvalidArgumentError(fmt::format(
        "{}: width ({}) and height ({}) must be integers in int range", kContext, width, height));
  }
  K.width = static_cast<int>(width);
  K.height = static_cast<int>(height);
  AVP_ASSIGN_OR_RETURN(K.fx, Number(j, "fx", kContext));
  AVP_ASSIGN_OR_RETURN(K.fy, Number(j, "fy", kContext));
  AVP_ASSIGN_OR_RETURN(K.cx, Number(j, "cx", kContext));
  AVP_ASSIGN_OR_RETURN(K.cy, Number(j, "cy", kContext));
  if (j.contains("min_depth_m")) {
    AVP_ASSIGN_OR_RETURN(K.min_depth_m, Number(j, "min_depth_m", kContext));
  }
  if (j.contains("max_depth_m")) {
    AVP_ASSIGN_OR_RETURN(K.max_depth_m, Number(j, "max_depth_m", kContext));
  }
  AVP_RETURN_IF_ERROR(K.Validate());
  return K;
}

Result<RigidTransform> TransformFromJson(const nlohmann::json& j) {
  constexpr const char* kContext = "transform";
  if (j.is_object() && j.contains("translation_m") && j.contains("quaternion_wxyz")) {
    AVP_ASSIGN_OR_RETURN(const std::vector<double> t, Numbers(j, "translation_m", 3, kContext));
    AVP_ASSIGN_OR_RETURN(const std::vector<double> q, Numbers(j, "quaternion_wxyz", 4, kContext));
    const Eigen::Quaterniond quat(q[0], q[1], q[2], q[3]);
    if (std::abs(quat.norm() - 1.0) > 1e-3) {
      return InvalidArgumentError(
          fmt::format("{}: quaternion_wxyz [{}] must have unit norm (norm {})", kContext,
                      fmt::join(q, ", "), quat.norm()));
    }
    return RigidTransform(quat, Eigen::Vector3d(t[0], t[1], t[2]));
  }
  if (j.is_object() && j.contains("matrix") && j.at("matrix").is_array() &&
      j.at("matrix").size() == 4) {
    Eigen::Matrix4d M;
    for (int r = 0; r < 4; ++r) {
      const std::string row_key = fmt::format("matrix[{}]", r);  // errors name the row
      AVP_ASSIGN_OR_RETURN(
          const std::vector<double> row,
          Numbers(nlohmann::json{{row_key, j.at("matrix")[r]}}, row_key.c_str(), 4, kContext));
      for (int c = 0; c < 4; ++c) M(r, c) = row[c];
    }
    const Eigen::Matrix3d R = M.topLeftCorner<3, 3>();
    if (!IsRotationMatrix(R, 1e-5) || !M.row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1))) {
      return InvalidArgumentError(fmt::format("{}: 'matrix' is not a rigid transform", kContext));
    }
    return RigidTransform(R, Eigen::Vector3d(M.topRightCorner<3, 1>()));
  }
  return InvalidArgumentError(
      fmt::format("{}: expected 'translation_m' + 'quaternion_wxyz' or a 4x4 'matrix', got {}",
                  kContext, EscapeText(j.dump())));
}

Status WriteJsonFile(const std::filesystem::path& path, const nlohmann::json& j) {
  // Invalid UTF-8 in a string (a name from a file) is replaced (U+FFFD), not thrown.
  return WriteFileAtomic(
      path, j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n", "JSON file");
}

Result<nlohmann::json> ReadJsonFile(const std::filesystem::path& path) {
  AVP_ASSIGN_OR_RETURN(const std::string text, ReadFileBounded(path, "JSON file"));
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    // nlohmann quotes the text it last read: the file's bytes, escaped before they reach a
    // terminal.
    return ParseError(
        fmt::format("malformed JSON in '{}': {}", path.string(), EscapeText(e.what(), 200)));
  }
}

}  // namespace avp::io
