#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/sim/mesh_builder.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::sim {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

constexpr double kPi = 3.14159265358979323846;

/// Writes an OBJ object made of `mesh` (1-based indices continue from `base`).
std::string ObjObject(const std::string& name, const std::string& material,
                      const TriangleMesh& mesh, size_t& base) {
  std::string out = "o " + name + "\n";
  if (!material.empty()) out += "usemtl " + material + "\n";
  for (const Eigen::Vector3f& v : mesh.vertices) {
    out += "v " + std::to_string(v.x()) + " " + std::to_string(v.y()) + " " +
           std::to_string(v.z()) + "\n";
  }
  for (const Eigen::Vector3i& t : mesh.triangles) {
    out += "f " + std::to_string(base + t[0]) + " " + std::to_string(base + t[1]) + " " +
           std::to_string(base + t[2]) + "\n";
  }
  base += mesh.vertices.size();
  return out;
}

TriangleMesh Sphere(const Eigen::Vector3d& c, double r) {
  TriangleMesh s = MakeIcosphere(r, 1);
  s.Transform(RigidTransform(c));
  return s;
}

class SceneFileTest : public test::TempDirTest {
 protected:
  void SetUp() override {
    TempDirTest::SetUp();
    WritePlantObj();
  }

  /// plant.obj: a stem box, a leaf quad, two separate fruits and one object with two spheres.
  void WritePlantObj() {
    size_t base = 1;
    std::string obj = "mtllib plant.mtl\n";
    obj += ObjObject("stem", "green_stem", MakeBox(Box3({-0.01, -0.01, 0}, {0.01, 0.01, 1})), base);
    TriangleMesh leaf = MakeQuad(0.05, 0.02);
    leaf.Transform(RigidTransform(Eigen::Vector3d(0.06, 0, 0.5)));
    obj += ObjObject("leaf_1", "leafy", leaf, base);
    obj += ObjObject("fruit_a", "red", Sphere({0.1, 0.0, 0.6}, 0.03), base);
    obj += ObjObject("fruit_b", "red", Sphere({-0.1, 0.0, 0.6}, 0.02), base);
    TriangleMesh pair = Sphere({0.0, 0.1, 0.7}, 0.02);
    pair.Append(Sphere({0.0, 0.2, 0.7}, 0.02));
    obj += ObjObject("fruit_pair", "red", pair, base);
    Write("plant.obj", obj);
    Write("plant.mtl",
          "newmtl green_stem\nKd 0.1 0.3 0.1\nnewmtl leafy\nKd 0.05 0.4 0.05\n"
          "newmtl red\nKd 0.7 0.05 0.02\n");
  }

  Result<Scene> Load(const std::string& yaml) { return LoadSceneFile(Write("scene.yaml", yaml)); }

  static std::map<SemanticClass, int> CountClasses(const Scene& s) {
    std::map<SemanticClass, int> n;
    for (const SceneObject& o : s.objects) ++n[o.semantic_class];
    return n;
  }

  static const SceneObject& Named(const Scene& s, const std::string& name) {
    for (const SceneObject& o : s.objects) {
      if (o.name == name) return o;
    }
    ADD_FAILURE() << "no object " << name;
    return s.objects.front();
  }
};

const char* kPlantYaml = R"(version: 1
name: test_plant
description: a test
meshes:
  - file: plant.obj
    pose: {xyz: [0.7, 0.0, 0.0], rpy_deg: [0, 0, 90]}
    fruit_instances: components
    default_class: other
    classes:
      - {match: "fruit_*", class: fruit}
      - {match: "leaf*", class: leaf, color: [0.0, 1.0, 0.0]}
      - {match: "green_stem", class: stem}
)";

