#pragma once

// `avp render`: one simulated RGB-D + labels view of a scene, written to a folder.

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <avp/core/camera.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene.h>

namespace avp::experiment {

/// `avp render`: one simulated RGB-D + labels view written to a folder.
struct RenderOptions {
  sim::SceneSource scene;
  /// Arm joints in degrees (URDF convention); the camera pose is FK + mount.
  std::optional<std::vector<double>> joints_deg;
  /// Camera optical frame pose x, y, z (m), roll, pitch, yaw (deg) in the world (robot base) frame.
  std::optional<std::vector<double>> camera_pose;
  /// Arm configuration YAML; empty = the default igus ReBeL with a D435.
  std::filesystem::path arm_config;
  CameraIntrinsics intrinsics = CameraIntrinsics::RealSenseD435();
  /// Apply the seeded D435-like depth noise model (on by default, as in episodes; seeded from
  /// scene.seed).
  bool noise = true;
  std::filesystem::path out_dir = "out/render";
  /// Replace an earlier render's files in out_dir (the output rule: a folder holding anything is
  /// refused otherwise, and another command's folder always).
  bool force = false;
  /// Called once with the loaded scene (e.g. to print its warnings); may be empty.
  std::function<void(const sim::Scene&)> on_scene;
};

struct RenderSummary {
  RigidTransform X_WC;
  std::vector<double> joints_deg;  ///< empty when the pose was given directly
  size_t num_triangles = 0;
  size_t fruit_pixels = 0;
  size_t visible_fruits = 0;  ///< fruits with at least one pixel
  size_t total_fruits = 0;
  size_t valid_depth_pixels = 0;
  double render_ms = 0.0;
  std::vector<std::filesystem::path> files;
};

/// Renders and writes rgb.png, depth.png (uint16 mm), instance.png (uint16), class.png (uint8),
/// labels_preview.png, camera.json and fruits.json, between avp-state.json's "in-progress" and
/// "complete" (output_folder.h: a folder holding anything is refused before anything is
/// rendered, unless force and it is a render folder). Errors name the bad value (unknown scenario,
/// wrong joint count, unreachable or out-of-limit joints, unwritable folder ...).
Result<RenderSummary> RenderToFolder(const RenderOptions& options,
                                     const sim::ScenarioRegistry& scenarios);

}  // namespace avp::experiment
