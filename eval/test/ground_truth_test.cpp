// The observable ground truth on a real scenario (on the fruit surfaces, a subset of the
// voxelised surfaces, deterministic, perfectly reachable by a map of its own views), the
// observation views, option errors, and the OctoMap file round trip.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <unordered_set>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/parallel.h>
#include <avp/core/segmentation.h>
#include <avp/eval/ground_truth.h>
#include <avp/eval/metrics.h>
#include <avp/eval/oracle_planner.h>
#include <avp/mapping/integrator.h>
#include <avp/mapping/map_file.h>
#include <avp/mapping/octomap_io.h>
#include <avp/mapping/semantic_map.h>
#include <avp/robot/arm_model.h>
#include <avp/sim/ground_truth.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>
#include <avp/test/temp_dir_test.h>

namespace avp::eval {
namespace {

using ::testing::HasSubstr;
using ::testing::StartsWith;

/// The episode camera of the demo: 640 x 480, fx = fy = 525 px, centred, 0.1 - 3 m.
CameraIntrinsics EpisodeCamera() {
  CameraIntrinsics K;
  K.width = 640;
  K.height = 480;
  K.fx = 525.0;
  K.fy = 525.0;
  K.cx = 319.5;
  K.cy = 239.5;
  K.min_depth_m = 0.1;
  K.max_depth_m = 3.0;
  return K;
}

Eigen::VectorXd StartJoints(const sim::Scene& scene, const robot::ArmModel& arm) {
  if (scene.start_joints_rad.empty()) return arm.home_joints();
  return Eigen::Map<const Eigen::VectorXd>(
      scene.start_joints_rad.data(), static_cast<Eigen::Index>(scene.start_joints_rad.size()));
}

/// One scenario's ground truth, computed once for the suite (it takes about a second).
class ObservableGroundTruthTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    Result<sim::Scene> scene = sim::MakeScenario("tomato-single-cluster", 1);
    ASSERT_TRUE(scene.ok()) << scene.status().ToString();
    scene_ = new sim::Scene(std::move(*scene));
    Result<robot::ArmModel> arm = robot::LoadDefaultArm();
    ASSERT_TRUE(arm.ok()) << arm.status().ToString();
    arm_ = new robot::ArmModel(std::move(*arm));
    const auto t0 = std::chrono::steady_clock::now();
    Result<GroundTruth> gt = ObservableGroundTruth(*scene_, *arm_, StartJoints(*scene_, *arm_),
                                                   EpisodeCamera(), GroundTruthOptions{});
    seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ASSERT_TRUE(gt.ok()) << gt.status().ToString();
    gt_ = new GroundTruth(std::move(*gt));
    std::printf("[ observable GT ] %s: %zu voxels, %zu of %zu views reachable, %.3f s\n",
                scene_->name.c_str(), gt_->voxels.size(), gt_->views_reachable, gt_->views_tried,
                seconds_);
  }
  static void TearDownTestSuite() {
    delete gt_;
    delete arm_;
    delete scene_;
    gt_ = nullptr;
    arm_ = nullptr;
    scene_ = nullptr;
  }
  void SetUp() override {
    ASSERT_NE(gt_, nullptr);
    ASSERT_NE(scene_, nullptr);
  }

  static sim::Scene* scene_;
  static robot::ArmModel* arm_;
  static GroundTruth* gt_;
  static double seconds_;
};

sim::Scene* ObservableGroundTruthTest::scene_ = nullptr;
robot::ArmModel* ObservableGroundTruthTest::arm_ = nullptr;
GroundTruth* ObservableGroundTruthTest::gt_ = nullptr;
double ObservableGroundTruthTest::seconds_ = 0.0;