TEST_F(SceneFileTest, ObjGroupsBecomeClassedObjectsWithPosesApplied) {
  const Result<Scene> r = Load(kPlantYaml);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const Scene& s = *r;
  EXPECT_EQ(s.name, "test_plant");
  EXPECT_EQ(s.description, "a test");
  EXPECT_TRUE(s.Validate().ok());
  std::map<SemanticClass, int> n = CountClasses(s);
  EXPECT_EQ(n[SemanticClass::kStem], 1);  // matched by its material name
  EXPECT_EQ(n[SemanticClass::kLeaf], 1);
  // fruit_a, fruit_b, and fruit_pair split into its two connected components.
  EXPECT_EQ(n[SemanticClass::kFruit], 4);
  EXPECT_EQ(n[SemanticClass::kGround], 0);
  // Rotated 90 deg about z then moved to x = 0.7: fruit_a (0.1, 0, 0.6) -> (0.7, 0.1, 0.6).
  const std::vector<FruitTruth> fruits = s.Fruits();
  ASSERT_EQ(fruits.size(), 4u);
  EXPECT_EQ(fruits[0].name, "plant/fruit_a");
  EXPECT_LT((fruits[0].center_W - Eigen::Vector3d(0.7, 0.1, 0.6)).norm(), 1e-5);
  EXPECT_LT((fruits[1].center_W - Eigen::Vector3d(0.7, -0.1, 0.6)).norm(), 1e-5);
  EXPECT_EQ(fruits[2].name, "plant/fruit_pair#0");
  EXPECT_EQ(fruits[3].name, "plant/fruit_pair#1");
  EXPECT_LT((fruits[2].center_W - Eigen::Vector3d(0.6, 0.0, 0.7)).norm(), 1e-5);
  EXPECT_LT((fruits[3].center_W - Eigen::Vector3d(0.5, 0.0, 0.7)).norm(), 1e-5);
  // Colours: from the MTL file unless a rule overrides.
  EXPECT_NEAR(Named(s, "plant/fruit_a").albedo.x(), 0.7f, 1e-6f);
  EXPECT_NEAR(Named(s, "plant/stem").albedo.y(), 0.3f, 1e-6f);
  EXPECT_EQ(Named(s, "plant/leaf_1").albedo, Eigen::Vector3f(0, 1, 0));
  // Defaults: the reference start.
  EXPECT_TRUE(s.X_WC_start.IsNearlyEqualTo(ReferenceStartCameraPose(), 1e-12, 1e-12));
  EXPECT_EQ(s.start_joints_rad, ReferenceStartJointsRad());
  EXPECT_NEAR(s.plant_bounds.max().z(), 1.0, 1e-6);
}

TEST_F(SceneFileTest, FruitInstancesObjectsKeepsMeshesWhole) {
  std::string yaml = kPlantYaml;
  yaml.replace(yaml.find("components"), 10, "objects");
  const Result<Scene> r = Load(yaml);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(CountClasses(*r)[SemanticClass::kFruit], 3);
}

TEST_F(SceneFileTest, ScaleStartCameraAndGroundAreRead) {
  const Result<Scene> r = Load(R"(version: 1
start_joints_deg: [10, -60, 50, 0, 40, 0]
start_camera: {eye: [0.2, 0.1, 0.7], target: [1.2, 0.1, 0.7]}
ground: {z_m: -0.05, color: [0.2, 0.2, 0.2]}
meshes:
  - file: plant.obj
    scale: 2.0
    color: [0.5, 0.5, 0.0]
)");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const Scene& s = *r;
  EXPECT_EQ(s.name, "scene");  // the YAML file's stem
  ASSERT_EQ(s.start_joints_rad.size(), 6u);
  EXPECT_NEAR(s.start_joints_rad[0], 10.0 * kPi / 180.0, 1e-15);
  EXPECT_TRUE(s.X_WC_start.translation().isApprox(Eigen::Vector3d(0.2, 0.1, 0.7)));
  EXPECT_TRUE(s.X_WC_start.rotation().col(2).isApprox(Eigen::Vector3d::UnitX()));
  EXPECT_TRUE((-s.X_WC_start.rotation().col(1)).isApprox(Eigen::Vector3d::UnitZ()));
  // Everything is class 'other' (no rules) with the override colour; the stem is 2 m tall.
  const std::map<SemanticClass, int> n = CountClasses(s);
  EXPECT_EQ(n.at(SemanticClass::kOther), 5);
  EXPECT_EQ(n.at(SemanticClass::kGround), 1);
  EXPECT_NEAR(s.plant_bounds.max().z(), 2.0, 1e-6);
  for (const SceneObject& o : s.objects) {
    if (o.semantic_class == SemanticClass::kGround) {
      EXPECT_NEAR(o.Bounds().min().z(), -0.05, 1e-7);
      EXPECT_EQ(o.albedo, Eigen::Vector3f(0.2f, 0.2f, 0.2f));
    } else {
      EXPECT_EQ(o.albedo, Eigen::Vector3f(0.5f, 0.5f, 0.0f));
    }
  }
  // A yawed reference start needs no camera: it follows joint 1.
  const Result<Scene> yawed = Load(R"(version: 1
start_joints_deg: [30, -70, 60, 0, 47.5, 0]
ground: true
meshes: [{file: plant.obj}]
)");
  ASSERT_TRUE(yawed.ok()) << yawed.status().ToString();
  EXPECT_TRUE(yawed->X_WC_start.IsNearlyEqualTo(ReferenceStartCameraPose(30.0), 1e-12, 1e-12));
  EXPECT_EQ(CountClasses(*yawed)[SemanticClass::kGround], 1);
}

