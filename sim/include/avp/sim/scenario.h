#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/registry.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/sim/scene.h>

namespace avp::sim {

/// A named, seeded scene generator (a user picks it with --scenario NAME): the paper's
/// experiments, or any a program registers.
struct ScenarioEntry {
  std::string name;         ///< e.g. "tomato-full-occlusion"
  std::string description;  ///< one line, shown by `avp scenes`
  /// The scene for `seed` (deterministic: the same seed, the same scene on any machine). Make()
  /// sets its name, description and seed and finishes it (triangle counts, plant bounds).
  std::function<Result<Scene>(uint64_t seed)> build;

  bool Matches(std::string_view spec) const { return name == spec; }
  std::string DisplayName() const { return name; }
  bool HasFactory() const { return static_cast<bool>(build); }
};

/// The scenarios a program knows, in registration order (NamedRegistry: Add, Find, Get, Names,
/// entries). Built once at start-up, read-only afterwards.
class ScenarioRegistry : public NamedRegistry<ScenarioEntry> {
 public:
  ScenarioRegistry() : NamedRegistry("scenario") {}
  /// The scene of `name` for `seed`. Errors: NotFound naming the unknown scenario and listing
  /// the known ones; the builder's errors.
  Result<Scene> Make(std::string_view name, uint64_t seed) const;
};

/// Registers the built-in scenarios (the paper's four tomato experiments and three espaliers).
/// @throws avp::Error if a name is already taken.
void RegisterBuiltinScenarios(ScenarioRegistry& registry);
/// A registry with RegisterBuiltinScenarios only.
ScenarioRegistry BuiltinScenarios();

/// The scenario used when none is named ("tomato-multiple-clusters").
std::string_view DefaultScenarioName();

/// A built-in scenario's scene: BuiltinScenarios().Make(name, seed).
Result<Scene> MakeScenario(std::string_view name, uint64_t seed);

/// Where a command's scene comes from: a registered scenario (seeded) or a YAML scene file.
struct SceneSource {
  std::string scenario;              ///< empty: use scene_file, or the default scenario
  std::filesystem::path scene_file;  ///< a YAML scene (docs/scene-format.md)
  uint64_t seed = 0;
};

/// Builds the scene of `source` from `scenarios` or the file; errors name the bad scenario or
/// file. Giving both is an error.
Result<Scene> LoadScene(const SceneSource& source, const ScenarioRegistry& scenarios);

// ---- Arm start configuration shared by the scenarios (and scene files) --------------------------

/// The reference start configuration in the official igus ReBeL URDF's joint convention, degrees:
/// q = (0, -70, 60, 0, 47.5, 0). FK puts the flange at (0.190, 0, 0.617) m with its axes aligned
/// to the world (x = approach = world +x).
inline constexpr double kReferenceStartJointsDeg[6] = {0.0, -70.0, 60.0, 0.0, 47.5, 0.0};

/// Joint radians of the reference start with joint 1 set to `yaw_q1_deg` (joint 1 turns about
/// -z in this URDF, so q1 = +theta yaws the view by -theta, towards -y).
std::vector<double> ReferenceStartJointsRad(double yaw_q1_deg = 0.0);

/// The nominal camera optical frame at ReferenceStartJointsRad(yaw_q1_deg): the default mount
/// (optical z = flange x, optical x = -flange y, optical y = -flange z, offset (0.03, 0, 0.06) m in
/// the flange frame) on the reference flange pose, rotated by -q1 about the world z axis through
/// the base. At q1 = 0: eye (0.22, 0, 0.677) looking along +x with image up = world +z.
RigidTransform ReferenceStartCameraPose(double yaw_q1_deg = 0.0);

/// Adds a flat ground rectangle at height `z_m` (class ground, 2 triangles) spanning x in
/// [-1.5, 2.5] and y in [-2, 2] m; returns its instance id.
uint16_t AddGroundPlane(Scene& scene, double z_m = 0.0);

}  // namespace avp::sim
