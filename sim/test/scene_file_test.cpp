#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/sim/mesh_builder.h>
#include <avp/sim/rgbd_renderer.h>
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

  static const ScenePartReport& Named(const std::vector<ScenePartReport>& parts,
                                      const std::string& name) {
    for (const ScenePartReport& p : parts) {
      if (p.name == name) return p;
    }
    ADD_FAILURE() << "no part " << name;
    return parts.front();
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

// --- Placeholder materials, fruit fragments and merge rules (issue 16) ---

/// A generated plant in plant coordinates: a stem, two leaves, four fruits (icospheres of 25 mm
/// radius, 42 vertices each) at z = 0.6 m, y = -0.12 .. 0.12 m, each with two calyx fragments
/// (8 mm x 8 mm x 4 mm boxes, 8 vertices, 0.256 cm3) on its top.
struct PlantPart {
  std::string name;
  TriangleMesh mesh;
};

constexpr int kFruits = 4;

Eigen::Vector3d FruitCenter(int k) { return {0.0, -0.12 + 0.08 * k, 0.6}; }

std::vector<PlantPart> FragmentedPlant();

/// Bounding box of fruit k (plant coordinates): its sphere alone, or with its calyx fragments.
Box3 FruitBox(int k, bool with_calyx) {
  Box3 box;
  const std::string name = "Fruit" + std::to_string(k + 1);
  for (const PlantPart& part : FragmentedPlant()) {
    if (part.name == name || (with_calyx && part.name.rfind(name + "_", 0) == 0)) {
      box.Extend(part.mesh.Bounds());
    }
  }
  return box;
}

std::vector<PlantPart> FragmentedPlant() {
  std::vector<PlantPart> parts;
  parts.push_back({"Stem", MakeBox(Box3({0.04, -0.005, 0.0}, {0.05, 0.005, 0.8}))});
  for (int k = 0; k < 2; ++k) {
    TriangleMesh leaf = MakeQuad(0.04, 0.02);
    leaf.Transform(RigidTransform(Eigen::Vector3d(0.02, k == 0 ? -0.1 : 0.1, 0.3)));
    parts.push_back({"Leaf" + std::to_string(k + 1), leaf});
  }
  for (int k = 0; k < kFruits; ++k) {
    const std::string name = "Fruit" + std::to_string(k + 1);
    parts.push_back({name, Sphere(FruitCenter(k), 0.025)});
    for (const double dx : {-0.006, 0.006}) {
      const Eigen::Vector3d c = FruitCenter(k) + Eigen::Vector3d(dx, 0.0, 0.026);
      parts.push_back({name + (dx < 0 ? "_calyx_a" : "_calyx_b"),
                       MakeBox(Box3(c - Eigen::Vector3d(0.004, 0.004, 0.002),
                                    c + Eigen::Vector3d(0.004, 0.004, 0.002)))});
    }
  }
  return parts;
}

/// The parts as COLLADA (Z_UP, metres): one node and one geometry per part, every geometry bound
/// to one material named `material` with diffuse colour `rgb`.
std::string ColladaOf(const std::vector<PlantPart>& parts, const std::string& material,
                      const Eigen::Vector3f& rgb) {
  std::string geometries, nodes;
  for (size_t i = 0; i < parts.size(); ++i) {
    const TriangleMesh& m = parts[i].mesh;
    std::string positions, indices;
    for (const Eigen::Vector3f& v : m.vertices) {
      positions += fmt::format("{} {} {} ", v.x(), v.y(), v.z());
    }
    for (const Eigen::Vector3i& t : m.triangles) {
      indices += fmt::format("{} {} {} ", t[0], t[1], t[2]);
    }
    geometries += fmt::format(
        R"(<geometry id="g{0}" name="{1}"><mesh><source id="g{0}-pos">)"
        R"(<float_array id="g{0}-arr" count="{2}">{3}</float_array><technique_common>)"
        R"(<accessor source="#g{0}-arr" count="{4}" stride="3"><param name="X" type="float"/>)"
        R"(<param name="Y" type="float"/><param name="Z" type="float"/></accessor>)"
        R"(</technique_common></source><vertices id="g{0}-vtx"><input semantic="POSITION" )"
        R"(source="#g{0}-pos"/></vertices><triangles count="{5}" material="mat">)"
        R"(<input semantic="VERTEX" source="#g{0}-vtx" offset="0"/><p>{6}</p></triangles>)"
        "</mesh></geometry>\n",
        i, parts[i].name, 3 * m.vertices.size(), positions, m.vertices.size(), m.triangles.size(),
        indices);
    nodes +=
        fmt::format(R"(<node id="n{0}" name="{1}"><instance_geometry url="#g{0}"><bind_material>)"
                    R"(<technique_common><instance_material symbol="mat" target="#placeholder"/>)"
                    "</technique_common></bind_material></instance_geometry></node>\n",
                    i, parts[i].name);
  }
  return fmt::format(
      R"(<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
<asset><unit name="meter" meter="1"/><up_axis>Z_UP</up_axis></asset>
<library_effects><effect id="placeholder-fx"><profile_COMMON><technique sid="common"><lambert>
<diffuse><color>{} {} {} 1</color></diffuse></lambert></technique></profile_COMMON></effect>
</library_effects>
<library_materials><material id="placeholder" name="{}"><instance_effect url="#placeholder-fx"/>
</material></library_materials>
<library_geometries>
{}</library_geometries>
<library_visual_scenes><visual_scene id="Scene" name="Scene">
{}</visual_scene></library_visual_scenes>
<scene><instance_visual_scene url="#Scene"/></scene>
</COLLADA>
)",
      rgb.x(), rgb.y(), rgb.z(), material, geometries, nodes);
}