TEST_F(SceneFileTest, PlyTextIsLoadedWithTheDefaultClass) {
  Write("tri.ply", R"(ply
format ascii 1.0
element vertex 4
property float x
property float y
property float z
element face 2
property list uchar int vertex_indices
end_header
0 0 0
0.1 0 0
0.1 0.1 0
0 0.1 0
3 0 1 2
3 0 2 3
)");
  const Result<Scene> r = Load(R"(version: 1
meshes:
  - file: tri.ply
    default_class: leaf
    pose: {xyz: [1, 2, 3]}
)");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->objects.size(), 1u);
  const SceneObject& o = r->objects[0];
  EXPECT_EQ(o.semantic_class, SemanticClass::kLeaf);
  EXPECT_EQ(o.num_triangles(), 2u);
  EXPECT_EQ(o.name.rfind("tri/", 0), 0u) << o.name;
  EXPECT_TRUE(o.Bounds().min().isApprox(Eigen::Vector3d(1, 2, 3), 1e-6));
  EXPECT_TRUE(o.Bounds().max().isApprox(Eigen::Vector3d(1.1, 2.1, 3), 1e-6));
}

/// A COLLADA file in centimetres with a node transform and a given up axis.
std::string Collada(const std::string& up_axis) {
  return R"(<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="centimeter" meter="0.01"/><up_axis>)" +
         up_axis + R"(</up_axis></asset>
  <library_geometries>
    <geometry id="tri-mesh" name="tri">
      <mesh>
        <source id="tri-pos">
          <float_array id="tri-pos-array" count="9">0 0 0 10 0 0 0 0 10</float_array>
          <technique_common><accessor source="#tri-pos-array" count="3" stride="3">
            <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
          </accessor></technique_common>
        </source>
        <vertices id="tri-vtx"><input semantic="POSITION" source="#tri-pos"/></vertices>
        <triangles count="1"><input semantic="VERTEX" source="#tri-vtx" offset="0"/><p>0 1 2</p></triangles>
      </mesh>
    </geometry>
  </library_geometries>
  <library_visual_scenes>
    <visual_scene id="Scene" name="Scene">
      <node id="n1" name="fruit_node">
        <translate>100 0 0</translate>
        <instance_geometry url="#tri-mesh"/>
      </node>
    </visual_scene>
  </library_visual_scenes>
  <scene><instance_visual_scene url="#Scene"/></scene>
</COLLADA>
)";
}

TEST_F(SceneFileTest, ColladaUnitsUpAxisAndNodeTransformsAreApplied) {
  const std::string yaml = R"(version: 1
meshes:
  - file: tri.dae
    classes: [{match: "fruit_node", class: fruit}]
)";
  // Z_UP in centimetres: the vertex (0, 0, 10) cm under a node at x = 100 cm is (1, 0, 0.1) m.
  Write("tri.dae", Collada("Z_UP"));
  Result<Scene> r = Load(yaml);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->objects.size(), 1u);
  EXPECT_EQ(r->objects[0].semantic_class, SemanticClass::kFruit);
  EXPECT_EQ(r->objects[0].name, "tri/fruit_node/tri");
  const TriangleMesh& m = std::get<TriangleMesh>(r->objects[0].shape);
  EXPECT_TRUE(m.vertices[2].isApprox(Eigen::Vector3f(1.0f, 0.0f, 0.1f), 1e-6f))
      << m.vertices[2].transpose();
  EXPECT_TRUE(m.vertices[1].isApprox(Eigen::Vector3f(1.1f, 0.0f, 0.0f), 1e-6f));

  // The same data declared Y_UP: file +y is up, so (0, 0, 10) cm points to world -y.
  Write("tri.dae", Collada("Y_UP"));
  r = Load(yaml);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const TriangleMesh& y = std::get<TriangleMesh>(r->objects[0].shape);
  EXPECT_TRUE(y.vertices[2].isApprox(Eigen::Vector3f(1.0f, -0.1f, 0.0f), 1e-6f))
      << y.vertices[2].transpose();

  // An explicit up_axis describes the raw coordinates and overrides the declaration.
  r = Load(R"(version: 1
meshes: [{file: tri.dae, up_axis: z}]
)");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE(std::get<TriangleMesh>(r->objects[0].shape)
                  .vertices[2]
                  .isApprox(Eigen::Vector3f(1.0f, 0.0f, 0.1f), 1e-6f));
}

