#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

#include <fcl/narrowphase/distance.h>
#include <gtest/gtest.h>

#include <avp/core/limits.h>
#include <avp/core/rng.h>
#include <avp/motion/collision_checker.h>
#include <avp/motion/robot_geometry.h>
#include <avp/test/temp_dir_test.h>

#include "motion_test_util.h"

namespace avp::motion {
namespace {

using testing::DefaultArm;
using testing::DefaultGeometry;
using testing::Deg;

const RobotBody* FindBody(const RobotGeometry& g, std::string_view name) {
  for (const RobotBody& b : g.bodies()) {
    if (b.name == name) return &b;
  }
  return nullptr;
}

TEST(RobotGeometryTest, TheReBeLHasItsLinksCylindersAndTheCameraBody) {
  const RobotGeometry& g = DefaultGeometry();
  EXPECT_EQ(g.source(), GeometrySource::kCollision);
  EXPECT_TRUE(g.warnings().empty());
  // One cylinder for each of base_link, link_1, link_2, link_5, link_6, link_7, and the D435 and
  // its bracket on the flange (configs/arms/igus_rebel_d435.yaml).
  EXPECT_EQ(g.bodies().size(), 8u);
  const RobotBody* camera = FindBody(g, "flange/d435");
  ASSERT_NE(camera, nullptr);
  EXPECT_EQ(camera->shape.kind, robot::ShapeKind::kBox);
  EXPECT_TRUE(camera->shape.size.isApprox(Eigen::Vector3d(0.025, 0.090, 0.025)));
  EXPECT_EQ(DefaultArm().links()[static_cast<size_t>(camera->link)].name, "flange");
  const RobotBody* base = FindBody(g, "base_link#0");
  ASSERT_NE(base, nullptr);
  EXPECT_FALSE(base->moves);
  EXPECT_TRUE(FindBody(g, "link_7#0")->moves);
}

TEST(RobotGeometryTest, SpheresCoverEveryPointOfEveryShape) {
  const RobotGeometry& g = DefaultGeometry();
  Rng rng(7);
  for (const RobotBody& body : g.bodies()) {
    const Eigen::Vector3d& size = body.shape.size;
    for (int k = 0; k < 2000; ++k) {
      Eigen::Vector3d p_S;  // a point of the shape, in its frame
      if (body.shape.kind == robot::ShapeKind::kCylinder) {
        const double r = size.x() * std::sqrt(rng.Uniform01());
        const double a = rng.Uniform(0, 2 * M_PI);
        p_S = Eigen::Vector3d(r * std::cos(a), r * std::sin(a), rng.Uniform(-0.5, 0.5) * size.z());
      } else {
        ASSERT_EQ(body.shape.kind, robot::ShapeKind::kBox) << body.name;
        p_S =
            Eigen::Vector3d(rng.Uniform(-0.5, 0.5), rng.Uniform(-0.5, 0.5), rng.Uniform(-0.5, 0.5))
                .cwiseProduct(size);
      }
      const Eigen::Vector3d p_L = body.X_LG * p_S;
      bool inside = false;
      for (const Sphere& s : body.spheres) inside = inside || (p_L - s.center).norm() <= s.radius;
      ASSERT_TRUE(inside) << body.name << " point " << p_S.transpose();
    }
  }
}

TEST(RobotGeometryTest, MaxDisplacementBoundsHowFarEveryPointMoves) {
  const RobotGeometry& g = DefaultGeometry();
  const robot::ArmModel& arm = DefaultArm();
  Rng rng(11);
  for (int k = 0; k < 200; ++k) {
    const Eigen::VectorXd a = arm.RandomJoints(rng);
    const Eigen::VectorXd b = arm.RandomJoints(rng);
    const double bound = g.MaxDisplacement(b - a);
    // The path length of every sphere centre along the straight joint segment, summed finely.
    const int steps = 200;
    std::vector<double> travelled(64, 0.0);
    std::vector<Eigen::Vector3d> previous;
    for (int i = 0; i <= steps; ++i) {
      const std::vector<Eigen::Isometry3d> links = g.LinkPoses(a + (b - a) * i / steps);
      std::vector<Eigen::Vector3d> now;
      for (const RobotBody& body : g.bodies()) {
        for (const Sphere& s : body.spheres) {
          // The sphere's farthest point along the motion is within its radius of the centre;
          // the centre's path is what the bound covers (radius included in Rᵢ).
          now.push_back(links[static_cast<size_t>(body.link)] * s.center);
        }
      }
      if (!previous.empty()) {
        for (size_t j = 0; j < now.size(); ++j) travelled[j] += (now[j] - previous[j]).norm();
      }
      previous = std::move(now);
    }
    for (size_t j = 0; j < previous.size(); ++j) ASSERT_LE(travelled[j], bound + 1e-9) << k;
  }
}

TEST(RobotGeometryTest, AllowedPairsAreAdjacentOrComputedAndHomeIsFree) {
  const RobotGeometry& g = DefaultGeometry();
  EXPECT_FALSE(g.self_check_pairs().empty());
  EXPECT_EQ(g.SelfCollision(DefaultArm().home_joints()), std::make_pair(-1, -1));
  int adjacent = 0;
  for (const AllowedPair& p : g.allowed_pairs()) {
    adjacent += p.reason == AllowedReason::kAdjacent ? 1 : 0;
    // An allowed pair is never also checked.
    for (const auto& c : g.self_check_pairs()) {
      EXPECT_FALSE(c.first == p.a && c.second == p.b);
    }
  }
  EXPECT_GE(adjacent, 5);  // base–link_1, link_1–link_2, ... at least one per joint
  // The camera on the flange is checked against the upper arm (link_2).
  const auto index = [&](std::string_view name) {
    return static_cast<int>(FindBody(g, name) - g.bodies().data());
  };
  const std::pair<int, int> camera_upper_arm{index("link_2#0"), index("flange/d435")};
  EXPECT_NE(std::find(g.self_check_pairs().begin(), g.self_check_pairs().end(), camera_upper_arm),
            g.self_check_pairs().end());
}

TEST(RobotGeometryTest, AFoldedArmCollidesWithItselfAndFclAgrees) {
  const RobotGeometry& g = DefaultGeometry();
  // Elbow folded fully back with the wrist turned in: the camera reaches the upper arm.
  Rng rng(3);
  int colliding = 0;
  for (int k = 0; k < 3000 && colliding < 20; ++k) {
    const Eigen::VectorXd q = DefaultArm().RandomJoints(rng);
    const auto [a, b] = g.SelfCollision(q);
    if (a < 0) continue;
    ++colliding;
    // Independently: FCL's distance between the two bodies is ~0 (they touch or overlap).
    const std::vector<Eigen::Isometry3d> poses = g.BodyPoses(q);
    fcl::DistanceRequestd request;
    request.enable_signed_distance = true;
    fcl::DistanceResultd result;
    const fcl::CollisionObjectd oa(std::const_pointer_cast<fcl::CollisionGeometryd>(
                                       g.bodies()[static_cast<size_t>(a)].geometry),
                                   poses[static_cast<size_t>(a)]);
    const fcl::CollisionObjectd ob(std::const_pointer_cast<fcl::CollisionGeometryd>(
                                       g.bodies()[static_cast<size_t>(b)].geometry),
                                   poses[static_cast<size_t>(b)]);
    EXPECT_LE(fcl::distance(&oa, &ob, request, result), 1e-6)
        << g.bodies()[static_cast<size_t>(a)].name << " – "
        << g.bodies()[static_cast<size_t>(b)].name;
  }
  EXPECT_GT(colliding, 0) << "no self-colliding state among 3000 random ones";
}

// ---- URDFs without collision geometry, bad geometry, meshes ------------------------------------

std::string TwoLinkUrdf(const std::string& link1_geometry) {
  return R"(<robot name="two">
  <link name="base"/>
  <link name="l1">)" +
         link1_geometry + R"(</link>
  <link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="tip"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
</robot>)";
}

