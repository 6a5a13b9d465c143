#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include <avp/core/camera.h>
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
  /// A family for training learned planners only: left out of the scenarios a bench runs when it
  /// names none (ScenarioRegistry::EvaluationNames), so that no evaluation sees it by default.
  bool training_only = false;

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
  /// The names of the scenarios that are not training_only, in registration order: the set a
  /// bench runs when it names none.
  std::vector<std::string> EvaluationNames() const;
};

/// The built-in scenario of the training plant family (sim/generic_plant.h): registered so that
/// `avp run`, `avp bench` and `avp scene` can show and use it, but for training learned planners
/// only; the tomato and espalier scenarios are the test set (docs/planning.md, "A learned gain").
inline constexpr std::string_view kGenericTrainingScenario = "generic-training";

/// Registers the built-in scenarios (the paper's four tomato experiments, three espaliers and the
/// training family, kGenericTrainingScenario).
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
  /// How the scene file's plant is arranged (ParseArrangement; empty: as the file places it). A
  /// registered scenario takes only "reference" (or nothing).
  std::string arrangement;
};

/// Builds the scene of `source` from `scenarios` or the file, then arranges it
/// (ApplyArrangement); errors name the bad scenario, file or arrangement. Giving both a scenario
/// and a file is an error, and so is an arrangement other than "reference" for a scenario.
Result<Scene> LoadScene(const SceneSource& source, const ScenarioRegistry& scenarios);

// ---- Arrangements: one plant placed like each of the paper's tomato scenarios -------------------
//
// A scene file holds one plant as its author placed it. An arrangement moves that plant, keeps
// some of its fruit and turns the arm's start, so that one mesh runs the paper's four tomato
// experiments (docs/scene-format.md, "Arrangements"). It uses nothing but the scene's objects:
// the plant is every object that is neither ground nor background (Scene::UpdatePlantBounds), the
// fruit are its fruit-class objects (Scene::Fruits).

/// An arrangement, parsed. Applied in this order: the start yaw (the arm and its start camera),
/// then one fruit cluster kept, then the plant turned about the vertical axis through the centre
/// of its plant_bounds (a fixed yaw, or the one that hides the most fruit), then moved.
struct Arrangement {
  /// The text it was parsed from ("full-occlusion", "plant-y=0.4+start-yaw=20"); empty: none.
  std::string spec;
  /// Added to every plant object's position after the turn, metres (world frame).
  Eigen::Vector3d plant_offset_m = Eigen::Vector3d::Zero();
  /// The plant's turn about the vertical axis through its plant_bounds centre, degrees
  /// (counter-clockwise seen from above).
  double plant_yaw_deg = 0.0;
  /// Choose plant_yaw_deg among 0, 15, ..., 345 as the one that leaves the fewest fruit pixels in
  /// the rendered start view (ties: the smallest yaw).
  bool occluding_yaw = false;
  /// Keep only the fruit of one cluster (FruitClusters with cluster_gap_m): the one with the most
  /// fruit, ties: the one whose centroid is nearest the start camera.
  bool single_cluster = false;
  double cluster_gap_m = 0.04;
  /// Added to arm joint 1 (q1) at the start, degrees; the start camera turns by Rz(-q1) about the
  /// world z axis through the base (ReferenceStartCameraPose).
  double start_yaw_deg = 0.0;

  /// True when it changes nothing.
  bool IsIdentity() const;
};

/// The named arrangements, the paper's four tomato scenarios: "reference" (as the file places it:
/// tomato-multiple-clusters), "full-occlusion", "single-cluster", "unoriented-start" (plant-y=0.4
/// + start-yaw=20, as tomato-unoriented-start).
const std::vector<std::string>& ArrangementNames();
/// "paper": in an avp bench scenario list, `scene.yaml@paper` stands for the four named ones.
inline constexpr std::string_view kPaperArrangements = "paper";

/// The spacing of occluding_yaw's candidates, degrees.
inline constexpr double kOcclusionYawStepDeg = 15.0;

/// Parses "NAME" or items joined by '+': a name of ArrangementNames(), or KEY=VALUE with KEY one
/// of plant-x, plant-y, plant-z (metres), plant-yaw (degrees), start-yaw (degrees), cluster-gap
/// (metres, with single-cluster). "" gives the identity. Errors (InvalidArgument, naming the spec
/// and the item): an unknown name or key (listing the known ones), a bad or out-of-range number,
/// a field set twice (e.g. full-occlusion+plant-yaw=30), "paper" (a bench list's shorthand).
Result<Arrangement> ParseArrangement(std::string_view spec);

/// What ApplyArrangement did.
struct ArrangementReport {
  double plant_yaw_deg = 0.0;  ///< the turn applied (the one chosen with occluding_yaw)
  /// With occluding_yaw: the start view's fruit pixels at each candidate yaw (0, 15, ...).
  std::vector<size_t> fruit_pixels_by_yaw;
  size_t fruits_kept = 0, fruits_removed = 0;
  std::string summary;  ///< one line, also appended to the scene's description
};

/// The scene's fruit in clusters: single linkage, two fruit linked when their centres are at most
/// r_a + r_b + gap_m apart (r: FruitTruth::mean_radius_m, so gap_m is the gap between their
/// surfaces). Each cluster lists instance ids ascending; clusters ordered by their first id.
std::vector<std::vector<uint16_t>> FruitClusters(const Scene& scene, double gap_m);

/// The fruit pixels (class fruit) of `scene` rendered from `X_WC` with `camera`.
size_t CountFruitPixels(const Scene& scene, const CameraIntrinsics& camera,
                        const RigidTransform& X_WC);

/// Arranges `scene` in place (see Arrangement for the order), then recomputes plant_bounds and
/// appends "@<spec>" to its name (when spec is not empty) and the report's summary to its
/// description. Fruit ground truth follows (it is read from the objects). occluding_yaw renders
/// the start view with `camera` (the plant alone, without ground and background objects).
/// Errors: InvalidArgument for a scene without plant, single_cluster without fruit, a start yaw
/// with no start joints.
Result<ArrangementReport> ApplyArrangement(
    Scene& scene, const Arrangement& arrangement,
    const CameraIntrinsics& camera = CameraIntrinsics::RealSenseD435());

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