TEST_F(SceneFileTest, GltfWithEmbeddedBufferIsLoadedYUp) {
  // One triangle (0,0,0) (1,0,0) (0,1,0) in a child node translated by (0, 2, 0) under a parent
  // scaled by 0.5; glTF is Y-up, so file (x, y, z) lands at world (x, -z, y).
  // Buffer: 9 float32 positions + 3 uint16 indices + 2 padding bytes, base64.
  const std::string buffer = "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIAAAA=";
  Write("leaf.gltf", R"({"asset": {"version": "2.0"}, "scene": 0,
  "scenes": [{"nodes": [0]}],
  "nodes": [{"name": "parent", "scale": [0.5, 0.5, 0.5], "children": [1]},
            {"name": "leaf_node", "mesh": 0, "translation": [0, 2, 0]}],
  "meshes": [{"name": "leaf_mesh", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
  "buffers": [{"byteLength": 44, "uri": "data:application/octet-stream;base64,)" +
                         buffer + R"("}],
  "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                  {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
  "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                 "min": [0, 0, 0], "max": [1, 1, 0]},
                {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}]})");
  const Result<Scene> r = Load(R"(version: 1
meshes:
  - file: leaf.gltf
    classes: [{match: "leaf_mesh", class: leaf}]
)");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->objects.size(), 1u);
  EXPECT_EQ(r->objects[0].semantic_class, SemanticClass::kLeaf);
  EXPECT_EQ(r->objects[0].name, "leaf/leaf_node/leaf_mesh");
  const TriangleMesh& m = std::get<TriangleMesh>(r->objects[0].shape);
  ASSERT_EQ(m.vertices.size(), 3u);
  // (0, 0, 0) -> 0.5 * (0, 2, 0) = (0, 1, 0) in glTF -> (0, 0, 1) in W.
  EXPECT_TRUE(m.vertices[0].isApprox(Eigen::Vector3f(0.0f, 0.0f, 1.0f), 1e-6f));
  // (1, 0, 0) -> (0.5, 1, 0) -> (0.5, 0, 1); (0, 1, 0) -> (0, 1.5, 0) -> (0, 0, 1.5).
  EXPECT_TRUE(m.vertices[1].isApprox(Eigen::Vector3f(0.5f, 0.0f, 1.0f), 1e-6f));
  EXPECT_TRUE(m.vertices[2].isApprox(Eigen::Vector3f(0.0f, 0.0f, 1.5f), 1e-6f));
}

