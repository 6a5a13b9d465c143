#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/error.h>
#include <avp/core/rng.h>
#include <avp/core/text.h>
#include <avp/sim/espalier.h>
#include <avp/sim/generic_plant.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene_file.h>
#include <avp/sim/tomato_plant.h>

namespace avp::sim {

namespace {

// ---- Start configurations -----------------------------------------------------------------------
//
// Joint 1 yaw used by the "unoriented" scenarios. q1 = +theta turns the arm about the base's -z,
// so the camera looks theta towards -y, away from plants placed at +y.
//
// tomato-unoriented-start: the reference's scenario 4 moves the same plant 0.4 m to +y and keeps
// the start pose; we do that too, and also yaw the arm 20 degrees away (q1 = +20), so that no
// fruit is in the start view for any seed (with the shift alone, fruits near y = 0.25-0.33 are at
// the image's left edge for some seeds).
constexpr double kTomatoUnorientedYawDeg = 20.0;
constexpr double kTomatoUnorientedShiftY = 0.4;
// espalier-unoriented-start: the espalier is 1.5 m wide, so shifting cannot take it out of view;
// the arm is yawed 65 degrees towards -y, which leaves at most the last ~10 cm of the -y cordon
// tips at the image's edge.
constexpr double kEspalierUnorientedYawDeg = 65.0;

const Eigen::Vector3f kSoilColor(0.15f, 0.10f, 0.065f);

TomatoPlantParams MultipleClustersTomato() {
  TomatoPlantParams p;
  p.trusses_min = 4;
  p.trusses_max = 6;
  p.fruits_per_truss_min = 3;
  p.fruits_per_truss_max = 7;
  p.leaf_density = 1.0;
  return p;
}

TomatoPlantParams FullOcclusionTomato() {
  TomatoPlantParams p;
  p.trusses_min = 3;
  p.trusses_max = 5;
  p.fruits_per_truss_min = 3;
  p.fruits_per_truss_max = 7;
  // Trusses on the far side of the stem (+x, away from the arm), a dense canopy, and screen leaves
  // that close every remaining line of sight from the start camera.
  p.truss_azimuth_deg = 0.0;
  p.truss_azimuth_spread_deg = 110.0;
  p.leaf_density = 1.3;
  p.occlusion.enabled = true;
  p.occlusion.eye_W = ReferenceStartCameraPose().translation();
  p.occlusion.view_direction_W = ReferenceStartCameraPose().rotation().col(2);
  return p;
}

TomatoPlantParams SingleClusterTomato() {
  TomatoPlantParams p;
  p.trusses_min = 1;
  p.trusses_max = 1;
  p.fruits_per_truss_min = 5;
  p.fruits_per_truss_max = 8;
  p.truss_height_min_fraction = 0.6;
  p.truss_height_max_fraction = 0.8;
  p.leaf_density = 0.6;
  return p;
}

EspalierParams MultipleFruitsEspalier() {
  EspalierParams p;
  p.fruits_min = 14;
  p.fruits_max = 24;
  p.fruit_side = FruitSide::kBoth;
  return p;
}

EspalierParams FullOcclusionEspalier() {
  EspalierParams p;
  p.fruits_min = 12;
  p.fruits_max = 20;
  p.fruit_side = FruitSide::kBack;
  p.leaf_density = 1.3;
  p.occlusion.enabled = true;
  p.occlusion.eye_W = ReferenceStartCameraPose().translation();
  p.occlusion.view_direction_W = ReferenceStartCameraPose().rotation().col(2);
  return p;
}

void SetStart(Scene& scene, double yaw_q1_deg) {
  scene.start_joints_rad = ReferenceStartJointsRad(yaw_q1_deg);
  scene.X_WC_start = ReferenceStartCameraPose(yaw_q1_deg);
}

void FinishScene(Scene& scene) {
  AddGroundPlane(scene, 0.0);
  scene.UpdatePlantBounds();
}

/// The generator of one plant kind: the unoriented scenarios share the plant of their oriented
/// twin, so (seed s) gives the same plant there, only moved (tomato) or seen from elsewhere.
Rng PlantRng(const char* kind, uint64_t seed) { return Rng(seed).Fork(kind); }

Scene BuildTomato(const TomatoPlantParams& params, const char* kind, uint64_t seed) {
  Scene scene;
  Rng rng = PlantRng(kind, seed);
  AddTomatoPlant(params, rng, scene);
  return scene;
}

Scene BuildEspalier(const EspalierParams& params, const char* kind, uint64_t seed) {
  Scene scene;
  Rng rng = PlantRng(kind, seed);
  AddEspalier(params, rng, scene);
  return scene;
}

/// A builder whose scene gets the ground plane and its plant bounds.
std::function<Result<Scene>(uint64_t)> Finished(std::function<Scene(uint64_t)> build) {
  return [build = std::move(build)](uint64_t seed) -> Result<Scene> {
    Scene scene = build(seed);
    FinishScene(scene);
    return scene;
  };
}

std::vector<ScenarioEntry> BuiltinEntries() {
  std::vector<ScenarioEntry> entries = {
      {"tomato-multiple-clusters",
       "tomato plant with 4-6 trusses of 3-7 fruits at typical leaf density, seen from the "
       "reference start (default)",
       Finished([](uint64_t seed) {
         Scene s = BuildTomato(MultipleClustersTomato(), "tomato-multiple-clusters", seed);
         SetStart(s, 0.0);
         return s;
       })},
      {"tomato-full-occlusion",
       "tomato plant whose 3-5 trusses hang behind the stem, hidden from the start view by a "
       "dense leaf layer",
       Finished([](uint64_t seed) {
         Scene s = BuildTomato(FullOcclusionTomato(), "tomato-full-occlusion", seed);
         SetStart(s, 0.0);
         return s;
       })},
      {"tomato-single-cluster", "sparse tomato plant with a single upper truss of 5-8 fruits",
       Finished([](uint64_t seed) {
         Scene s = BuildTomato(SingleClusterTomato(), "tomato-single-cluster", seed);
         SetStart(s, 0.0);
         return s;
       })},
      {"tomato-unoriented-start",
       "the multiple-clusters plant moved 0.4 m to +y with the arm yawed 20 deg away: no fruit "
       "in the start view",
       Finished([](uint64_t seed) {
         TomatoPlantParams params = MultipleClustersTomato();
         params.stem_base_W.y() += kTomatoUnorientedShiftY;
         Scene s = BuildTomato(params, "tomato-multiple-clusters", seed);
         SetStart(s, kTomatoUnorientedYawDeg);
         return s;
       })},
      {"espalier-multiple-fruits",
       "apple espalier, 1.5 m wide on 3-4 cordon tiers, 14-24 apples on both sides",
       Finished([](uint64_t seed) {
         Scene s = BuildEspalier(MultipleFruitsEspalier(), "espalier-multiple-fruits", seed);
         SetStart(s, 0.0);
         return s;
       })},
      {"espalier-full-occlusion",
       "apple espalier with 12-20 apples behind the cordons, hidden from the start view by "
       "dense leaves",
       Finished([](uint64_t seed) {
         Scene s = BuildEspalier(FullOcclusionEspalier(), "espalier-full-occlusion", seed);
         SetStart(s, 0.0);
         return s;
       })},
      {"espalier-unoriented-start",
       "the multiple-fruits espalier with the arm yawed 65 deg away (towards -y) at the start",
       Finished([](uint64_t seed) {
         Scene s = BuildEspalier(MultipleFruitsEspalier(), "espalier-multiple-fruits", seed);
         SetStart(s, kEspalierUnorientedYawDeg);
         return s;
       })},
      {std::string(kGenericTrainingScenario),
       "TRAINING ONLY: generic plants (single, row, wall or trellis), random branches, leaves and "
       "fruit",
       Finished([](uint64_t seed) {
         Scene s;
         Rng rng = PlantRng("generic-training", seed);
         const GenericPlantDraw draw = DrawGenericLayout(rng);
         SetStart(s, draw.start_yaw_deg);
         AddGenericPlants(draw, s.X_WC_start, rng, s);
         return s;
       }),
       /*training_only=*/true},
  };
  return entries;
}

}  // namespace

Result<Scene> ScenarioRegistry::Make(std::string_view name, uint64_t seed) const {
  AVP_ASSIGN_OR_RETURN(const ScenarioEntry* e, Get(name));
  AVP_ASSIGN_OR_RETURN(Scene scene, e->build(seed));
  scene.name = e->name;
  scene.description = e->description;
  scene.seed = seed;
  return scene;
}

std::vector<std::string> ScenarioRegistry::EvaluationNames() const {
  std::vector<std::string> names;
  for (const ScenarioEntry& e : entries()) {
    if (!e.training_only) names.push_back(e.name);
  }
  return names;
}

void RegisterBuiltinScenarios(ScenarioRegistry& registry) { AddAll(registry, BuiltinEntries()); }

ScenarioRegistry BuiltinScenarios() {
  ScenarioRegistry registry;
  RegisterBuiltinScenarios(registry);
  return registry;
}

std::string_view DefaultScenarioName() { return "tomato-multiple-clusters"; }

Result<Scene> MakeScenario(std::string_view name, uint64_t seed) {
  static const ScenarioRegistry* builtins = new ScenarioRegistry(BuiltinScenarios());
  return builtins->Make(name, seed);
}

Result<Scene> LoadScene(const SceneSource& source, const ScenarioRegistry& scenarios) {
  if (!source.scenario.empty() && !source.scene_file.empty()) {
    return InvalidArgumentError(
        fmt::format("give either a scenario ('{}') or a scene file ('{}'), not both",
                    source.scenario, source.scene_file.string()));
  }
  AVP_ASSIGN_OR_RETURN(const Arrangement arrangement, ParseArrangement(source.arrangement));
  if (!source.scene_file.empty()) {
    AVP_ASSIGN_OR_RETURN(Scene scene, LoadSceneFile(source.scene_file));
    if (Result<ArrangementReport> r = ApplyArrangement(scene, arrangement); !r.ok()) {
      return r.status().WithContext(source.scene_file.string());
    }
    return scene;
  }
  const std::string name =
      source.scenario.empty() ? std::string(DefaultScenarioName()) : source.scenario;
  if (!arrangement.IsIdentity()) {
    return InvalidArgumentError(fmt::format(
        "arrangement {} is for scene files: the scenario '{}' is arranged by its generator (only "
        "'reference' is accepted)",
        QuoteText(source.arrangement), name));
  }
  AVP_ASSIGN_OR_RETURN(Scene scene, scenarios.Make(name, source.seed));
  if (!source.arrangement.empty()) scene.name += "@" + source.arrangement;
  return scene;
}

std::vector<double> ReferenceStartJointsRad(double yaw_q1_deg) {
  std::vector<double> q;
  for (const double deg : kReferenceStartJointsDeg) q.push_back(DegToRad(deg));
  q[0] = DegToRad(yaw_q1_deg);
  return q;
}

RigidTransform ReferenceStartCameraPose(double yaw_q1_deg) {
  // Flange at the reference start (q1 = 0): p_WF = (0.190, 0, 0.617), R_WF = I.
  const RigidTransform X_WF(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.190, 0.0, 0.617));
  // Default camera mount: columns are the optical axes in the flange frame.
  //   optical x = -flange y, optical y = -flange z, optical z = flange x.
  Eigen::Matrix3d R_FC;
  R_FC.col(0) = -Eigen::Vector3d::UnitY();
  R_FC.col(1) = -Eigen::Vector3d::UnitZ();
  R_FC.col(2) = Eigen::Vector3d::UnitX();
  const RigidTransform X_FC(R_FC, Eigen::Vector3d(0.03, 0.0, 0.06));
  // X_WC at q1 = 0: eye (0.22, 0, 0.677), looking along +x, image up = +z (= LookAt(eye,
  // eye + x, z)).
  const RigidTransform X_WC0 = X_WF * X_FC;
  // Joint 1 turns about -z through the base origin: the whole arm, camera included, rotates by
  // Rz(-q1) in the world.
  const RigidTransform X_yaw(
      Eigen::AngleAxisd(-DegToRad(yaw_q1_deg), Eigen::Vector3d::UnitZ()).toRotationMatrix(),
      Eigen::Vector3d::Zero());
  return X_yaw * X_WC0;
}

uint16_t AddGroundPlane(Scene& scene, double z_m) {
  SceneObject ground;
  ground.name = "ground";
  ground.semantic_class = SemanticClass::kGround;
  ground.albedo = kSoilColor;
  TriangleMesh quad = MakeQuad(2.0, 2.0);
  quad.Transform(RigidTransform(Eigen::Vector3d(0.5, 0.0, z_m)));
  ground.shape = std::move(quad);
  return scene.Add(std::move(ground));
}

}  // namespace avp::sim