Result<RobotGeometry> GeometryOf(const std::string& urdf, const std::filesystem::path& folder) {
  robot::ArmConfig config;
  config.urdf_path = folder / "two.urdf";
  config.base_link = "base";
  config.tip_link = "tip";
  AVP_ASSIGN_OR_RETURN(const robot::ArmModel arm, robot::ArmModel::FromUrdfString(urdf, config));
  return RobotGeometry::Create(arm);
}

class RobotGeometryUrdfTest : public avp::test::TempDirTest {};

TEST_F(RobotGeometryUrdfTest, VisualShapesStandInForMissingCollisionShapesWithAWarning) {
  const Result<RobotGeometry> g = GeometryOf(
      TwoLinkUrdf(R"(<visual><geometry><box size="0.1 0.1 0.3"/></geometry></visual>)"), dir_);
  ASSERT_TRUE(g.ok()) << g.status().ToString();
  EXPECT_EQ(g->source(), GeometrySource::kVisual);
  ASSERT_EQ(g->warnings().size(), 1u);
  EXPECT_NE(g->warnings()[0].find("no <collision> shape"), std::string::npos);
  ASSERT_EQ(g->bodies().size(), 1u);
}

TEST_F(RobotGeometryUrdfTest, ANakedUrdfIsModelledAsCylindersBetweenJointsWithAWarning) {
  const Result<RobotGeometry> g = GeometryOf(TwoLinkUrdf(""), dir_);
  ASSERT_TRUE(g.ok()) << g.status().ToString();
  EXPECT_EQ(g->source(), GeometrySource::kCapsules);
  ASSERT_EQ(g->warnings().size(), 1u);
  EXPECT_NE(g->warnings()[0].find("neither <collision> nor <visual>"), std::string::npos);
  // One cylinder along l1, from joint j1 (z 0.1) to j2 (z 0.4): it covers (0, 0, 0.25) in W.
  ASSERT_GE(g->bodies().size(), 1u);
  const RobotBody& b = g->bodies()[0];
  const Eigen::Vector3d mid =
      g->LinkPoses(Eigen::VectorXd::Zero(2))[static_cast<size_t>(b.link)] * b.X_LG.translation();
  EXPECT_NEAR((mid - Eigen::Vector3d(0, 0, 0.25)).norm(), 0.0, 1e-9);
}