TEST_F(SceneFileTest, ErrorsNameTheBadValue) {
  const auto error = [&](const std::string& yaml) {
    const Result<Scene> r = Load(yaml);
    EXPECT_FALSE(r.ok()) << yaml;
    return r.status();
  };
  Status s = error("version: 1\nmeshes: [{file: plant.obj, colour: [1, 0, 0]}]\n");
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("scene.yaml: meshes[0]"));
  EXPECT_THAT(s.message(), HasSubstr("'colour'"));

  s = error("version: 1\nmeshes: [{file: plant.obj}]\nseed: 3\n");
  EXPECT_THAT(s.message(), HasSubstr("unknown key 'seed'"));

  s = error("version: 1\nmeshes: [{file: plant.obj, classes: [{match: 'f*', class: fruti}]}]\n");
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("meshes[0].classes[0].class: unknown semantic class 'fruti'"));
  EXPECT_THAT(s.message(), HasSubstr("fruit, leaf, stem"));

  s = error("version: 1\nmeshes: [{file: plant.obj, default_class: tree}]\n");
  EXPECT_THAT(s.message(), HasSubstr("'tree'"));

  s = error("version: 1\nmeshes: [{file: missing/plant2.obj}]\n");
  EXPECT_EQ(s.code(), StatusCode::kNotFound);
  EXPECT_THAT(s.message(), HasSubstr((dir_ / "missing/plant2.obj").string()));

  Write("broken.ply", "this is not a ply file\n");
  s = error("version: 1\nmeshes: [{file: broken.ply}]\n");
  EXPECT_EQ(s.code(), StatusCode::kParseError);
  EXPECT_THAT(s.message(), HasSubstr("broken.ply"));
  EXPECT_THAT(s.message(), HasSubstr("magic number"));  // assimp's own words

  Write("notes.xyz123", "hello\n");
  s = error("version: 1\nmeshes: [{file: notes.xyz123}]\n");
  EXPECT_EQ(s.code(), StatusCode::kParseError);
  EXPECT_THAT(s.message(), HasSubstr("notes.xyz123"));

  s = error("version: 1\nmeshes: [{file: plant.obj\n");
  EXPECT_EQ(s.code(), StatusCode::kParseError);
  EXPECT_THAT(s.message(), HasSubstr("line "));
  EXPECT_THAT(s.message(), HasSubstr("column "));

  s = error("version: 2\nmeshes: [{file: plant.obj}]\n");
  EXPECT_THAT(s.message(), HasSubstr("unsupported scene file version 2 (supported: 1)"));
  s = error("meshes: [{file: plant.obj}]\n");
  EXPECT_THAT(s.message(), HasSubstr("'version' is missing"));

  s = error("version: 1\nmeshes: [{file: plant.obj, fruit_instances: spheres}]\n");
  EXPECT_THAT(s.message(), HasSubstr("'objects' or 'components', got 'spheres'"));
  s = error("version: 1\nmeshes: [{file: plant.obj, up_axis: x}]\n");
  EXPECT_THAT(s.message(), HasSubstr("'y' or 'z', got 'x'"));
  s = error("version: 1\nmeshes: [{file: plant.obj, color: [2, 0, 0]}]\n");
  EXPECT_THAT(s.message(), HasSubstr("[2, 0, 0]"));
  s = error("version: 1\nmeshes: [{file: plant.obj, scale: -1}]\n");
  EXPECT_THAT(s.message(), HasSubstr("scale: [-1, -1, -1] must be > 0"));
  s = error("version: 1\nmeshes: [{file: plant.obj, pose: {xyz: [1, 2]}}]\n");
  EXPECT_THAT(s.message(), HasSubstr("must have 3 numbers, got 2"));
  s = error("version: 1\nmeshes: []\n");
  EXPECT_THAT(s.message(), HasSubstr("'meshes' must be a non-empty list"));
  s = error("version: 1\nstart_joints_deg: [0, -40, 90, 0, 40, 0]\nmeshes: [{file: plant.obj}]\n");
  EXPECT_THAT(s.message(), HasSubstr("'start_camera' (eye, target) is required"));
  EXPECT_THAT(s.message(), HasSubstr("[0, -40, 90, 0, 40, 0]"));
  s = error(
      "version: 1\nstart_camera: {eye: [0, 0, 1], target: [0, 0, 2]}\nmeshes: [{file: "
      "plant.obj}]\n");
  EXPECT_THAT(s.message(), HasSubstr("parallel to up"));
  s = error("version: 1\nground: {height: 0}\nmeshes: [{file: plant.obj}]\n");
  EXPECT_THAT(s.message(), HasSubstr("'height'"));

  const Result<Scene> missing = LoadSceneFile(dir_ / "nope.yaml");
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(missing.status().message(), HasSubstr("nope.yaml"));
}

