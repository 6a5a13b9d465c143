#pragma once

#include <filesystem>

#include <nlohmann/json.hpp>

#include <avp/core/camera.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>

namespace avp::io {

/// {"width", "height", "fx", "fy", "cx", "cy", "min_depth_m", "max_depth_m", "K": [[...]x3]}
nlohmann::json ToJson(const CameraIntrinsics& K);
/// {"translation_m": [x, y, z], "quaternion_wxyz": [w, x, y, z], "rpy_rad": [...], "matrix": 4x4}
nlohmann::json ToJson(const RigidTransform& X);

/// Parses ToJson(CameraIntrinsics) output; errors name the missing or bad field.
Result<CameraIntrinsics> IntrinsicsFromJson(const nlohmann::json& j);
/// Parses {"translation_m", "quaternion_wxyz"} (or "matrix").
Result<RigidTransform> TransformFromJson(const nlohmann::json& j);

/// Writes `j` pretty-printed (2 spaces) and a trailing newline; creates parent folders.
Status WriteJsonFile(const std::filesystem::path& path, const nlohmann::json& j);
Result<nlohmann::json> ReadJsonFile(const std::filesystem::path& path);

}  // namespace avp::io