TEST_F(ObservableGroundTruthTest, BookkeepingIsConsistent) {
  const GroundTruth& gt = *gt_;
  EXPECT_EQ(gt.voxel_size_m, 0.005);
  EXPECT_EQ(gt.source, "observable:tomato-single-cluster");
  EXPECT_EQ(gt.fruits.size(), scene_->Fruits().size());
  EXPECT_GE(gt.fruits.size(), 5u);
  EXPECT_GT(gt.voxels.size(), 500u);
  EXPECT_GT(gt.views_reachable, 0u);
  EXPECT_LT(gt.views_reachable, gt.views_tried);  // the back of the fan is out of reach
  EXPECT_EQ(gt.views.size(), gt.views_reachable);
  size_t counted = 0;
  for (const sim::FruitTruth& f : gt.fruits) {
    ASSERT_TRUE(gt.voxels_per_fruit.count(f.instance_id)) << f.instance_id;
    counted += gt.voxels_per_fruit.at(f.instance_id);
  }
  EXPECT_EQ(counted, gt.voxels.size());
  EXPECT_EQ(gt.voxels_per_fruit.size(), gt.fruits.size());
  EXPECT_GE(gt.ObservableFruits(), gt.fruits.size() / 2);
}

TEST_F(ObservableGroundTruthTest, BestVisibleFractionsAgreeWithTheVoxels) {
  // A fruit with observable voxels was seen by some view (fraction > 0) and one without was not;
  // the single cluster at typical leaf density has fruits in plain view.
  const GroundTruth& gt = *gt_;
  for (const sim::FruitTruth& f : gt.fruits) {
    const double v = gt.best_visible_fraction.at(f.instance_id);
    EXPECT_GE(v, 0.0);
    EXPECT_LE(v, 1.0);
    EXPECT_EQ(v > 0.0, gt.voxels_per_fruit.at(f.instance_id) > 0) << "fruit " << f.instance_id;
  }
  EXPECT_EQ(gt.FruitsVisibleAtLeast(0.0), gt.fruits.size());
  EXPECT_GE(gt.FruitsVisibleAtLeast(0.5), 1u);
  size_t previous = gt.fruits.size();
  for (const double level : kVisibleFractionLevels) {
    EXPECT_LE(gt.FruitsVisibleAtLeast(level), previous) << level;
    previous = gt.FruitsVisibleAtLeast(level);
  }
  EXPECT_EQ(gt.FruitsVisibleAtLeast(1.5), 0u);
}

TEST_F(ObservableGroundTruthTest, EveryVoxelLiesOnItsFruitsSurface) {
  const double s = gt_->voxel_size_m;
  for (const auto& [key, id] : gt_->voxels) {
    const sim::SceneObject* o = scene_->FindInstance(id);
    ASSERT_NE(o, nullptr) << "voxel of unknown instance " << id;
    ASSERT_EQ(o->semantic_class, SemanticClass::kFruit);
    const auto* e = std::get_if<sim::Ellipsoid>(&o->shape);
    ASSERT_NE(e, nullptr);
    // The radial projection onto the ellipsoid bounds the distance to the surface from above.
    const Eigen::Vector3d p = key.Center(s);
    const Eigen::Vector3d q = e->center_W + (p - e->center_W) / std::sqrt(e->Implicit(p) + 1.0);
    EXPECT_LE((p - q).norm(), s) << "voxel " << key.x << "," << key.y << "," << key.z;
  }
}

TEST_F(ObservableGroundTruthTest, IsASubsetOfTheVoxelisedSurfaces) {
  const sim::FruitVoxels surface = sim::VoxelizeFruitSurfaces(*scene_, gt_->voxel_size_m);
  size_t exact = 0;
  for (const auto& [key, id] : gt_->voxels) {
    if (surface.voxels.count(key)) {
      ++exact;
      continue;
    }
    bool near = false;
    for (int dz = -1; dz <= 1 && !near; ++dz) {
      for (int dy = -1; dy <= 1 && !near; ++dy) {
        for (int dx = -1; dx <= 1 && !near; ++dx) {
          near = surface.voxels.count({key.x + dx, key.y + dy, key.z + dz}) > 0;
        }
      }
    }
    EXPECT_TRUE(near) << "voxel " << key.x << "," << key.y << "," << key.z;
  }
  // Surface points lie in their voxel, so all but float-rounding cases match exactly.
  EXPECT_GE(static_cast<double>(exact), 0.99 * static_cast<double>(gt_->voxels.size()));
  // Observable is a strict subset: the fruit backs facing the plant are never seen.
  EXPECT_LT(gt_->voxels.size(), surface.voxels.size());
  std::printf(
      "[ observable GT ] %zu of %zu surface voxels observable (%.1f %%)\n", gt_->voxels.size(),
      surface.voxels.size(),
      100.0 * static_cast<double>(gt_->voxels.size()) / static_cast<double>(surface.voxels.size()));
}