TEST_F(SceneFileTest, SavedScenariosLoadBackWithTheSameFruit) {
  const Scene original = MakeScenario("tomato-single-cluster", 3).value();
  ASSERT_TRUE(SaveSceneFiles(original, dir_ / "saved").ok());
  EXPECT_TRUE(fs::exists(dir_ / "saved" / "tomato-single-cluster.obj"));
  EXPECT_TRUE(fs::exists(dir_ / "saved" / "tomato-single-cluster.mtl"));
  const Result<Scene> loaded = LoadSceneFile(dir_ / "saved" / "tomato-single-cluster.yaml");
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  EXPECT_EQ(loaded->name, original.name);
  EXPECT_EQ(loaded->description, original.description);
  EXPECT_EQ(CountClasses(*loaded), CountClasses(original));
  ASSERT_EQ(loaded->objects.size(), original.objects.size());
  for (size_t i = 0; i < original.objects.size(); ++i) {
    EXPECT_LT((loaded->objects[i].albedo - original.objects[i].albedo).norm(), 1e-5f);
    EXPECT_NE(loaded->objects[i].name.find(original.objects[i].name), std::string::npos);
  }
  const std::vector<FruitTruth> a = original.Fruits();
  const std::vector<FruitTruth> b = loaded->Fruits();
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_LT((a[i].center_W - b[i].center_W).norm(), 0.001) << a[i].name;
    EXPECT_NEAR(a[i].mean_radius_m(), b[i].mean_radius_m(), 0.002);
  }
  ASSERT_EQ(loaded->start_joints_rad.size(), 6u);
  for (size_t i = 0; i < 6; ++i) {
    EXPECT_NEAR(loaded->start_joints_rad[i], original.start_joints_rad[i], 1e-9);
  }
  EXPECT_TRUE(loaded->X_WC_start.IsNearlyEqualTo(original.X_WC_start, 1e-9, 1e-9));
  EXPECT_LT((loaded->plant_bounds.min() - original.plant_bounds.min()).norm(), 0.002);
  EXPECT_LT((loaded->plant_bounds.max() - original.plant_bounds.max()).norm(), 0.002);
}

TEST_F(SceneFileTest, SaveReportsUnwritableDirectories) {
  Write("a_file", "x");
  const Status s =
      SaveSceneFiles(MakeScenario("tomato-single-cluster", 0).value(), dir_ / "a_file" / "sub");
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_THAT(s.message(), HasSubstr("a_file"));
}

TEST(SceneFileExampleTest, ShippedExampleLoads) {
  const fs::path example = fs::path(AVP_CONFIG_DIR) / "scenes" / "example_plant.yaml";
  const Result<Scene> r = LoadSceneFile(example);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->name, "example_plant");
  std::map<SemanticClass, int> n;
  for (const SceneObject& o : r->objects) ++n[o.semantic_class];
  EXPECT_EQ(n[SemanticClass::kFruit], 4);
  EXPECT_EQ(n[SemanticClass::kLeaf], 3);
  EXPECT_EQ(n[SemanticClass::kStem], 5);
  EXPECT_EQ(n[SemanticClass::kSupport], 1);
  EXPECT_EQ(n[SemanticClass::kGround], 1);
  EXPECT_EQ(n[SemanticClass::kOther], 0);
  for (const FruitTruth& f : r->Fruits()) {
    EXPECT_GT(f.center_W.x(), 0.4);
    EXPECT_LT(f.center_W.x(), 0.7);
    EXPECT_NEAR(f.center_W.z(), 0.7, 0.1);
  }
  EXPECT_LT(fs::file_size(example.parent_path() / "example_plant.obj"), 200u * 1024u);
}

TEST(GlobMatchTest, StarsAndQuestionMarks) {
  EXPECT_TRUE(GlobMatch("fruit*", "fruit_1"));
  EXPECT_TRUE(GlobMatch("fruit*", "fruit"));
  EXPECT_TRUE(GlobMatch("*", ""));
  EXPECT_TRUE(GlobMatch("*leaf*", "tomato/leaf_03"));
  EXPECT_TRUE(GlobMatch("f?uit_*_?", "fruit_12_3"));
  EXPECT_TRUE(GlobMatch("a*b*c", "aXXbYYbZc"));
  EXPECT_FALSE(GlobMatch("fruit*", "Fruit_1"));  // case-sensitive
  EXPECT_FALSE(GlobMatch("fruit", "fruit_1"));
  EXPECT_FALSE(GlobMatch("?", ""));
  EXPECT_FALSE(GlobMatch("a*b*c", "aXXbYYbZ"));
  EXPECT_FALSE(GlobMatch("", "x"));
}

}  // namespace
}  // namespace avp::sim
