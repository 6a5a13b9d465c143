#include <cmath>
#include <limits>
#include <string>

#include <Eigen/Geometry>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/scene.h>

namespace avp::sim {
namespace {

using ::testing::HasSubstr;

SceneObject MeshObject(std::string name, SemanticClass c, TriangleMesh mesh) {
  SceneObject o;
  o.name = std::move(name);
  o.semantic_class = c;
  o.shape = std::move(mesh);
  return o;
}

SceneObject Fruit(std::string name, const Eigen::Vector3d& center, double radius) {
  SceneObject o;
  o.name = std::move(name);
  o.semantic_class = SemanticClass::kFruit;
  Ellipsoid e;
  e.center_W = center;
  e.radii = Eigen::Vector3d::Constant(radius);
  o.shape = e;
  return o;
}

TEST(TriangleMeshTest, AppendOffsetsIndicesAndTransformsVertices) {
  TriangleMesh a = MakeQuad(1.0, 1.0);
  const TriangleMesh b = MakeQuad(0.5, 0.5);
  a.Append(b, RigidTransform(Eigen::Vector3d(0, 0, 2)));
  ASSERT_EQ(a.vertices.size(), 8u);
  ASSERT_EQ(a.num_triangles(), 4u);
  EXPECT_EQ(a.triangles[2], b.triangles[0] + Eigen::Vector3i::Constant(4));
  EXPECT_FLOAT_EQ(a.vertices[4].z(), 2.0f);
  EXPECT_FLOAT_EQ(a.vertices[4].x(), -0.5f);
  EXPECT_TRUE(a.Validate().ok());
  const Box3 bounds = a.Bounds();
  EXPECT_DOUBLE_EQ(bounds.min().z(), 0.0);
  EXPECT_DOUBLE_EQ(bounds.max().z(), 2.0);
}

TEST(TriangleMeshTest, TransformRotatesAndTranslates) {
  TriangleMesh m;
  m.vertices = {{1, 0, 0}};
  m.Transform(
      RigidTransform(Eigen::AngleAxisd(EIGEN_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
                     Eigen::Vector3d(0, 0, 1)));
  EXPECT_NEAR(m.vertices[0].x(), 0.0f, 1e-7f);
  EXPECT_NEAR(m.vertices[0].y(), 1.0f, 1e-7f);
  EXPECT_NEAR(m.vertices[0].z(), 1.0f, 1e-7f);
  EXPECT_TRUE(TriangleMesh{}.Bounds().IsEmpty());
  EXPECT_TRUE(TriangleMesh{}.empty());
}

TEST(TriangleMeshTest, ValidateNamesTheFirstBadElement) {
  TriangleMesh m = MakeQuad(1.0, 1.0);
  m.triangles.push_back({0, 1, 7});
  Status s = m.Validate();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("triangle 2"));
  EXPECT_THAT(s.message(), HasSubstr("(0, 1, 7)"));
  m = MakeQuad(1.0, 1.0);
  m.vertices[3].y() = std::numeric_limits<float>::quiet_NaN();
  s = m.Validate();
  EXPECT_THAT(s.message(), HasSubstr("vertex 3"));
}

TEST(EllipsoidTest, ImplicitAndBoundsFollowTheRotation) {
  Ellipsoid e;
  e.center_W = Eigen::Vector3d(1, 2, 3);
  e.radii = Eigen::Vector3d(0.3, 0.1, 0.2);
  // Rotate 90 deg about z: the 0.3 axis now points along world y.
  e.R_WE = Eigen::AngleAxisd(EIGEN_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  EXPECT_NEAR(e.Implicit(e.center_W), -1.0, 1e-12);
  EXPECT_NEAR(e.Implicit(e.center_W + Eigen::Vector3d(0, 0.3, 0)), 0.0, 1e-12);
  EXPECT_NEAR(e.Implicit(e.center_W + Eigen::Vector3d(0.1, 0, 0)), 0.0, 1e-12);
  EXPECT_GT(e.Implicit(e.center_W + Eigen::Vector3d(0.3, 0, 0)), 0.0);
  const Box3 b = e.Bounds();
  EXPECT_TRUE(b.min().isApprox(Eigen::Vector3d(0.9, 1.7, 2.8), 1e-12));
  EXPECT_TRUE(b.max().isApprox(Eigen::Vector3d(1.1, 2.3, 3.2), 1e-12));

  // 45 deg about z: half extents sqrt((0.3^2 + 0.1^2) / 2) in x and y.
  e.R_WE = Eigen::AngleAxisd(EIGEN_PI / 4, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const double h = std::sqrt((0.09 + 0.01) / 2.0);
  EXPECT_NEAR(e.Bounds().size().x(), 2 * h, 1e-12);
  EXPECT_NEAR(e.Bounds().size().y(), 2 * h, 1e-12);
}

TEST(SceneTest, AddAssignsIncreasingUniqueIds) {
  Scene scene;
  EXPECT_EQ(scene.Add(MeshObject("a", SemanticClass::kLeaf, MakeQuad(1, 1))), 1);
  EXPECT_EQ(scene.Add(Fruit("f", {0, 0, 1}, 0.02)), 2);
  // Ids continue after the largest one, even if objects were removed in between.
  scene.objects.erase(scene.objects.begin());
  EXPECT_EQ(scene.Add(Fruit("g", {0, 0, 2}, 0.02)), 3);
  EXPECT_EQ(scene.objects.size(), 2u);
  EXPECT_EQ(scene.FindInstance(3)->name, "g");
  EXPECT_EQ(scene.FindInstance(1), nullptr);
  EXPECT_TRUE(scene.Validate().ok());
}

TEST(SceneTest, AddThrowsPastTheLastId) {
  Scene scene;
  scene.objects.resize(1);
  scene.objects[0].instance_id = 65535;
  try {
    scene.Add(Fruit("x", {0, 0, 0}, 0.01));
    FAIL() << "expected avp::Error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("next = 65536"));
  }
}

TEST(SceneTest, FruitsReportCentresAndRadiiInIdOrder) {
  Scene scene;
  scene.Add(MeshObject("leaf", SemanticClass::kLeaf, MakeQuad(1, 1)));
  scene.Add(Fruit("b", {0.7, 0.1, 0.8}, 0.03));
  TriangleMesh box = MakeBox(Box3({0.5, -0.1, 0.5}, {0.56, -0.04, 0.58}));
  scene.Add(MeshObject("mesh_fruit", SemanticClass::kFruit, box));
  const std::vector<FruitTruth> fruits = scene.Fruits();
  ASSERT_EQ(fruits.size(), 2u);
  EXPECT_EQ(fruits[0].instance_id, 2);
  EXPECT_EQ(fruits[0].name, "b");
  EXPECT_TRUE(fruits[0].center_W.isApprox(Eigen::Vector3d(0.7, 0.1, 0.8)));
  EXPECT_DOUBLE_EQ(fruits[0].mean_radius_m(), 0.03);
  // A mesh fruit: the centre and half size of its bounding box.
  EXPECT_TRUE(fruits[1].center_W.isApprox(Eigen::Vector3d(0.53, -0.07, 0.54), 1e-6));
  EXPECT_TRUE(fruits[1].radii.isApprox(Eigen::Vector3d(0.03, 0.03, 0.04), 1e-5));
  EXPECT_EQ(scene.num_triangles(), 2u + 12u);
}

TEST(SceneTest, PlantBoundsSkipGroundAndBackground) {
  Scene scene;
  TriangleMesh ground = MakeQuad(5, 5);
  scene.Add(MeshObject("ground", SemanticClass::kGround, ground));
  scene.Add(MeshObject("wall", SemanticClass::kBackground, MakeBox(Box3({3, -5, 0}, {3.1, 5, 3}))));
  scene.Add(Fruit("f", {0.7, 0, 0.8}, 0.03));
  scene.Add(
      MeshObject("stake", SemanticClass::kSupport, MakeBox(Box3({0.7, 0, 0}, {0.71, 0.01, 1.2}))));
  scene.UpdatePlantBounds();
  EXPECT_TRUE(scene.plant_bounds.min().isApprox(Eigen::Vector3d(0.67, -0.03, 0.0), 1e-6));
  EXPECT_TRUE(scene.plant_bounds.max().isApprox(Eigen::Vector3d(0.73, 0.03, 1.2), 1e-6));
}

TEST(SceneTest, ValidateRejectsBadObjects) {
  Scene scene;
  scene.name = "s";
  scene.Add(Fruit("f", {0, 0, 0}, 0.02));
  scene.Add(Fruit("g", {0, 0, 1}, 0.02));
  ASSERT_TRUE(scene.Validate().ok());

  Scene duplicate = scene;
  duplicate.objects[1].instance_id = 1;
  EXPECT_THAT(duplicate.Validate().message(), HasSubstr("instance id 1 is used twice"));

  Scene zero = scene;
  zero.objects[0].instance_id = 0;
  EXPECT_THAT(zero.Validate().message(), HasSubstr("instance id 0"));

  Scene flat = scene;
  std::get<Ellipsoid>(flat.objects[1].shape).radii.z() = 0.0;
  EXPECT_THAT(flat.Validate().message(), HasSubstr("object 'g'"));

  Scene broken = scene;
  TriangleMesh bad = MakeQuad(1, 1);
  bad.triangles[0][0] = -1;
  broken.Add(MeshObject("bad_leaf", SemanticClass::kLeaf, bad));
  const Status s = broken.Validate();
  EXPECT_THAT(s.message(), HasSubstr("bad_leaf"));
  EXPECT_THAT(s.message(), HasSubstr("(-1, 1, 2)"));
}

}  // namespace
}  // namespace avp::sim