TEST_F(ObservableGroundTruthTest, EqualsTheFruitVoxelsOfItsViewsRenderedWhole) {
  // ObservableGroundTruth renders only the windows around the fruits' images; rendering every
  // reachable view whole must give the same voxels (up to float ties at silhouettes) and the same
  // best visible fraction of every fruit.
  const GroundTruthOptions options;
  const CameraIntrinsics K = ObservationIntrinsics(EpisodeCamera(), options);
  const sim::RgbdRenderer renderer(*scene_);
  std::unordered_set<VoxelKey, VoxelKeyHash> whole;
  std::map<uint16_t, double> best;  // the largest visible fraction per fruit, from whole renders
  for (const ObservationView& view : gt_->views) {
    const sim::RenderedFrame f = renderer.Render(K, view.X_WC);
    std::map<uint16_t, size_t> pixels;
    for (int v = 0; v < K.height; ++v) {
      for (int u = 0; u < K.width; ++u) {
        const float d = f.rgbd.depth_m.at(u, v);
        if (f.class_ids.at(u, v) != static_cast<uint8_t>(SemanticClass::kFruit) || !(d > 0.0f)) {
          continue;
        }
        const Eigen::Vector3d p_W =
            view.X_WC * Eigen::Vector3d((u - K.cx) / K.fx * d, (v - K.cy) / K.fy * d, d);
        if ((p_W - view.X_WC.translation()).norm() > options.max_range_m) continue;
        whole.insert(VoxelKey::FromPoint(p_W, gt_->voxel_size_m));
        ++pixels[f.instance_ids.at(u, v)];
      }
    }
    for (const sim::FruitTruth& fruit : gt_->fruits) {
      const auto n = pixels.find(fruit.instance_id);
      if (n == pixels.end()) continue;
      // pi (f r / z)^2 by hand (ExpectedFruitAreaPx's formula).
      const double z = (view.X_WC.inverse() * fruit.center_W).z();
      const double r_px = std::sqrt(K.fx * K.fy) * fruit.mean_radius_m() / z;
      const double fraction = std::min(1.0, static_cast<double>(n->second) / (M_PI * r_px * r_px));
      best[fruit.instance_id] = std::max(best[fruit.instance_id], fraction);
    }
  }
  ASSERT_EQ(gt_->best_visible_fraction.size(), gt_->fruits.size());
  for (const sim::FruitTruth& fruit : gt_->fruits) {
    EXPECT_NEAR(gt_->best_visible_fraction.at(fruit.instance_id), best[fruit.instance_id], 0.01)
        << "fruit " << fruit.instance_id;
  }
  size_t common = 0;
  for (const auto& [key, id] : gt_->voxels) common += whole.count(key);
  const size_t differing = whole.size() + gt_->voxels.size() - 2 * common;
  EXPECT_LE(static_cast<double>(differing), 1e-3 * static_cast<double>(whole.size()))
      << whole.size() << " voxels rendered whole, " << gt_->voxels.size() << " in the GT, "
      << common << " common";
}

TEST_F(ObservableGroundTruthTest, IsDeterministicForAnyThreadCount) {
  // The fixture's truth used the hardware's threads; this one, one thread (core/parallel.h).
  const ThreadScope one_thread(1);
  const Result<GroundTruth> again = ObservableGroundTruth(
      *scene_, *arm_, StartJoints(*scene_, *arm_), EpisodeCamera(), GroundTruthOptions{});
  ASSERT_TRUE(again.ok());
  EXPECT_TRUE(again->voxels == gt_->voxels);
  EXPECT_EQ(again->SortedKeys(), gt_->SortedKeys());
  EXPECT_TRUE(again->voxels_per_fruit == gt_->voxels_per_fruit);
  EXPECT_TRUE(again->best_visible_fraction == gt_->best_visible_fraction);
  EXPECT_EQ(again->views_tried, gt_->views_tried);
  EXPECT_EQ(again->views_reachable, gt_->views_reachable);
}