TEST_F(RobotGeometryUrdfTest, AJointWithLimitsOfZeroWidthIsRefusedByTheChecker) {
  std::string urdf =
      TwoLinkUrdf(R"(<collision><geometry><box size="0.1 0.1 0.3"/></geometry></collision>)");
  const std::string limits = R"(<axis xyz="0 1 0"/><limit lower="-1" upper="1")";
  ASSERT_NE(urdf.find(limits), std::string::npos);
  urdf.replace(urdf.find(limits), limits.size(),
               R"(<axis xyz="0 1 0"/><limit lower="0.3" upper="0.3")");
  Result<RobotGeometry> g = GeometryOf(urdf, dir_);
  ASSERT_TRUE(g.ok()) << g.status().ToString();  // the model itself may hold such a joint
  const Result<CollisionChecker> c = CollisionChecker::Create(*std::move(g), {}, {});
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(c.status().message().find("joint 'j2' has limits of zero width ([0.3, 0.3])"),
            std::string::npos)
      << c.status().ToString();
}

TEST_F(RobotGeometryUrdfTest, DegenerateGeometryIsNamed) {
  const Result<RobotGeometry> g = GeometryOf(
      TwoLinkUrdf(R"(<collision><geometry><box size="0.1 0 0.3"/></geometry></collision>)"), dir_);
  ASSERT_FALSE(g.ok());
  EXPECT_NE(g.status().message().find("link 'l1'"), std::string::npos) << g.status().ToString();
  EXPECT_NE(g.status().message().find("box size (0.1, 0, 0.3)"), std::string::npos)
      << g.status().ToString();
}

TEST_F(RobotGeometryUrdfTest, MeshesAreReadAndMissingOnesNamed) {
  // A tetrahedron in ASCII STL, scaled by 2.
  std::ofstream(dir_ / "tet.stl")
      << "solid t\n"
         "facet normal 0 0 -1\nouter loop\nvertex 0 0 0\nvertex 0.1 0 0\n"
         "vertex 0 0.1 0\nendloop\nendfacet\n"
         "facet normal 0 -1 0\nouter loop\nvertex 0 0 0\nvertex 0 0 0.1\n"
         "vertex 0.1 0 0\nendloop\nendfacet\n"
         "facet normal -1 0 0\nouter loop\nvertex 0 0 0\nvertex 0 0.1 0\n"
         "vertex 0 0 0.1\nendloop\nendfacet\n"
         "facet normal 1 1 1\nouter loop\nvertex 0.1 0 0\nvertex 0 0 0.1\n"
         "vertex 0 0.1 0\nendloop\nendfacet\nendsolid t\n";
  const Result<RobotGeometry> g = GeometryOf(
      TwoLinkUrdf(
          R"(<collision><geometry><mesh filename="tet.stl" scale="2 2 2"/></geometry></collision>)"),
      dir_);
  ASSERT_TRUE(g.ok()) << g.status().ToString();
  ASSERT_EQ(g->bodies().size(), 1u);
  EXPECT_EQ(g->bodies()[0].shape.kind, robot::ShapeKind::kMesh);
  EXPECT_NEAR(g->bodies()[0].geometry->aabb_local.max_.x(), 0.2, 1e-6);  // STL: floats

  const Result<RobotGeometry> missing = GeometryOf(
      TwoLinkUrdf(R"(<collision><geometry><mesh filename="gone.stl"/></geometry></collision>)"),
      dir_);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("gone.stl"), std::string::npos);

  const Result<RobotGeometry> package = GeometryOf(
      TwoLinkUrdf(
          R"(<collision><geometry><mesh filename="package://rebel/l1.stl"/></geometry></collision>)"),
      dir_);
  ASSERT_FALSE(package.ok());
  EXPECT_NE(package.status().message().find("package://rebel/l1.stl"), std::string::npos);
}