/// The parts as OBJ + MTL with every fruit part (spheres, calyx fragments and one stray fragment
/// 0.1 m above the fruits) in one object "Fruits", everything with the grey material "Grey".
void WriteFragmentedObj(const fs::path& dir) {
  size_t base = 1;
  std::string obj = "mtllib plant.mtl\n";
  TriangleMesh fruits;
  for (const PlantPart& part : FragmentedPlant()) {
    if (part.name.rfind("Fruit", 0) == 0) {
      fruits.Append(part.mesh);
    } else {
      obj += ObjObject(part.name, "Grey", part.mesh, base);
    }
  }
  fruits.Append(MakeBox(Box3({-0.003, -0.003, 0.75}, {0.003, 0.003, 0.756})));  // stray
  obj += ObjObject("Fruits", "Grey", fruits, base);
  std::ofstream(dir / "plant.obj") << obj;
  std::ofstream(dir / "plant.mtl") << "newmtl Grey\nKd 0.6 0.6 0.6\n";
}

const char* kColladaPlantYaml = R"(version: 1
meshes:
  - file: plant.dae
    pose: {xyz: [0.7, 0, 0]}
    classes:
      - {match: "Fruit*", class: fruit}
      - {match: "Leaf*", class: leaf}
      - {match: "Stem", class: stem}
      - {match: "Flower*", class: other}
)";

bool AnyWarningHas(const std::vector<std::string>& warnings,
                   const std::vector<std::string>& parts) {
  for (const std::string& w : warnings) {
    bool all = true;
    for (const std::string& p : parts) all = all && w.find(p) != std::string::npos;
    if (all) return true;
  }
  return false;
}

/// Fruit-class pixels of the start view whose colour is red (r > 2 g and r > 2 b), and all
/// fruit-class pixels.
std::pair<size_t, size_t> RedFruitPixels(const Scene& scene) {
  const RgbdRenderer renderer(scene);
  const RenderedFrame f =
      renderer.Render(CameraIntrinsics::RealSenseD435().Scaled(0.5), scene.X_WC_start);
  size_t red = 0, fruit = 0;
  for (int v = 0; v < f.class_ids.height(); ++v) {
    for (int u = 0; u < f.class_ids.width(); ++u) {
      if (f.class_ids(u, v) != static_cast<uint8_t>(SemanticClass::kFruit)) continue;
      ++fruit;
      const int r = f.rgbd.rgb(u, v, 0), g = f.rgbd.rgb(u, v, 1), b = f.rgbd.rgb(u, v, 2);
      if (r > 2 * g && r > 2 * b) ++red;
    }
  }
  return {red, fruit};
}