TEST_F(ObservableGroundTruthTest, MapOfOneOfItsViewsHasPrecisionOne) {
  // Render one reachable observation view at full size and integrate its fruit masks.
  GroundTruthOptions options;
  const CameraIntrinsics K = ObservationIntrinsics(EpisodeCamera(), options);
  EXPECT_EQ(K.width, 320);
  EXPECT_EQ(K.height, 240);
  EXPECT_DOUBLE_EQ(K.fx, 262.5);
  EXPECT_DOUBLE_EQ(K.cx, 159.5);
  const sim::RgbdRenderer renderer(*scene_);
  mapping::MapOptions map_options;
  map_options.grid.voxel_size_m = gt_->voxel_size_m;
  const mapping::Integrator integrator;
  size_t checked = 0;
  for (size_t i = 0; i < gt_->views.size() && checked < 3; i += gt_->views.size() / 3 + 1) {
    mapping::SemanticMap map(map_options);
    const sim::RenderedFrame frame = renderer.Render(K, gt_->views[i].X_WC);
    const Segmentation seg =
        Segmentation::FromLabelImages(frame.instance_ids, frame.class_ids, 0.9f);
    ASSERT_TRUE(integrator.Integrate(frame.rgbd, &seg, map).ok());
    const MapMetrics m = EvaluateMap(map, *gt_);
    if (m.predicted_voxels == 0) continue;
    ++checked;
    EXPECT_EQ(m.exact.fp, 0u) << "view " << i;
    EXPECT_DOUBLE_EQ(m.exact.precision, 1.0) << "view " << i;
    EXPECT_GT(m.exact.recall, 0.0);
    EXPECT_LT(m.exact.recall, 1.0);  // one view sees only part of what all views see
  }
  EXPECT_GE(checked, 1u);
}

// oracle-nbv's true gain: GT voxels a view would see that the map does not hold as fruit yet.
TEST_F(ObservableGroundTruthTest, OracleTrueGainCountsUnmappedGroundTruthSeenByTheView) {
  const OracleNbvPlanner oracle(*scene_, *gt_);
  mapping::MapOptions map_options;
  map_options.grid.voxel_size_m = gt_->voxel_size_m;
  mapping::SemanticMap map(map_options);
  const CameraIntrinsics K = EpisodeCamera();
  const RigidTransform X = gt_->views.front().X_WC;
  const size_t before = oracle.TrueGain(map, SemanticClass::kFruit, K, X);
  EXPECT_GT(before, 50u);
  // Turned around, the camera sees no fruit.
  const RigidTransform away(
      X.rotation() * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitY()).toRotationMatrix(),
      X.translation());
  EXPECT_EQ(oracle.TrueGain(map, SemanticClass::kFruit, K, away), 0u);
  // Once the view's fruit is mapped, the same view has (almost) nothing new left to show: what
  // remains is the 4x finer oracle render seeing voxels the mapped frame's pixels missed.
  const sim::RgbdRenderer renderer(*scene_);
  const sim::RenderedFrame frame = renderer.Render(K, X);
  const Segmentation seg = Segmentation::FromLabelImages(frame.instance_ids, frame.class_ids, 0.9f);
  ASSERT_TRUE(mapping::Integrator().Integrate(frame.rgbd, &seg, map).ok());
  const size_t after = oracle.TrueGain(map, SemanticClass::kFruit, K, X);
  EXPECT_LT(after, before / 10) << "before " << before;
}

