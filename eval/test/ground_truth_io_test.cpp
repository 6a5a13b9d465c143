// The ground truth's JSON form (what recordings attach as ground_truth.json): an exact round trip
// of a real scenario's observable ground truth and of awkward doubles, through the JSON text, and
// errors that name the bad field.
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/eval/ground_truth.h>
#include <avp/eval/ground_truth_io.h>
#include <avp/robot/arm_model.h>
#include <avp/sim/scenario.h>

namespace avp::eval {
namespace {

using ::testing::HasSubstr;

bool SameBits(double a, double b) {
  return std::bit_cast<uint64_t>(a) == std::bit_cast<uint64_t>(b);
}

bool SameBits(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  if (a.rows() != b.rows() || a.cols() != b.cols()) return false;
  for (Eigen::Index i = 0; i < a.size(); ++i) {
    if (!SameBits(a.data()[i], b.data()[i])) return false;
  }
  return true;
}

/// Every field of `b` equals `a`'s, doubles bit for bit.
void ExpectIdentical(const GroundTruth& a, const GroundTruth& b) {
  EXPECT_TRUE(SameBits(a.voxel_size_m, b.voxel_size_m));
  EXPECT_EQ(a.source, b.source);
  EXPECT_EQ(a.voxels, b.voxels);
  ASSERT_EQ(a.fruits.size(), b.fruits.size());
  for (size_t i = 0; i < a.fruits.size(); ++i) {
    EXPECT_EQ(a.fruits[i].instance_id, b.fruits[i].instance_id) << i;
    EXPECT_EQ(a.fruits[i].name, b.fruits[i].name) << i;
    EXPECT_TRUE(SameBits(a.fruits[i].center_W, b.fruits[i].center_W)) << i;
    EXPECT_TRUE(SameBits(a.fruits[i].radii, b.fruits[i].radii)) << i;
  }
  EXPECT_EQ(a.voxels_per_fruit, b.voxels_per_fruit);
  ASSERT_EQ(a.best_visible_fraction.size(), b.best_visible_fraction.size());
  for (const auto& [id, f] : a.best_visible_fraction) {
    ASSERT_TRUE(b.best_visible_fraction.contains(id)) << id;
    EXPECT_TRUE(SameBits(f, b.best_visible_fraction.at(id))) << id;
  }
  EXPECT_EQ(a.views_tried, b.views_tried);
  EXPECT_EQ(a.views_reachable, b.views_reachable);
  ASSERT_EQ(a.views.size(), b.views.size());
  for (size_t i = 0; i < a.views.size(); ++i) {
    EXPECT_EQ(a.views[i].fruit_id, b.views[i].fruit_id) << i;
    EXPECT_TRUE(SameBits(a.views[i].radius_m, b.views[i].radius_m)) << i;
    EXPECT_TRUE(SameBits(a.views[i].azimuth_deg, b.views[i].azimuth_deg)) << i;
    EXPECT_TRUE(SameBits(a.views[i].elevation_deg, b.views[i].elevation_deg)) << i;
    EXPECT_TRUE(SameBits(a.views[i].X_WC.rotation(), b.views[i].X_WC.rotation())) << i;
    EXPECT_TRUE(SameBits(a.views[i].X_WC.translation(), b.views[i].X_WC.translation())) << i;
  }
}

/// Through the text, as a recording stores it.
GroundTruth ThroughText(const GroundTruth& truth) {
  const std::string text = GroundTruthToJson(truth).dump();
  Result<GroundTruth> back = GroundTruthFromJson(nlohmann::json::parse(text));
  EXPECT_TRUE(back.ok()) << back.status().ToString();
  return back.ok() ? *back : GroundTruth{};
}

GroundTruth Awkward() {
  GroundTruth g;
  g.voxel_size_m = 0.1 + 0.2;  // 0.30000000000000004
  g.source = "file:/tmp/a \"quoted\" \xc3\xa9 path";
  g.voxels[{-2147483647 - 1, 2147483647, 0}] = 65535;
  g.voxels[{-3, 4, -5}] = 0;
  g.voxels[{7, 7, 7}] = 2;
  sim::FruitTruth f;
  f.instance_id = 2;
  f.name = "tomato_2";
  f.center_W = {1.0 / 3.0, -std::numeric_limits<double>::denorm_min(), 1e300};
  f.radii = {0.031, 2.0 / 7.0, std::nextafter(0.03, 1.0)};
  g.fruits.push_back(f);
  g.voxels_per_fruit[2] = 1;
  g.voxels_per_fruit[0] = 1;
  g.best_visible_fraction[2] = 0.1 + 0.7;
  g.best_visible_fraction[5] = 0.0;
  g.views_tried = 9;
  g.views_reachable = 1;
  ObservationView v;
  v.fruit_id = 2;
  v.radius_m = 0.28;
  v.azimuth_deg = -84.99999999999999;
  v.elevation_deg = 55.0;
  v.X_WC = RigidTransform::LookAt({0.3, -0.2, 0.9}, {0.6, 0.1, 0.7});
  g.views.push_back(v);
  return g;
}

TEST(GroundTruthJson, AwkwardDoublesAndKeysRoundTripExactly) {
  const GroundTruth g = Awkward();
  ExpectIdentical(g, ThroughText(g));
  // The text does not depend on the hash maps' order: written twice, the same bytes.
  EXPECT_EQ(GroundTruthToJson(g).dump(), GroundTruthToJson(ThroughText(g)).dump());
  const nlohmann::json j = GroundTruthToJson(g);
  EXPECT_EQ(j["voxels"][0], nlohmann::json({-2147483648LL, 2147483647, 0, 65535}));
  EXPECT_EQ(j["format"], "avp-ground-truth");
}

TEST(GroundTruthJson, EmptyRoundTrips) {
  GroundTruth g;
  g.voxel_size_m = 0.005;
  ExpectIdentical(g, ThroughText(g));
}

TEST(GroundTruthJson, ObservableGroundTruthOfAScenarioRoundTripsExactly) {
  Result<sim::Scene> scene = sim::MakeScenario("tomato-single-cluster", 1);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  Result<robot::ArmModel> arm = robot::LoadDefaultArm();
  ASSERT_TRUE(arm.ok()) << arm.status().ToString();
  CameraIntrinsics K;
  K.width = 640;
  K.height = 480;
  K.fx = K.fy = 525.0;
  K.cx = 319.5;
  K.cy = 239.5;
  GroundTruthOptions options;
  options.image_width = 160;  // a quick one
  options.image_height = 120;
  const Eigen::VectorXd q = scene->start_joints_rad.empty()
                                ? arm->home_joints()
                                : Eigen::Map<const Eigen::VectorXd>(
                                      scene->start_joints_rad.data(),
                                      static_cast<Eigen::Index>(scene->start_joints_rad.size()));
  Result<GroundTruth> gt = ObservableGroundTruth(*scene, *arm, q, K, options);
  ASSERT_TRUE(gt.ok()) << gt.status().ToString();
  ASSERT_GT(gt->voxels.size(), 100u);
  ASSERT_GT(gt->views.size(), 10u);
  ASSERT_FALSE(gt->fruits.empty());
  ASSERT_FALSE(gt->best_visible_fraction.empty());
  const GroundTruth back = ThroughText(*gt);
  ExpectIdentical(*gt, back);
  EXPECT_EQ(back.ObservableFruits(), gt->ObservableFruits());
  EXPECT_EQ(back.FruitsVisibleAtLeast(0.25), gt->FruitsVisibleAtLeast(0.25));
}

std::string ErrorOf(const nlohmann::json& j) {
  Result<GroundTruth> r = GroundTruthFromJson(j);
  EXPECT_FALSE(r.ok());
  return r.ok() ? std::string() : r.status().ToString();
}

TEST(GroundTruthJson, ErrorsNameTheField) {
  const nlohmann::json good = GroundTruthToJson(Awkward());
  ASSERT_TRUE(GroundTruthFromJson(good).ok());

  EXPECT_THAT(ErrorOf(nlohmann::json::array()), HasSubstr("must be a JSON object"));
  nlohmann::json j = good;
  j["format"] = "something-else";
  EXPECT_THAT(ErrorOf(j), HasSubstr("format must be \"avp-ground-truth\", got \"something-else\""));
  j = good;
  j["version"] = 2;
  EXPECT_THAT(ErrorOf(j), HasSubstr("version must be 1"));
  j = good;
  j.erase("voxel_size_m");
  EXPECT_THAT(ErrorOf(j), HasSubstr("missing field 'voxel_size_m'"));
  j = good;
  j["voxel_size_m"] = -0.005;
  EXPECT_THAT(ErrorOf(j), HasSubstr("voxel_size_m must be > 0, got -0.005"));
  j = good;
  j["voxels"][1][1] = 1.5;
  EXPECT_THAT(ErrorOf(j), HasSubstr("voxels[1][1] must be an integer in int32 range, got 1.5"));
  j = good;
  j["voxels"][0][0] = 2147483648LL;
  EXPECT_THAT(ErrorOf(j), HasSubstr("voxels[0][0] must be an integer in int32 range"));
  j = good;
  j["voxels"][2][3] = 65536;
  EXPECT_THAT(ErrorOf(j), HasSubstr("voxels[2][3] must be an integer in [0, 65535], got 65536"));
  j = good;
  j["voxels"].push_back(j["voxels"][0]);
  EXPECT_THAT(ErrorOf(j), HasSubstr("voxels[3] must be a voxel listed once"));
  j = good;
  j["fruits"][0]["center_W"][1] = "x";
  EXPECT_THAT(ErrorOf(j), HasSubstr("fruits[0].center_W[1] must be a finite number, got \"x\""));
  j = good;
  j["fruits"][0].erase("name");
  EXPECT_THAT(ErrorOf(j), HasSubstr("fruits[0]: missing field 'name'"));
  j = good;
  j["best_visible_fraction"][0][1] = 1.25;
  EXPECT_THAT(ErrorOf(j),
              HasSubstr("best_visible_fraction[0][1] must be a fraction in [0, 1], got 1.25"));
  j = good;
  j["views_reachable"] = 10;
  EXPECT_THAT(ErrorOf(j), HasSubstr("views_reachable must be an integer in [0, views_tried]"));
  j = good;
  j["views"][0]["X_WC"][0] = 2.0;
  EXPECT_THAT(ErrorOf(j), HasSubstr("views[0].X_WC must be a rigid transform"));
  j = good;
  j["views"][0]["X_WC"].erase(11);
  EXPECT_THAT(ErrorOf(j), HasSubstr("views[0].X_WC must be an array of 12 numbers"));
  j = good;
  j["views"][0]["X_WC"][3] = nullptr;  // what a NaN is written as
  EXPECT_THAT(ErrorOf(j), HasSubstr("views[0].X_WC[3] must be a finite number, got null"));
}

}  // namespace
}  // namespace avp::eval