TEST_F(SceneFileTest, PlaceholderMaterialGivesWayToClassColoursWithAWarning) {
  Write("plant.dae", ColladaOf(FragmentedPlant(), "Placeholder", {0.6f, 0.6f, 0.6f}));
  SceneFileReport report;
  const Result<Scene> r = LoadSceneFile(Write("scene.yaml", kColladaPlantYaml), &report);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->objects.size(), 3u + 3u * kFruits);
  for (const SceneObject& o : r->objects) {
    EXPECT_EQ(o.albedo, DefaultClassColor(o.semantic_class)) << o.name;
  }
  ASSERT_EQ(report.parts.size(), r->objects.size());
  for (const ScenePartReport& p : report.parts) {
    EXPECT_EQ(p.color_source, ColorSource::kPlaceholder) << p.name;
    EXPECT_EQ(p.material, "Placeholder");
    EXPECT_TRUE(p.material_color.isApprox(Eigen::Vector3f(0.6f, 0.6f, 0.6f), 1e-6f));
  }
  EXPECT_EQ(r->warnings, report.warnings);
  // One warning naming the material, its colour, and each class with its parts count.
  EXPECT_TRUE(AnyWarningHas(
      report.warnings,
      {"material 'Placeholder' colour [0.6, 0.6, 0.6] looks like a placeholder",
       "replaced by the class default in fruit (12 parts, now [0.55, 0.05, 0.03]), leaf (2 parts, "
       "now [0.08, 0.25, 0.05]), stem (1 part, now [0.16, 0.3, 0.07])"}))
      << testing::PrintToString(report.warnings);
  // The rule that matches nothing, and the fragments far smaller than the fruits.
  EXPECT_TRUE(AnyWarningHas(report.warnings, {"classes[3]", "'Flower*'", "classifies no part"}));
  EXPECT_TRUE(
      AnyWarningHas(report.warnings, {"8 of its 12 fruit instances", "fruit_min_volume_cm3"}));
  ASSERT_EQ(report.rules.size(), 4u);
  EXPECT_EQ(report.rules[0].parts, 12u);
  EXPECT_EQ(report.rules[1].parts, 2u);
  EXPECT_EQ(report.rules[2].parts, 1u);
  EXPECT_EQ(report.rules[3].parts, 0u);
  // Rendered, the fruit is red where the placeholder grey left none.
  const auto [red, fruit] = RedFruitPixels(*r);
  EXPECT_GT(fruit, 200u);
  EXPECT_GE(red * 100, fruit * 95);

  // materials: use keeps the grey: the whole plant is one colour, and nothing red is rendered.
  std::string use = kColladaPlantYaml;
  use.insert(use.find("    classes:"), "    materials: use\n");
  SceneFileReport use_report;
  const Result<Scene> u = LoadSceneFile(Write("use.yaml", use), &use_report);
  ASSERT_TRUE(u.ok()) << u.status().ToString();
  for (const SceneObject& o : u->objects) {
    EXPECT_TRUE(o.albedo.isApprox(Eigen::Vector3f(0.6f, 0.6f, 0.6f), 1e-6f)) << o.name;
  }
  EXPECT_EQ(use_report.parts.front().color_source, ColorSource::kMaterial);
  EXPECT_FALSE(AnyWarningHas(use_report.warnings, {"placeholder"}));
  EXPECT_TRUE(AnyWarningHas(use_report.warnings,
                            {"the whole plant (15 parts, classes", "one colour [0.6, 0.6, 0.6]"}))
      << testing::PrintToString(use_report.warnings);
  const auto [use_red, use_fruit] = RedFruitPixels(*u);
  EXPECT_EQ(use_fruit, fruit);
  EXPECT_EQ(use_red, 0u);

  // materials: ignore: class defaults, no placeholder to report.
  std::string ignore = kColladaPlantYaml;
  ignore.insert(ignore.find("    classes:"), "    materials: ignore\n");
  SceneFileReport ignore_report;
  const Result<Scene> i = LoadSceneFile(Write("ignore.yaml", ignore), &ignore_report);
  ASSERT_TRUE(i.ok()) << i.status().ToString();
  EXPECT_EQ(i->objects.front().albedo, DefaultClassColor(i->objects.front().semantic_class));
  EXPECT_EQ(ignore_report.parts.front().color_source, ColorSource::kClassDefault);
  EXPECT_FALSE(AnyWarningHas(ignore_report.warnings, {"placeholder"}));

  // A chromatic material is a real colour: kept under auto.
  Write("plant.dae", ColladaOf(FragmentedPlant(), "Red", {0.7f, 0.1f, 0.05f}));
  SceneFileReport red_report;
  const Result<Scene> c = LoadSceneFile(Write("scene.yaml", kColladaPlantYaml), &red_report);
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_TRUE(c->objects.front().albedo.isApprox(Eigen::Vector3f(0.7f, 0.1f, 0.05f), 1e-6f));
  EXPECT_EQ(red_report.parts.front().color_source, ColorSource::kMaterial);
  // ... but then every class is that one colour.
  EXPECT_TRUE(AnyWarningHas(red_report.warnings, {"the whole plant", "one colour"}));
}