TEST_F(ObservableGroundTruthTest, OracleDetectGainExpectsTheFruitsTheDetectorWouldFind) {
  // The detector sees every visible fruit with probability p_max (a step at v = 0).
  OracleNbvOptions certain;
  certain.objective = OracleNbvOptions::Objective::kDetections;
  certain.detector.v_min = 0.0;
  certain.detector.v_full = 0.0;
  certain.detector.p_max = 1.0;
  certain.detector.min_pixels = 1;
  OracleNbvOptions half = certain;
  half.detector.p_max = 0.5;
  const OracleNbvOptions noisy = [] {
    OracleNbvOptions o;
    o.objective = OracleNbvOptions::Objective::kDetections;
    return o;  // the oracle segmenter's default model
  }();
  const OracleNbvPlanner oracle(*scene_, *gt_, certain);
  const OracleNbvPlanner oracle_half(*scene_, *gt_, half);
  const OracleNbvPlanner oracle_noisy(*scene_, *gt_, noisy);
  EXPECT_EQ(oracle.name(), "oracle-detect");
  EXPECT_EQ(OracleNbvPlanner(*scene_, *gt_).name(), "oracle-nbv");

  mapping::MapOptions map_options;
  map_options.grid.voxel_size_m = gt_->voxel_size_m;
  mapping::SemanticMap map(map_options);
  const CameraIntrinsics K = EpisodeCamera();
  const RigidTransform X = gt_->views.front().X_WC;
  const std::unordered_set<uint16_t> none = oracle.FoundFruits(map, SemanticClass::kFruit);
  EXPECT_TRUE(none.empty());
  // Each fruit in view is worth kFruitValue plus its new voxels: at least its own fruit.
  const double before = oracle.ExpectedDetectionGain(map, SemanticClass::kFruit, K, X, none);
  EXPECT_GT(before, kFruitValue + 50.0);
  EXPECT_DOUBLE_EQ(oracle_half.ExpectedDetectionGain(map, SemanticClass::kFruit, K, X, none),
                   0.5 * before);
  EXPECT_LE(oracle_noisy.ExpectedDetectionGain(map, SemanticClass::kFruit, K, X, none), before);
  const RigidTransform away(
      X.rotation() * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitY()).toRotationMatrix(),
      X.translation());
  EXPECT_EQ(oracle.ExpectedDetectionGain(map, SemanticClass::kFruit, K, away, none), 0.0);

  // Once the view is mapped, its fruits are found and no longer worth kFruitValue.
  const sim::RgbdRenderer renderer(*scene_);
  const sim::RenderedFrame frame = renderer.Render(K, X);
  const Segmentation seg = Segmentation::FromLabelImages(frame.instance_ids, frame.class_ids, 0.9f);
  ASSERT_TRUE(mapping::Integrator().Integrate(frame.rgbd, &seg, map).ok());
  const std::unordered_set<uint16_t> found = oracle.FoundFruits(map, SemanticClass::kFruit);
  EXPECT_TRUE(found.count(gt_->views.front().fruit_id) == 1);
  const double after = oracle.ExpectedDetectionGain(map, SemanticClass::kFruit, K, X, found);
  EXPECT_LT(after, before / 10) << "before " << before;
}

TEST_F(ObservableGroundTruthTest, ObservationViewsFaceTheBaseAndLookAtTheirFruit) {
  GroundTruthOptions options;
  const std::vector<ObservationView> views = ObservationViews(gt_->fruits, options);
  EXPECT_EQ(views.size(), gt_->views_tried);
  EXPECT_LE(views.size(), gt_->fruits.size() * 3 * 4 * 9);
  for (const ObservationView& v : views) {
    const sim::FruitTruth* fruit = nullptr;
    for (const sim::FruitTruth& f : gt_->fruits) {
      if (f.instance_id == v.fruit_id) fruit = &f;
    }
    ASSERT_NE(fruit, nullptr);
    const Eigen::Vector3d eye = v.X_WC.translation();
    EXPECT_NEAR((eye - fruit->center_W).norm(), v.radius_m, 1e-9);
    EXPECT_GT(eye.z(), 0.0);
    // The optical axis points at the fruit centre.
    const Eigen::Vector3d axis = v.X_WC.rotation().col(2);
    EXPECT_NEAR(axis.dot((fruit->center_W - eye).normalized()), 1.0, 1e-9);
    // The camera is on the base's side: within 85 deg of the fruit-to-base direction.
    const Eigen::Vector2d to_base = -fruit->center_W.head<2>().normalized();
    const Eigen::Vector2d to_eye = (eye - fruit->center_W).head<2>().normalized();
    EXPECT_GE(to_base.dot(to_eye), std::cos(85.0 * M_PI / 180.0) - 1e-9);
  }
}

