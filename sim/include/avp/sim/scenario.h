#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/sim/scene.h>

namespace avp::sim {

/// A named, seeded scene generator mirroring one of the paper's experiments.
struct ScenarioInfo {
  std::string name;         ///< e.g. "tomato-full-occlusion"
  std::string description;  ///< one line, shown by `avp scenes`
};

/// Every built-in scenario, in a stable order. The first is the default.
const std::vector<ScenarioInfo>& ListScenarios();
/// The scenario used when none is named ("tomato-multiple-clusters").
std::string_view DefaultScenarioName();

/// Builds the scenario's scene for `seed`: the same (name, seed) gives an identical scene on any
/// machine, and different seeds give different plants of the same kind.
/// Errors: NotFound naming the unknown scenario and listing the known ones.
Result<Scene> MakeScenario(std::string_view name, uint64_t seed);

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