TEST_F(SceneFileTest, ClassesSharingAColourAreReported) {
  Write("plant.dae", ColladaOf(FragmentedPlant(), "Placeholder", {0.6f, 0.6f, 0.6f}));
  // Fruit and leaf given one colour by their rules; the stem keeps its class colour.
  const Result<Scene> r = Load(R"(version: 1
meshes:
  - file: plant.dae
    classes:
      - {match: "Fruit*", class: fruit, color: [0.1, 0.5, 0.1]}
      - {match: "Leaf*", class: leaf, color: [0.1, 0.5, 0.1]}
      - {match: "Stem", class: stem}
)");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE(
      AnyWarningHas(r->warnings, {"every fruit part (12) is [0.1, 0.5, 0.1]",
                                  "a colour leaf parts have too", "cannot tell fruit from leaf"}))
      << testing::PrintToString(r->warnings);
  EXPECT_FALSE(AnyWarningHas(r->warnings, {"the whole plant"}));
  EXPECT_FALSE(AnyWarningHas(r->warnings, {"no part is of class fruit"}));
  // No fruit rule at all: no fruit part.
  const Result<Scene> none = Load(R"(version: 1
meshes: [{file: plant.dae, default_class: leaf}]
)");
  ASSERT_TRUE(none.ok()) << none.status().ToString();
  EXPECT_TRUE(AnyWarningHas(none->warnings, {"no part is of class fruit"}));
}