TEST(GroundTruthOptionsTest, ValidateNamesEveryBadField) {
  GroundTruthOptions o;
  EXPECT_TRUE(o.Validate().ok());
  o.voxel_size_m = 0.5;
  o.radii_m = {0.3, -1.0};
  o.azimuths = 0;
  o.elevations_deg = {90.0};
  o.image_width = 0;
  o.max_range_m = 0.0;
  const Status s = o.Validate();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("voxel_size_m (0.5 m)"));
  EXPECT_THAT(s.message(), HasSubstr("radii_m[1] (-1 m)"));
  EXPECT_THAT(s.message(), HasSubstr("azimuths (0)"));
  EXPECT_THAT(s.message(), HasSubstr("elevations_deg[0] (90 deg)"));
  EXPECT_THAT(s.message(), HasSubstr("image_width (0 px)"));
  EXPECT_THAT(s.message(), HasSubstr("max_range_m (0)"));
}

TEST(GroundTruthOptionsTest, ObservableGroundTruthRejectsBadInputs) {
  Result<sim::Scene> scene = sim::MakeScenario("tomato-single-cluster", 1);
  ASSERT_TRUE(scene.ok());
  Result<robot::ArmModel> arm = robot::LoadDefaultArm();
  ASSERT_TRUE(arm.ok());
  GroundTruthOptions bad;
  bad.azimuths = -1;
  Result<GroundTruth> r =
      ObservableGroundTruth(*scene, *arm, arm->home_joints(), EpisodeCamera(), bad);
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(), HasSubstr("azimuths (-1)"));
  r = ObservableGroundTruth(*scene, *arm, Eigen::VectorXd::Zero(2), EpisodeCamera(), {});
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(), HasSubstr("start joints (0, 0) must be 6 finite values"));
  CameraIntrinsics K = EpisodeCamera();
  K.fx = -1.0;
  r = ObservableGroundTruth(*scene, *arm, arm->home_joints(), K, {});
  EXPECT_THAT(r.status().message(), HasSubstr("fx (-1)"));
}

TEST(GroundTruthOptionsTest, SingleFruitSceneWithFewViews) {
  // One sphere in front of the arm, a small fan: every GT voxel on the sphere's near side.
  sim::Scene scene;
  scene.name = "one-sphere";
  sim::SceneObject o;
  o.name = "fruit";
  o.semantic_class = SemanticClass::kFruit;
  sim::Ellipsoid e;
  e.center_W = Eigen::Vector3d(0.55, 0.0, 0.55);
  e.radii = Eigen::Vector3d::Constant(0.035);
  o.shape = e;
  const uint16_t id = scene.Add(o);
  scene.UpdatePlantBounds();
  Result<robot::ArmModel> arm = robot::LoadDefaultArm();
  ASSERT_TRUE(arm.ok());
  GroundTruthOptions options;
  options.radii_m = {0.3};
  options.elevations_deg = {0.0};
  options.azimuths = 1;
  const Result<GroundTruth> gt =
      ObservableGroundTruth(scene, *arm, arm->home_joints(), EpisodeCamera(), options);
  ASSERT_TRUE(gt.ok()) << gt.status().ToString();
  EXPECT_EQ(gt->views_tried, 1u);
  ASSERT_EQ(gt->views_reachable, 1u);
  ASSERT_GT(gt->voxels.size(), 50u);
  for (const auto& [key, fruit] : gt->voxels) {
    EXPECT_EQ(fruit, id);
    EXPECT_LT(key.Center(gt->voxel_size_m).x(), e.center_W.x() + gt->voxel_size_m);
  }
  EXPECT_EQ(gt->voxels_per_fruit.at(id), gt->voxels.size());
  EXPECT_EQ(gt->ObservableFruits(), 1u);
  // In plain view: its whole disc (the silhouette of a sphere is a little larger than
  // pi (f r / z)^2, so the fraction clamps at 1).
  EXPECT_GT(gt->best_visible_fraction.at(id), 0.97);

  // A leaf between the camera (at (0.25, 0, 0.55), looking +x) and the fruit, whose top edge is
  // level with the camera and the fruit's centre, hides the fruit's lower half.
  sim::SceneObject leaf;
  leaf.name = "leaf";
  leaf.semantic_class = SemanticClass::kLeaf;
  sim::TriangleMesh quad;
  quad.vertices = {
      {0.40f, -0.1f, 0.40f}, {0.40f, 0.1f, 0.40f}, {0.40f, 0.1f, 0.55f}, {0.40f, -0.1f, 0.55f}};
  quad.triangles = {{0, 1, 2}, {0, 2, 3}};
  leaf.shape = quad;
  scene.Add(leaf);
  scene.UpdatePlantBounds();
  const Result<GroundTruth> half =
      ObservableGroundTruth(scene, *arm, arm->home_joints(), EpisodeCamera(), options);
  ASSERT_TRUE(half.ok()) << half.status().ToString();
  ASSERT_EQ(half->views_reachable, 1u);
  EXPECT_NEAR(half->best_visible_fraction.at(id), 0.5, 0.05);
  EXPECT_EQ(half->FruitsVisibleAtLeast(0.25), 1u);
  EXPECT_EQ(half->FruitsVisibleAtLeast(0.75), 0u);
}