/// Sets a process-wide limit by name for a scope, restoring its value after (the limit's accessor
/// is internal to robot_geometry.cpp, so core's ScopedLimit, which takes it, cannot be used).
class ScopedLimitByName {
 public:
  ScopedLimitByName(std::string_view name, uint64_t value) : name_(name) {
    for (const LimitInfo& info : RegisteredLimits()) {
      if (info.name == name_) previous_ = info.value;
    }
    ok_ = previous_ != 0 && SetLimit(name_, value).ok();
  }
  ~ScopedLimitByName() {
    if (previous_ != 0) (void)SetLimit(name_, previous_);
  }
  bool ok() const { return ok_; }

 private:
  std::string name_;
  uint64_t previous_ = 0;
  bool ok_ = false;
};

TEST_F(RobotGeometryUrdfTest, AMeshFileLargerThanTheLimitIsRefusedBeforeAssimpReadsIt) {
  // Registered when the program starts, 256 MiB by default.
  bool listed = false;
  for (const LimitInfo& info : RegisteredLimits()) {
    if (info.name != "max_collision_mesh_file_bytes") continue;
    listed = true;
    EXPECT_EQ(info.default_value, uint64_t{256} << 20);
    EXPECT_EQ(info.unit, "bytes");
  }
  ASSERT_TRUE(listed);

  // Not a mesh at all: past the limit it is refused by its size, before assimp could fail on it.
  const std::string junk(300, 'x');
  std::ofstream(dir_ / "huge.stl") << junk;
  const std::string urdf =
      TwoLinkUrdf(R"(<collision><geometry><mesh filename="huge.stl"/></geometry></collision>)");
  {
    const ScopedLimitByName tiny("max_collision_mesh_file_bytes", 100);
    ASSERT_TRUE(tiny.ok());
    const Result<RobotGeometry> g = GeometryOf(urdf, dir_);
    ASSERT_FALSE(g.ok());
    EXPECT_EQ(g.status().code(), StatusCode::kResourceExhausted) << g.status().ToString();
    const std::string m = g.status().message();
    EXPECT_NE(m.find("link 'l1'"), std::string::npos) << m;
    EXPECT_NE(m.find((dir_ / "huge.stl").string()), std::string::npos) << m;           // the file
    EXPECT_NE(m.find("of 300 bytes"), std::string::npos) << m;                         // its size
    EXPECT_NE(m.find("max_collision_mesh_file_bytes = 100"), std::string::npos) << m;  // limit
    EXPECT_NE(m.find("--limit max_collision_mesh_file_bytes=N"), std::string::npos) << m;
  }
  {
    // A file exactly at the limit is not refused by its size.
    const ScopedLimitByName exact("max_collision_mesh_file_bytes", 300);
    ASSERT_TRUE(exact.ok());
    const Result<RobotGeometry> g = GeometryOf(urdf, dir_);
    ASSERT_FALSE(g.ok());
    EXPECT_NE(g.status().code(), StatusCode::kResourceExhausted) << g.status().ToString();
  }
  // Within the default limit the same file reaches assimp, which cannot read it.
  const Result<RobotGeometry> g = GeometryOf(urdf, dir_);
  ASSERT_FALSE(g.ok());
  EXPECT_NE(g.status().code(), StatusCode::kResourceExhausted) << g.status().ToString();
  EXPECT_NE(g.status().message().find("cannot read mesh"), std::string::npos)
      << g.status().ToString();
}

}  // namespace
}  // namespace avp::motion