TEST_F(SceneFileTest, MergeRulesJoinCalyxPartsToTheirFruitByName) {
  Write("plant.dae", ColladaOf(FragmentedPlant(), "Placeholder", {0.6f, 0.6f, 0.6f}));
  std::string yaml = kColladaPlantYaml;
  yaml += R"(    merge:
      - {match: "Fruit*_calyx_*", into: "Fruit*"}
      - {match: "Bud*", into: "Fruit*"}
)";
  SceneFileReport report;
  const Result<Scene> r = LoadSceneFile(Write("scene.yaml", yaml), &report);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const std::vector<FruitTruth> fruits = r->Fruits();
  ASSERT_EQ(fruits.size(), static_cast<size_t>(kFruits));
  for (int k = 0; k < kFruits; ++k) {
    const std::string name = "plant/Fruit" + std::to_string(k + 1);
    EXPECT_EQ(fruits[k].name, name);
    const SceneObject& o = Named(*r, name);
    EXPECT_EQ(o.num_triangles(), 80u + 2u * 12u);  // the sphere and both calyx boxes
    // The truth is the box of the sphere and its calyx (which reaches 28 mm above the centre).
    const Box3 box = FruitBox(k, true);
    EXPECT_LT((fruits[k].center_W - (box.center() + Eigen::Vector3d(0.7, 0, 0))).norm(), 1e-5);
    EXPECT_LT((fruits[k].radii - 0.5 * box.size()).norm(), 1e-5);
    EXPECT_NEAR(box.max().z(), 0.628, 1e-6);
    ASSERT_EQ(report.fruits[k].merged.size(), 2u);
    EXPECT_EQ(report.fruits[k].merged[0], name + "_calyx_a");
    EXPECT_EQ(report.fruits[k].merged[1], name + "_calyx_b");
  }
  ASSERT_EQ(report.fragments.size(), 2u * kFruits);
  EXPECT_EQ(report.fragments[0].into, "plant/Fruit1");
  EXPECT_THAT(report.fragments[0].reason, HasSubstr("merge[0]"));
  EXPECT_THAT(Named(report.parts, "plant/Fruit2_calyx_b").fate.front(),
              HasSubstr("merged into plant/Fruit2 (merge[0])"));
  EXPECT_TRUE(AnyWarningHas(report.warnings, {"merge[1]", "'Bud*'", "matches no part"}));
  // The merged fragments are no longer tiny fruits.
  EXPECT_FALSE(AnyWarningHas(report.warnings, {"fruit_min_volume_cm3"}));

  // A target that does not exist leaves the parts alone, with a warning.
  std::string missing = kColladaPlantYaml;
  missing += "    merge: [{match: \"Fruit*_calyx_*\", into: \"Berry*\"}]\n";
  const Result<Scene> m = Load(missing);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->Fruits().size(), 3u * kFruits);
  EXPECT_TRUE(AnyWarningHas(m->warnings, {"merge[0]", "8 of the 8 parts", "'Berry*'"}))
      << testing::PrintToString(m->warnings);
}