class GroundTruthFileTest : public avp::test::TempDirTest {};

TEST_F(GroundTruthFileTest, OctomapRoundTrip) {
  Result<sim::Scene> scene = sim::MakeScenario("tomato-single-cluster", 2);
  ASSERT_TRUE(scene.ok());
  const double s = 0.005;
  const sim::FruitVoxels surface = sim::VoxelizeFruitSurfaces(*scene, s);
  mapping::GridOptions grid_options;
  grid_options.voxel_size_m = s;
  mapping::OccupancyGrid grid(grid_options);
  for (const VoxelKey& k : surface.SortedKeys()) grid.SetLogOdds(k, grid.clamp_max_log_odds());
  grid.SetLogOdds({0, 0, 0}, grid.clamp_min_log_odds());  // free: not part of the GT
  const std::filesystem::path bt = dir_ / "gt.bt";
  ASSERT_TRUE(mapping::ExportOctomapBinary(grid, bt).ok());

  const Result<GroundTruth> with_scene = GroundTruthFromOctomapFile(bt, &*scene);
  ASSERT_TRUE(with_scene.ok()) << with_scene.status().ToString();
  EXPECT_EQ(with_scene->source, "file:" + bt.string());
  EXPECT_DOUBLE_EQ(with_scene->voxel_size_m, s);
  EXPECT_EQ(with_scene->SortedKeys(), surface.SortedKeys());
  EXPECT_EQ(with_scene->fruits.size(), scene->Fruits().size());
  EXPECT_EQ(with_scene->views_tried, 0u);
  size_t same_fruit = 0;
  for (const auto& [key, id] : surface.voxels) same_fruit += with_scene->voxels.at(key) == id;
  EXPECT_GE(static_cast<double>(same_fruit), 0.97 * static_cast<double>(surface.voxels.size()));
  size_t counted = 0;
  for (const auto& [id, n] : with_scene->voxels_per_fruit) counted += n;
  EXPECT_EQ(counted, surface.voxels.size());

  const Result<GroundTruth> bare = GroundTruthFromOctomapFile(bt, nullptr);
  ASSERT_TRUE(bare.ok());
  EXPECT_EQ(bare->voxels.size(), surface.voxels.size());
  EXPECT_TRUE(bare->fruits.empty());
  EXPECT_TRUE(bare->voxels_per_fruit.empty());
  for (const auto& [key, id] : bare->voxels) ASSERT_EQ(id, 0);

  const Result<GroundTruth> missing = GroundTruthFromOctomapFile(dir_ / "missing.bt", nullptr);
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(missing.status().message(), HasSubstr("missing.bt"));
}

