#include <chrono>
#include <cmath>
#include <future>
#include <iostream>
#include <limits>
#include <memory>
#include <numbers>
#include <optional>
#include <set>
#include <string>
#include <variant>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/core/rng.h>
#include <avp/motion/robot_geometry.h>
#include <avp/robot/arm_model.h>
#include <avp/robot/trajectory.h>
#include <avp/sim/contact_counter.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/scenario.h>
#include <avp/sim/sim_arm.h>

namespace avp::sim {
namespace {

using ::testing::HasSubstr;

constexpr double kPi = std::numbers::pi;

const robot::ArmModel& Arm() {
  static const robot::ArmModel arm = robot::LoadDefaultArm().value();
  return arm;
}

const motion::RobotGeometry& Geometry() {
  static const motion::RobotGeometry geometry = motion::RobotGeometry::Create(Arm()).value();
  return geometry;
}

ContactCounter Counter(const Scene& scene, double max_step_m = 0.002) {
  return ContactCounter::Create(scene, Geometry(), max_step_m).value();
}

/// Index of the body whose name ends with `suffix` ("d435": the camera attached to the flange).
size_t BodyIndex(const std::string& suffix) {
  const std::vector<motion::RobotBody>& bodies = Geometry().bodies();
  for (size_t i = 0; i < bodies.size(); ++i) {
    const std::string& n = bodies[i].name;
    if (n.size() >= suffix.size() &&
        n.compare(n.size() - suffix.size(), suffix.size(), suffix) == 0) {
      return i;
    }
  }
  throw Error("no robot body named *" + suffix);
}

Eigen::VectorXd Home() { return Arm().home_joints(); }

/// Home with joint 1 at `q1` (joint 1 turns the whole arm about the vertical axis through the
/// base, by Rz(−q1)).
Eigen::VectorXd Yawed(double q1) {
  Eigen::VectorXd q = Home();
  q[0] = q1;
  return q;
}

/// The motion of the tests: joint 1 sweeps 90°, the rest at home. Halfway, the whole arm has
/// turned by 45°.
const Eigen::VectorXd kStart = Yawed(0.0);
const Eigen::VectorXd kMid = Yawed(kPi / 4);
const Eigen::VectorXd kEnd = Yawed(kPi / 2);

/// X_WG of the camera body (the D435's box, 25 x 90 x 25 mm, its long side along G's y) at q.
Eigen::Isometry3d CameraBodyPose(const Eigen::VectorXd& q) {
  return Geometry().BodyPoses(q)[BodyIndex("d435")];
}

RigidTransform ToRigid(const Eigen::Isometry3d& X) {
  return RigidTransform(Eigen::Matrix3d(X.linear()), Eigen::Vector3d(X.translation()));
}

/// A point inside the camera body, near its +y end and top face, away from every other body
/// (the bracket ends at G's y = ±0.02 and below G's z = 0).
const Eigen::Vector3d kInsideCamera_G(0.0, 0.035, 0.004);

/// An 8 x 2 x 8 mm plate (thin along G's y) centred at kInsideCamera_G of the camera body posed
/// at q: wholly inside the camera body at q.
TriangleMesh PlateInCameraAt(const Eigen::VectorXd& q) {
  TriangleMesh plate = MakeBox(Eigen::Vector3d(0.004, 0.001, 0.004));
  Eigen::Isometry3d X = CameraBodyPose(q);
  X.translation() = X * kInsideCamera_G;
  plate.Transform(ToRigid(X));
  return plate;
}

/// A 2 cm thick vertical wall in the half-plane at azimuth `azimuth_rad` from the base's axis,
/// from 0.12 m to 0.6 m out and from 0.2 m to 0.9 m up.
TriangleMesh RadialWall(double azimuth_rad) {
  TriangleMesh wall =
      MakeBox(Box3(Eigen::Vector3d(0.12, -0.01, 0.2), Eigen::Vector3d(0.6, 0.01, 0.9)));
  wall.Transform(
      RigidTransform(Eigen::AngleAxisd(azimuth_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
                     Eigen::Vector3d::Zero()));
  return wall;
}

Scene SceneWith(std::string name, SemanticClass c, std::variant<TriangleMesh, Ellipsoid> shape) {
  Scene scene;
  scene.Add(std::move(name), c, Eigen::Vector3f(0.3f, 0.6f, 0.2f), std::move(shape));
  return scene;
}

std::string Describe(const std::vector<ContactInterval>& contacts) {
  std::string out;
  for (const ContactInterval& c : contacts) {
    out += c.Describe() + " [samples " + std::to_string(c.first_sample) + ".." +
           std::to_string(c.last_sample) + "]\n";
  }
  return out;
}

// ---- Setup
// ---------------------------------------------------------------------------------------

TEST(ContactCounterTest, CategoriesOfTheSemanticClasses) {
  EXPECT_EQ(ContactCategoryOf(SemanticClass::kFruit), ContactCategory::kFruit);
  EXPECT_EQ(ContactCategoryOf(SemanticClass::kLeaf), ContactCategory::kPlant);
  EXPECT_EQ(ContactCategoryOf(SemanticClass::kStem), ContactCategory::kPlant);
  EXPECT_EQ(ContactCategoryOf(SemanticClass::kSupport), ContactCategory::kSupport);
  EXPECT_EQ(ContactCategoryOf(SemanticClass::kOther), ContactCategory::kSupport);
  EXPECT_EQ(ContactCategoryOf(SemanticClass::kGround), ContactCategory::kGround);
  EXPECT_EQ(ContactCategoryOf(SemanticClass::kBackground), ContactCategory::kIgnored);
}

TEST(ContactCounterTest, RejectsABadStep) {
  for (const double step : {0.0, -0.001, std::nan("")}) {
    const Result<ContactCounter> counter = ContactCounter::Create(Scene{}, Geometry(), step);
    ASSERT_FALSE(counter.ok()) << step;
    EXPECT_THAT(counter.status().message(), HasSubstr("max_step_m"));
  }
}

TEST(ContactCounterTest, RejectsWrongWaypoints) {
  const ContactCounter counter = Counter(Scene{});
  EXPECT_THROW((void)counter.CountAlong({kStart, Eigen::VectorXd::Zero(3)}), Error);
  Eigen::VectorXd nan = kStart;
  nan[2] = std::nan("");
  EXPECT_THROW((void)counter.CountAt(nan), Error);
  EXPECT_EQ(counter.CountAlong({}).total(), 0);
}

TEST(ContactCounterTest, SamplesSoThatNoPointMovesMoreThanTheStep) {
  const ContactCounter counter = Counter(Scene{}, 0.002);
  const std::vector<Eigen::VectorXd> samples = counter.SampleAlong({kStart, kEnd});
  const int steps = static_cast<int>(std::ceil(Geometry().MaxDisplacement(kEnd - kStart) / 0.002));
  ASSERT_EQ(samples.size(), static_cast<size_t>(steps + 1));
  EXPECT_TRUE(samples.front().isApprox(kStart));
  EXPECT_TRUE(samples.back().isApprox(kEnd));
  for (size_t i = 1; i < samples.size(); ++i) {
    EXPECT_LE(Geometry().MaxDisplacement(samples[i] - samples[i - 1]), 0.002 + 1e-12);
  }
  // A polyline samples its shared vertex once.
  EXPECT_EQ(
      counter.SampleAlong({kStart, kMid, kEnd}).size(),
      counter.SampleAlong({kStart, kMid}).size() + counter.SampleAlong({kMid, kEnd}).size() - 1);
  EXPECT_EQ(counter.SampleAlong({kStart}).size(), 1u);
}

// ---- Contacts with the scene
// ---------------------------------------------------------------------

TEST(ContactCounterTest, ALeafInTheArmsPathIsOneContactNamingTheBodyAndTheLeaf) {
  const Scene scene = SceneWith("tomato/leaf_3", SemanticClass::kLeaf, PlateInCameraAt(kMid));
  const ContactCounter counter = Counter(scene);
  ASSERT_EQ(counter.num_objects(), 1u);
  EXPECT_EQ(counter.num_triangles(), 12u);
  // By construction the plate is inside the camera body halfway, 45° from both ends.
  EXPECT_EQ(counter.CountAt(kMid).plant, 1);
  EXPECT_EQ(counter.CountAt(kStart).total(), 0);
  EXPECT_EQ(counter.CountAt(kEnd).total(), 0);

  const std::vector<ContactInterval> contacts = counter.ListAlong({kStart, kEnd});
  ASSERT_EQ(contacts.size(), 1u) << Describe(contacts);
  const ContactInterval& c = contacts.front();
  EXPECT_THAT(c.body, HasSubstr("d435"));
  EXPECT_EQ(c.other, "tomato/leaf_3");
  EXPECT_EQ(c.category, ContactCategory::kPlant);
  // One run of many consecutive colliding samples: the 90 mm camera crosses a 2 mm plate.
  EXPECT_GT(c.last_sample - c.first_sample, 10);
  EXPECT_LT(c.begin_fraction, 0.5);
  EXPECT_GT(c.end_fraction, 0.5);
  EXPECT_GT(c.begin_fraction, 0.1);
  EXPECT_LT(c.end_fraction, 0.9);

  const robot::MotionContacts counts = counter.CountAlong({kStart, kEnd});
  EXPECT_EQ(counts.plant, 1);
  EXPECT_EQ(counts.total(), 1);
  EXPECT_THAT(counts.first, HasSubstr("d435"));
  EXPECT_THAT(counts.first, HasSubstr("leaf 'tomato/leaf_3' at "));
  EXPECT_THAT(counts.first, HasSubstr("% of the move"));
  std::cout << "first contact: " << counts.first << " (samples " << c.first_sample << ".."
            << c.last_sample << " of " << counter.SampleAlong({kStart, kEnd}).size() << ")\n";

  // The run goes on across a vertex of the polyline (kMid is inside it): still one contact.
  EXPECT_EQ(counter.CountAlong({kStart, kMid, kEnd}).plant, 1);
  // There and back again: two separate runs.
  EXPECT_EQ(counter.CountAlong({kStart, kEnd, kStart}).plant, 2);
}

TEST(ContactCounterTest, AWallAcrossThePathIsOneContactPerBodyThatCrossesIt) {
  // The arm lies in the vertical plane through azimuth 0 (its upper arm leans back past the
  // base's axis) and turns by −90°: its front sweeps azimuths 0 → −90°, its back 180° → 90°. A
  // wall at −45° is crossed; the same wall at +45° is not.
  const Scene across = SceneWith("wall", SemanticClass::kSupport, RadialWall(-kPi / 4));
  const ContactCounter counter = Counter(across);
  EXPECT_EQ(counter.CountAt(kStart).total(), 0);
  EXPECT_EQ(counter.CountAt(kEnd).total(), 0);
  const std::vector<ContactInterval> contacts = counter.ListAlong({kStart, kEnd});
  std::set<std::string> bodies;
  for (const ContactInterval& c : contacts) {
    bodies.insert(c.body);
    EXPECT_EQ(c.other, "wall");
  }
  // The flange crosses the wall (it is 0.19 m out, 0.62 m up); so do the links next to it.
  EXPECT_GE(bodies.size(), 2u) << Describe(contacts);
  EXPECT_EQ(bodies.size(), contacts.size()) << "one run per body: " << Describe(contacts);
  const robot::MotionContacts counts = counter.CountAlong({kStart, kEnd});
  EXPECT_EQ(counts.support, static_cast<int>(bodies.size()));
  EXPECT_EQ(counts.total(), counts.support);
  EXPECT_THAT(counts.first, HasSubstr("support 'wall' at "));
  std::cout << "wall: " << counts.support << " contacts, first: " << counts.first << "\n";

  const Scene aside = SceneWith("wall", SemanticClass::kSupport, RadialWall(kPi / 4));
  EXPECT_EQ(Counter(aside).CountAlong({kStart, kEnd}).total(), 0)
      << Describe(Counter(aside).ListAlong({kStart, kEnd}));
  // The same wall as background is not checked.
  const Scene background = SceneWith("wall", SemanticClass::kBackground, RadialWall(-kPi / 4));
  EXPECT_EQ(Counter(background).num_objects(), 0u);
  EXPECT_EQ(Counter(background).CountAlong({kStart, kEnd}).total(), 0);
}

TEST(ContactCounterTest, AFruitEllipsoidInThePathCountsAsFruit) {
  Ellipsoid fruit;
  fruit.center_W = CameraBodyPose(kMid) * kInsideCamera_G;
  fruit.radii = Eigen::Vector3d(0.01, 0.008, 0.006);
  const ContactCounter counter = Counter(SceneWith("fruit_0", SemanticClass::kFruit, fruit));
  const robot::MotionContacts counts = counter.CountAlong({kStart, kEnd});
  EXPECT_EQ(counts.fruit, 1);
  EXPECT_EQ(counts.total(), 1);
  EXPECT_THAT(counts.first, HasSubstr("fruit 'fruit_0'"));
}

TEST(ContactCounterTest, EllipsoidContactIsExactToAMillimetre) {
  // An elongated, rotated ellipsoid whose long axis points at the camera body's top face.
  const Eigen::Isometry3d X_WG = CameraBodyPose(Home());
  const double half_height = 0.0125;  // the D435 box is 25 mm high (G's z)
  for (const double gap : {-0.001, 0.001}) {
    Ellipsoid fruit;
    fruit.radii = Eigen::Vector3d(0.04, 0.015, 0.01);
    // Columns: the long axis along G's z, the others along G's x and y.
    Eigen::Matrix3d R_GE;
    R_GE.col(0) = Eigen::Vector3d::UnitZ();
    R_GE.col(1) = Eigen::Vector3d::UnitX();
    R_GE.col(2) = Eigen::Vector3d::UnitY();
    fruit.R_WE = X_WG.linear() * R_GE;
    fruit.center_W = X_WG * Eigen::Vector3d(0.0, 0.0, half_height + 0.04 + gap);
    const ContactCounter counter = Counter(SceneWith("fruit", SemanticClass::kFruit, fruit));
    EXPECT_EQ(counter.CountAt(Home()).fruit, gap < 0 ? 1 : 0) << "gap " << gap;
  }
}

TEST(ContactCounterTest, MeshContactIsExactToAMillimetre) {
  // A small horizontal leaf just above or just into the camera body's top face.
  const Eigen::Isometry3d X_WG = CameraBodyPose(Home());
  ASSERT_NEAR(std::abs(X_WG.linear()(2, 2)), 1.0, 1e-9) << "the camera's G z is vertical at home";
  const double top_z = X_WG.translation().z() + 0.0125;
  for (const double gap : {-0.001, 0.001}) {
    TriangleMesh leaf = MakeQuad(0.01, 0.01);
    leaf.Transform(RigidTransform(
        Eigen::Vector3d(X_WG.translation().x(), X_WG.translation().y(), top_z + gap)));
    const ContactCounter counter = Counter(SceneWith("leaf", SemanticClass::kLeaf, leaf));
    EXPECT_EQ(counter.CountAt(Home()).plant, gap < 0 ? 1 : 0) << "gap " << gap;
  }
}

TEST(ContactCounterTest, NearestAtNamesTheNearestObjectWithinTheDistanceAskedFor) {
  // A small horizontal leaf 12 mm above the camera body's top face, or 1 mm into it.
  const Eigen::Isometry3d X_WG = CameraBodyPose(Home());
  const double top_z = X_WG.translation().z() + 0.0125;
  const auto leaf_at = [&](double gap) {
    TriangleMesh leaf = MakeQuad(0.01, 0.01);
    leaf.Transform(RigidTransform(
        Eigen::Vector3d(X_WG.translation().x(), X_WG.translation().y(), top_z + gap)));
    return Counter(SceneWith("tomato/leaf_11", SemanticClass::kLeaf, leaf));
  };
  const ContactCounter near = leaf_at(0.012);
  const robot::TrueClearance within = near.NearestAt(Home(), 0.02);
  EXPECT_NEAR(within.distance_m, 0.012, 1e-6);
  EXPECT_THAT(within.nearest, HasSubstr("d435 – leaf 'tomato/leaf_11'"));
  const robot::TrueClearance beyond = near.NearestAt(Home(), 0.01);
  EXPECT_EQ(beyond.distance_m, std::numeric_limits<double>::infinity());
  EXPECT_EQ(beyond.nearest, "");
  EXPECT_EQ(leaf_at(-0.001).NearestAt(Home(), 0.0).distance_m, 0.0);
  EXPECT_THROW(near.NearestAt(Home(), -0.01), Error);
  EXPECT_THROW(near.NearestAt(Home(), std::numeric_limits<double>::quiet_NaN()), Error);
  // The simulated arm answers for its current joints; without a counter it cannot.
  SimArm arm(Arm(), Home());
  EXPECT_FALSE(arm.TrueClearanceNow(0.02).has_value());
  arm.SetContactCounter(std::make_shared<const ContactCounter>(near));
  ASSERT_TRUE(arm.TrueClearanceNow(0.02).has_value());
  EXPECT_NEAR(arm.TrueClearanceNow(0.02)->distance_m, 0.012, 1e-6);
}

TEST(ContactCounterTest, ContactWithALinkCylinderIsExactToAMillimetre) {
  // link_7's cylinder (radius 4 cm, axis G's z, centred): a fruit and a leaf beside its middle,
  // 1 mm off its surface or 1 mm into it.
  const size_t link7 = BodyIndex("link_7#0");
  const Eigen::Isometry3d X_WG = Geometry().BodyPoses(Home())[link7];
  constexpr double kRadius = 0.04;
  for (const double gap : {-0.001, 0.001}) {
    Ellipsoid fruit;
    fruit.radii = Eigen::Vector3d(0.03, 0.02, 0.015);  // the long axis along G's x
    fruit.R_WE = X_WG.linear();
    fruit.center_W = X_WG * Eigen::Vector3d(kRadius + 0.03 + gap, 0.0, 0.0);
    EXPECT_EQ(Counter(SceneWith("fruit", SemanticClass::kFruit, fruit)).CountAt(Home()).fruit,
              gap < 0 ? 1 : 0)
        << "gap " << gap;

    // A 2 x 2 cm quad in G's y-z plane, facing the axis, on the −x side.
    TriangleMesh leaf = MakeQuad(0.01, 0.01);
    const Eigen::Matrix3d R_GQ =
        Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();  // z → x
    leaf.Transform(RigidTransform(Eigen::Matrix3d(X_WG.linear() * R_GQ),
                                  X_WG * Eigen::Vector3d(-(kRadius + gap), 0.0, 0.0)));
    EXPECT_EQ(Counter(SceneWith("leaf", SemanticClass::kLeaf, leaf)).CountAt(Home()).plant,
              gap < 0 ? 1 : 0)
        << "gap " << gap;
  }
}

TEST(ContactCounterTest, TheGroundIsNotTouchedAtHomeButIsWhenTheArmReachesBelowIt) {
  Scene scene;
  AddGroundPlane(scene, 0.0);
  const ContactCounter counter = Counter(scene);
  // The base (fixed bodies) stands on the ground: not checked.
  EXPECT_EQ(counter.CountAt(Home()).total(), 0);
  EXPECT_EQ(counter.CountAlong({kStart, kEnd}).total(), 0);

  // Lean forward as far as the limits allow without folding onto itself: the flange goes below
  // the ground.
  Eigen::VectorXd low = Home();
  double lowest = std::numeric_limits<double>::infinity();
  for (int i = 0; i <= 8; ++i) {
    for (int j = 0; j <= 8; ++j) {
      Eigen::VectorXd q = Home();
      q[1] = Arm().lower_limits()[1] + (Arm().upper_limits()[1] - Arm().lower_limits()[1]) * i / 8;
      q[2] = Arm().lower_limits()[2] + (Arm().upper_limits()[2] - Arm().lower_limits()[2]) * j / 8;
      const double z = Arm().ForwardKinematics(q).translation().z();
      if (z < lowest && Geometry().SelfCollision(q).first < 0) {
        lowest = z;
        low = q;
      }
    }
  }
  ASSERT_LT(lowest, -0.05);
  const robot::MotionContacts counts = counter.CountAlong({Home(), low});
  EXPECT_GE(counts.ground, 1);
  EXPECT_EQ(counts.total(), counts.ground) << Describe(counter.ListAlong({Home(), low}));
  EXPECT_THAT(counts.first, HasSubstr("ground 'ground' at "));
  std::cout << "into the ground (flange z " << lowest << " m): " << counts.ground
            << " contacts, first: " << counts.first << "\n";
}

TEST(ContactCounterTest, FoldingTheArmOntoItselfIsASelfContact) {
  const ContactCounter counter = Counter(Scene{});
  EXPECT_EQ(counter.CountAt(Home()).total(), 0);
  // Fold the elbow and the wrist: the first state of the grid in self-collision.
  std::optional<Eigen::VectorXd> folded;
  for (int i = 0; i <= 8 && !folded; ++i) {
    for (int j = 0; j <= 8 && !folded; ++j) {
      Eigen::VectorXd q = Home();
      q[2] = Arm().lower_limits()[2] + (Arm().upper_limits()[2] - Arm().lower_limits()[2]) * i / 8;
      q[4] = Arm().lower_limits()[4] + (Arm().upper_limits()[4] - Arm().lower_limits()[4]) * j / 8;
      if (Geometry().SelfCollision(q).first >= 0) folded = q;
    }
  }
  ASSERT_TRUE(folded.has_value()) << "no folded state in self-collision on the grid";
  const robot::MotionContacts at = counter.CountAt(*folded);
  EXPECT_GE(at.self, 1);
  EXPECT_EQ(at.total(), at.self);
  const robot::MotionContacts along = counter.CountAlong({Home(), *folded});
  EXPECT_GE(along.self, 1);
  EXPECT_THAT(along.first, HasSubstr("self '"));
  std::cout << "folded " << folded->transpose() << ": " << along.self
            << " self contacts, first: " << along.first << "\n";
}

TEST(ContactCounterTest, ASceneFarAwayIsNeverTouched) {
  TriangleMesh wall = RadialWall(-kPi / 4);
  wall.Transform(RigidTransform(Eigen::Vector3d(10.0, 10.0, 0.0)));
  Ellipsoid fruit;
  fruit.center_W = Eigen::Vector3d(-10.0, 5.0, 0.6);
  Scene scene = SceneWith("far wall", SemanticClass::kSupport, wall);
  scene.Add("far fruit", SemanticClass::kFruit, Eigen::Vector3f(0.8f, 0.1f, 0.1f), fruit);
  const ContactCounter counter = Counter(scene);
  EXPECT_EQ(counter.num_objects(), 2u);
  const robot::MotionContacts counts = counter.CountAlong({kStart, kEnd});
  EXPECT_EQ(counts.total(), 0);
  EXPECT_EQ(counts.first, "");
}

TEST(ContactCounterTest, CopiesShareTheSceneAndQueriesAreThreadSafe) {
  const ContactCounter counter =
      Counter(SceneWith("wall", SemanticClass::kSupport, RadialWall(-kPi / 4)));
  const ContactCounter copy = counter;  // NOLINT(performance-unnecessary-copy-initialization)
  const int expected = counter.CountAlong({kStart, kEnd}).support;
  ASSERT_GE(expected, 1);
  std::vector<std::future<int>> results;
  for (int t = 0; t < 4; ++t) {
    results.push_back(std::async(std::launch::async, [&copy] {
      return copy.CountAlong({kStart, kEnd}).support;
    }));
  }
  for (std::future<int>& r : results) EXPECT_EQ(r.get(), expected);
}

// ---- A real scenario
// -----------------------------------------------------------------------------

TEST(ContactCounterTest, CountsMovesInARealScenarioQuickly) {
  const Scene scene = MakeScenario("tomato-multiple-clusters", 1).value();
  const auto t0 = std::chrono::steady_clock::now();
  const ContactCounter counter = Counter(scene);
  const double build_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::cout << "scene: " << scene.objects.size() << " objects, " << scene.num_triangles()
            << " triangles; counter: " << counter.num_objects() << " objects, "
            << counter.num_triangles() << " triangles, built in " << build_s * 1e3 << " ms\n";
  Eigen::VectorXd q = scene.start_joints_rad.empty()
                          ? Home()
                          : Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(
                                scene.start_joints_rad.data(),
                                static_cast<Eigen::Index>(scene.start_joints_rad.size())));
  Rng rng(7);
  double total_s = 0.0;
  size_t total_samples = 0;
  constexpr int kMoves = 8;
  for (int m = 0; m < kMoves; ++m) {
    // A move of up to ±0.6 rad per joint, within the limits.
    Eigen::VectorXd target = q;
    for (Eigen::Index i = 0; i < q.size(); ++i) target[i] += rng.Uniform(-0.6, 0.6);
    target = Arm().ClampToLimits(target);
    const size_t samples = counter.SampleAlong({q, target}).size();
    const auto t = std::chrono::steady_clock::now();
    const robot::MotionContacts counts = counter.CountAlong({q, target});
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
    std::cout << "move " << m << ": " << samples << " samples, " << s * 1e3 << " ms, "
              << counts.total() << " contacts (plant " << counts.plant << ", fruit " << counts.fruit
              << ", support " << counts.support << ", ground " << counts.ground << ", self "
              << counts.self << ")" << (counts.first.empty() ? "" : ": ") << counts.first << "\n";
    total_s += s;
    total_samples += samples;
    q = target;
  }
  std::cout << "mean " << total_s / kMoves * 1e3 << " ms per move, "
            << total_s / static_cast<double>(total_samples) * 1e6 << " us per sample\n";
  EXPECT_LT(total_s / kMoves, 2.0) << "CountAlong is too slow for the simulator's moves";
}

// ---- SimArm
// --------------------------------------------------------------------------------------

TEST(SimArmContactsTest, NoCounterNoContacts) {
  SimArm arm(Arm(), kStart);
  const robot::MoveResult result = arm.MoveToJoints(kEnd);
  ASSERT_TRUE(result.ok());
  EXPECT_FALSE(result.contacts.has_value());
  EXPECT_FALSE(result.straight_line_contacts.has_value());
}

TEST(SimArmContactsTest, AStraightMoveCountsItsLineTwice) {
  auto counter = std::make_shared<const ContactCounter>(
      Counter(SceneWith("leaf", SemanticClass::kLeaf, PlateInCameraAt(kMid))));
  SimArm arm(Arm(), kStart);
  arm.SetContactCounter(counter);
  EXPECT_EQ(arm.contact_counter(), counter);
  const robot::MoveResult result = arm.MoveToJoints(kEnd);
  ASSERT_TRUE(result.ok());
  ASSERT_TRUE(result.contacts.has_value());
  ASSERT_TRUE(result.straight_line_contacts.has_value());
  EXPECT_EQ(result.contacts->plant, 1);
  EXPECT_EQ(result.straight_line_contacts->plant, 1);
  EXPECT_EQ(result.contacts->first, result.straight_line_contacts->first);
  EXPECT_NEAR(result.joint_path_length, kPi / 2, 1e-12);
  EXPECT_TRUE(arm.CurrentJoints().isApprox(kEnd));
  // Back along the same line: the same contact again; then clearing the counter stops counting.
  EXPECT_EQ(arm.MoveToJoints(kStart).contacts->plant, 1);
  arm.SetContactCounter(nullptr);
  EXPECT_FALSE(arm.MoveToJoints(kEnd).contacts.has_value());
}

TEST(SimArmContactsTest, ATrajectoryAroundTheLeafTouchesNothingWhileItsStraightLineWould) {
  auto counter = std::make_shared<const ContactCounter>(
      Counter(SceneWith("leaf", SemanticClass::kLeaf, PlateInCameraAt(kMid))));
  // Around: tilt the wrist (joint 5) away, turn, tilt back.
  Eigen::VectorXd tilted_start = kStart;
  tilted_start[4] -= 0.5;
  Eigen::VectorXd tilted_end = kEnd;
  tilted_end[4] -= 0.5;
  const std::vector<Eigen::VectorXd> path = {kStart, tilted_start, tilted_end, kEnd};
  ASSERT_EQ(counter->CountAlong(path).total(), 0) << counter->CountAlong(path).first;
  const robot::JointTrajectory trajectory =
      robot::TimeParameterize(Arm(), path, 1.0, 1.0, 0.05).value();

  SimArm arm(Arm(), kStart);
  arm.SetContactCounter(counter);
  const robot::MoveResult result = arm.FollowTrajectory(trajectory);
  ASSERT_TRUE(result.ok()) << result.status.message();
  EXPECT_TRUE(arm.CurrentJoints().isApprox(kEnd));
  EXPECT_NEAR(result.joint_path_length, 0.5 + kPi / 2 + 0.5, 1e-9);
  EXPECT_DOUBLE_EQ(result.execution_s, trajectory.duration_s());
  ASSERT_TRUE(result.contacts.has_value());
  ASSERT_TRUE(result.straight_line_contacts.has_value());
  EXPECT_EQ(result.contacts->total(), 0) << result.contacts->first;
  EXPECT_EQ(result.straight_line_contacts->plant, 1);
  EXPECT_EQ(result.straight_line_contacts->total(), 1);
}

}  // namespace
}  // namespace avp::sim