TEST_F(SceneFileTest, SmallFruitComponentsJoinTheirNearestFruitOrAreDropped) {
  WriteFragmentedObj(dir_);
  const std::string base = R"(version: 1
meshes:
  - file: plant.obj
    fruit_instances: components
    classes: [{match: "Fruits", class: fruit}, {match: "Leaf*", class: leaf},
              {match: "Stem", class: stem}]
)";
  // Without a size rule: four fruits, eight calyx fragments and the stray one are 13 "fruits".
  const Result<Scene> plain = Load(base);
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  EXPECT_EQ(plain->Fruits().size(), 13u);
  EXPECT_TRUE(AnyWarningHas(plain->warnings, {"9 of its 13 fruit instances", "under 2%"}))
      << testing::PrintToString(plain->warnings);

  // Bounding box under 1 cm3: the calyx boxes (0.256 cm3, touching their fruit) merge, the stray
  // box 0.12 m above every fruit is out of the default 10 mm reach and dropped.
  SceneFileReport report;
  const Result<Scene> merged =
      LoadSceneFile(Write("merge.yaml", base + "    fruit_min_volume_cm3: 1.0\n"), &report);
  ASSERT_TRUE(merged.ok()) << merged.status().ToString();
  const std::vector<FruitTruth> fruits = merged->Fruits();
  ASSERT_EQ(fruits.size(), static_cast<size_t>(kFruits));
  for (int k = 0; k < kFruits; ++k) {
    EXPECT_LT((fruits[k].center_W - FruitBox(k, true).center()).norm(), 1e-5) << fruits[k].name;
    EXPECT_EQ(
        std::get<TriangleMesh>(merged->FindInstance(fruits[k].instance_id)->shape).num_triangles(),
        80u + 2u * 12u);
    EXPECT_EQ(report.fruits[k].merged.size(), 2u);
  }
  size_t joined = 0, dropped = 0;
  for (const SceneFragmentReport& f : report.fragments) {
    (f.into.empty() ? dropped : joined)++;
    if (!f.into.empty()) {
      EXPECT_LT(f.gap_mm, 5.0) << f.name;
    }
    EXPECT_NEAR(f.volume_cm3, f.into.empty() ? 0.216 : 0.256, 1e-3) << f.name;
  }
  EXPECT_EQ(joined, 8u);
  EXPECT_EQ(dropped, 1u);
  EXPECT_TRUE(
      AnyWarningHas(report.warnings, {"9 fruit fragments", "8 joined their nearest fruit",
                                      "1 dropped", "no fruit within 10 mm", "4 fruits remain"}))
      << testing::PrintToString(report.warnings);
  // The placeholder grey was replaced for the fruit as well.
  EXPECT_EQ(merged->FindInstance(fruits[0].instance_id)->albedo,
            DefaultClassColor(SemanticClass::kFruit));

  // A reach of 200 mm takes the stray fragment in too; a vertex minimum does the same as the
  // volume (boxes have 8 vertices, spheres 42).
  const Result<Scene> reach = Load(base +
                                   "    fruit_min_vertices: 20\n"
                                   "    fruit_merge_reach_mm: 200\n");
  ASSERT_TRUE(reach.ok()) << reach.status().ToString();
  ASSERT_EQ(reach->Fruits().size(), static_cast<size_t>(kFruits));
  size_t triangles = 0;
  for (const FruitTruth& f : reach->Fruits()) {
    triangles += reach->FindInstance(f.instance_id)->num_triangles();
  }
  EXPECT_EQ(triangles, kFruits * (80u + 2u * 12u) + 12u);

  // Drop mode: the fragments are gone, the fruits are bare spheres.
  SceneFileReport drop_report;
  const Result<Scene> drop = LoadSceneFile(
      Write("drop.yaml", base + "    fruit_min_volume_cm3: 1.0\n    fruit_small_parts: drop\n"),
      &drop_report);
  ASSERT_TRUE(drop.ok()) << drop.status().ToString();
  ASSERT_EQ(drop->Fruits().size(), static_cast<size_t>(kFruits));
  const std::vector<FruitTruth> bare = drop->Fruits();
  for (int k = 0; k < kFruits; ++k) {
    const FruitTruth& f = bare[static_cast<size_t>(k)];
    EXPECT_EQ(drop->FindInstance(f.instance_id)->num_triangles(), 80u);
    EXPECT_LT((f.center_W - FruitBox(k, false).center()).norm(), 1e-5);
    EXPECT_LT((f.radii - 0.5 * FruitBox(k, false).size()).norm(), 1e-5);
  }
  EXPECT_EQ(drop_report.fragments.size(), 9u);
  EXPECT_TRUE(AnyWarningHas(drop_report.warnings, {"0 joined", "9 dropped"}));
  EXPECT_EQ(Named(drop_report.parts, "plant/Fruits").fate.size(), 13u);
}

TEST_F(SceneFileTest, AMergedPartJoinsTheNearestComponentOfItsTarget) {
  // "Berries": two spheres in one object (components); "Berries_calyx" sits on the second one.
  size_t base = 1;
  TriangleMesh berries = Sphere({0.0, 0.0, 0.5}, 0.02);
  berries.Append(Sphere({0.0, 0.1, 0.5}, 0.02));
  std::string obj = ObjObject("Berries", "", berries, base);
  obj += ObjObject("Berries_calyx", "", MakeBox(Box3({-0.003, 0.097, 0.52}, {0.003, 0.103, 0.524})),
                   base);
  Write("berries.obj", obj);
  SceneFileReport report;
  const Result<Scene> r = LoadSceneFile(Write("berries.yaml", R"(version: 1
meshes:
  - file: berries.obj
    fruit_instances: components
    classes: [{match: "Berries*", class: fruit}]
    merge: [{match: "*_calyx", into: "*"}]
)"),
                                        &report);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const std::vector<FruitTruth> fruits = r->Fruits();
  ASSERT_EQ(fruits.size(), 2u);
  EXPECT_EQ(fruits[0].name, "berries/Berries#0");
  EXPECT_EQ(r->FindInstance(fruits[0].instance_id)->num_triangles(), 80u);
  EXPECT_EQ(r->FindInstance(fruits[1].instance_id)->num_triangles(), 80u + 12u);
  EXPECT_NEAR(fruits[1].center_W.y(), 0.1, 1e-6);
  ASSERT_EQ(report.fragments.size(), 1u);
  EXPECT_EQ(report.fragments[0].into, "berries/Berries#1");
  EXPECT_EQ(report.fruits[1].merged, std::vector<std::string>({"berries/Berries_calyx"}));
  // No material: the class default, and no placeholder warning.
  EXPECT_EQ(report.parts[0].color_source, ColorSource::kClassDefault);
  EXPECT_FALSE(AnyWarningHas(report.warnings, {"placeholder"}));
}