TEST_F(GroundTruthFileTest, TruncatedOctomapGroundTruthIsRefused) {
  // A truncated .ot given as ground truth used to load as a different tree (600 000 voxels
  // instead of 1 690) and be scored against: now it is an error that says where the tree ends.
  Result<sim::Scene> scene = sim::MakeScenario("tomato-single-cluster", 2);
  ASSERT_TRUE(scene.ok());
  const sim::FruitVoxels surface = sim::VoxelizeFruitSurfaces(*scene, 0.006);
  mapping::MapOptions options;
  options.grid.voxel_size_m = 0.006;
  mapping::SemanticMap map(options);
  for (const VoxelKey& k : surface.SortedKeys()) {
    map.grid().SetLogOdds(k, map.grid().clamp_max_log_odds());
  }
  const std::filesystem::path ot = dir_ / "gt.ot";
  ASSERT_TRUE(mapping::ExportOctomapColor(map, ot).ok());
  const Result<GroundTruth> whole = GroundTruthFromOctomapFile(ot, &*scene);
  ASSERT_TRUE(whole.ok()) << whole.status().ToString();
  EXPECT_EQ(whole->voxels.size(), surface.voxels.size());

  std::filesystem::resize_file(ot, std::filesystem::file_size(ot) * 2 / 3);
  const Result<GroundTruth> cut = GroundTruthFromOctomapFile(ot, &*scene);
  ASSERT_FALSE(cut.ok()) << "read " << cut->voxels.size() << " voxels from a truncated file";
  EXPECT_EQ(cut.status().code(), StatusCode::kParseError);
  EXPECT_THAT(cut.status().message(), HasSubstr("gt.ot"));
  EXPECT_THAT(cut.status().message(), HasSubstr("truncated"));
}

TEST_F(GroundTruthFileTest, LabelledMapFilesGiveTheirFruitVoxels) {
  // A run's map (fruit surface labelled fruit, plus leaf-labelled voxels) as the ground truth of
  // another run: from map.avpmap and from map.ot, only the fruit voxels count.
  Result<sim::Scene> scene = sim::MakeScenario("tomato-single-cluster", 2);
  ASSERT_TRUE(scene.ok());
  const sim::FruitVoxels surface = sim::VoxelizeFruitSurfaces(*scene, 0.006);
  mapping::MapOptions options;
  options.grid.voxel_size_m = 0.006;
  mapping::SemanticMap map(options);
  mapping::OccupancyGrid& grid = map.grid();
  for (const VoxelKey& k : surface.SortedKeys()) {
    grid.SetLogOdds(k, grid.clamp_max_log_odds());
    mapping::SemanticCell* c = grid.MutableSemantic(k);
    c->semantic_class = static_cast<uint8_t>(SemanticClass::kFruit);
    c->confidence = 0.9f;
    c->observations = 2;
  }
  size_t leaves = 0;
  for (int x = 0; x < 20; ++x) {
    const VoxelKey k{x, 500, 100};  // far from every fruit
    grid.SetLogOdds(k, grid.clamp_max_log_odds());
    mapping::SemanticCell* c = grid.MutableSemantic(k);
    c->semantic_class = static_cast<uint8_t>(SemanticClass::kLeaf);
    c->confidence = 0.9f;
    c->observations = 2;
    ++leaves;
  }
  const std::filesystem::path avpmap = dir_ / "map.avpmap";
  const std::filesystem::path ot = dir_ / "map.ot";
  const std::filesystem::path bt = dir_ / "map.bt";
  ASSERT_TRUE(mapping::SaveMap(map, avpmap).ok());
  ASSERT_TRUE(mapping::ExportOctomapColor(map, ot).ok());
  ASSERT_TRUE(mapping::ExportOctomapBinary(grid, bt).ok());
  for (const std::filesystem::path& file : {avpmap, ot}) {
    const Result<GroundTruth> gt = GroundTruthFromOctomapFile(file, &*scene);
    ASSERT_TRUE(gt.ok()) << file << ": " << gt.status().ToString();
    EXPECT_EQ(gt->SortedKeys(), surface.SortedKeys()) << file;
    EXPECT_EQ(gt->source, "file:" + file.string() + " (its fruit voxels)");
    EXPECT_EQ(gt->fruits.size(), scene->Fruits().size());
  }
  // A .bt has no classes: every occupied voxel, the leaves' too.
  const Result<GroundTruth> all = GroundTruthFromOctomapFile(bt, &*scene);
  ASSERT_TRUE(all.ok()) << all.status().ToString();
  EXPECT_EQ(all->voxels.size(), surface.voxels.size() + leaves);
  EXPECT_EQ(all->source, "file:" + bt.string());
}

}  // namespace
}  // namespace avp::eval