TEST_F(SceneFileTest, FragmentAndMaterialKeysRejectBadValues) {
  WriteFragmentedObj(dir_);
  const auto error = [&](const std::string& entry_keys) {
    const Result<Scene> r = Load("version: 1\nmeshes:\n  - file: plant.obj\n" + entry_keys);
    EXPECT_FALSE(r.ok()) << entry_keys;
    return r.status().message();
  };
  EXPECT_THAT(error("    materials: maybe\n"),
              HasSubstr("meshes[0].materials: must be 'auto', 'use' or 'ignore', got 'maybe'"));
  EXPECT_THAT(error("    fruit_small_parts: melt\n"),
              HasSubstr("meshes[0].fruit_small_parts: must be 'merge' or 'drop', got 'melt'"));
  EXPECT_THAT(error("    fruit_min_volume_cm3: -1\n"),
              HasSubstr("meshes[0].fruit_min_volume_cm3: must be >= 0, got -1"));
  EXPECT_THAT(error("    fruit_min_vertices: -3\n"),
              HasSubstr("meshes[0].fruit_min_vertices: must be >= 0, got -3"));
  EXPECT_THAT(error("    fruit_merge_reach_mm: -2\n"),
              HasSubstr("meshes[0].fruit_merge_reach_mm: must be >= 0, got -2"));
  EXPECT_THAT(error("    merge: [{match: \"a*\", into: \"b*\", to: x}]\n"),
              HasSubstr("meshes[0].merge[0]: unknown key 'to'"));
  EXPECT_THAT(error("    merge: [{match: \"a*\"}]\n"), HasSubstr("meshes[0].merge[0]"));
  EXPECT_THAT(error("    merge: {match: a}\n"), HasSubstr("meshes[0].merge: must be a list"));
  EXPECT_THAT(error("    fruit_min_size: 3\n"), HasSubstr("unknown key 'fruit_min_size'"));
}

TEST(GlobCaptureTest, StarsCaptureTheShortestText) {
  std::vector<std::string> c;
  EXPECT_TRUE(GlobCapture("Fruit*_calyx", "Fruit12_calyx", &c));
  EXPECT_EQ(c, std::vector<std::string>({"12"}));
  EXPECT_TRUE(GlobCapture("Fruit*_calyx_*", "Fruit3_calyx_b", &c));
  EXPECT_EQ(c, std::vector<std::string>({"3", "b"}));
  EXPECT_TRUE(GlobCapture("*_*", "a_b_c", &c));
  EXPECT_EQ(c, std::vector<std::string>({"a", "b_c"}));
  EXPECT_TRUE(GlobCapture("?x*", "axe", &c));
  EXPECT_EQ(c, std::vector<std::string>({"e"}));
  EXPECT_FALSE(GlobCapture("Fruit*_calyx", "Fruit12", &c));
  EXPECT_TRUE(c.empty());
  EXPECT_TRUE(GlobCapture("*", "", &c));
  EXPECT_EQ(c, std::vector<std::string>({""}));
  // Agrees with GlobMatch.
  for (const char* p : {"a*b*c", "*", "a?c", "**x"}) {
    for (const char* t : {"abc", "aXbYc", "x", "", "aXXbYYbZ"}) {
      EXPECT_EQ(GlobCapture(p, t, nullptr), GlobMatch(p, t)) << p << " " << t;
    }
  }
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
