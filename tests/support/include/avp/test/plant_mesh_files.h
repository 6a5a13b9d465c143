#pragma once

// A small asymmetric test plant written as mesh files in any format assimp exports (OBJ + MTL,
// PLY, STL, COLLADA, glTF 2 .gltf/.glb), with a scene file placing them: the way a user brings
// their own plant. Link assimp::assimp and avp::sim.
#include <filesystem>
#include <fstream>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <assimp/Exporter.hpp>
#include <assimp/scene.h>

#include <avp/core/transform.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/scene.h>

namespace avp::test {

/// One export format: assimp's id and the file extension.
struct MeshFormat {
  std::string assimp_id;  ///< "obj", "ply", "stl", "collada", "gltf2", "glb2"
  std::string ext;        ///< "obj", "ply", "stl", "dae", "gltf", "glb"
};

inline std::vector<MeshFormat> AllMeshFormats() {
  return {{"obj", "obj"},     {"ply", "ply"},    {"stl", "stl"},
          {"collada", "dae"}, {"gltf2", "gltf"}, {"glb2", "glb"}};
}

/// The test plant in the world frame (metres, z up): a stem at (0.7, 0), a leaf screen 9 cm
/// behind it (+x, away from the arm), two leaves, and two fruit clusters on the arm's side: 4
/// fruit (r 25 mm) in a row at z = 0.70 and 3 at z = 0.40.
struct TestPlant {
  sim::TriangleMesh foliage;  ///< stem, leaves, screen (one mesh)
  sim::TriangleMesh fruits;   ///< 7 disconnected icospheres (one mesh)
  std::vector<Eigen::Vector3d> fruit_centres;
  static constexpr double kFruitRadius = 0.025;

  TestPlant() {
    foliage = sim::MakeCylinder(Eigen::Vector3d(0.7, 0, 0), Eigen::Vector3d(0.7, 0, 0.9), 0.012, 8);
    sim::TriangleMesh screen = sim::MakeBox(Eigen::Vector3d(0.004, 0.2, 0.3));
    foliage.Append(screen, RigidTransform(Eigen::Vector3d(0.79, 0.0, 0.55)));
    sim::TriangleMesh leaf = sim::MakeBox(Eigen::Vector3d(0.08, 0.05, 0.002));
    foliage.Append(leaf, RigidTransform(Eigen::Vector3d(0.7, 0.12, 0.85)));
    foliage.Append(leaf, RigidTransform(Eigen::Vector3d(0.7, -0.12, 0.25)));
    const auto row = [&](int n, double z) {
      for (int i = 0; i < n; ++i) {
        fruit_centres.emplace_back(0.63, (i - 0.5 * (n - 1)) * 0.056, z);
      }
    };
    row(4, 0.70);
    row(3, 0.40);
    const sim::TriangleMesh sphere = sim::MakeIcosphere(kFruitRadius, 2);
    for (const Eigen::Vector3d& c : fruit_centres) fruits.Append(sphere, RigidTransform(c));
  }
};

namespace internal {

inline aiMesh* ToAiMesh(const sim::TriangleMesh& mesh, const std::string& name) {
  auto* m = new aiMesh();
  m->mName = name;
  m->mPrimitiveTypes = aiPrimitiveType_TRIANGLE;
  m->mMaterialIndex = 0;
  m->mNumVertices = static_cast<unsigned>(mesh.vertices.size());
  m->mVertices = new aiVector3D[m->mNumVertices];
  for (unsigned i = 0; i < m->mNumVertices; ++i) {
    const Eigen::Vector3f& v = mesh.vertices[i];
    m->mVertices[i] = aiVector3D(v.x(), v.y(), v.z());
  }
  m->mNumFaces = static_cast<unsigned>(mesh.triangles.size());
  m->mFaces = new aiFace[m->mNumFaces];
  for (unsigned f = 0; f < m->mNumFaces; ++f) {
    aiFace& face = m->mFaces[f];
    face.mNumIndices = 3;
    face.mIndices = new unsigned[3];
    for (int k = 0; k < 3; ++k) face.mIndices[k] = static_cast<unsigned>(mesh.triangles[f][k]);
  }
  return m;
}

}  // namespace internal

/// Writes `mesh` as <dir>/<stem>.<ext> in `format` (one node and mesh named `stem`, one material
/// of `rgb`). @throws std::runtime_error with assimp's message when the export fails.
inline std::filesystem::path WriteMeshFile(const sim::TriangleMesh& mesh, const MeshFormat& format,
                                           const std::filesystem::path& dir,
                                           const std::string& stem, const aiColor3D& rgb) {
  aiScene scene;  // its destructor frees what is attached below
  scene.mNumMaterials = 1;
  scene.mMaterials = new aiMaterial*[1];
  scene.mMaterials[0] = new aiMaterial();
  const aiString material_name(stem + "_material");
  scene.mMaterials[0]->AddProperty(&material_name, AI_MATKEY_NAME);
  scene.mMaterials[0]->AddProperty(&rgb, 1, AI_MATKEY_COLOR_DIFFUSE);
  scene.mNumMeshes = 1;
  scene.mMeshes = new aiMesh*[1];
  scene.mMeshes[0] = internal::ToAiMesh(mesh, stem);
  scene.mRootNode = new aiNode("root");
  auto* node = new aiNode(stem);
  node->mNumMeshes = 1;
  node->mMeshes = new unsigned[1]{0};
  scene.mRootNode->addChildren(1, &node);
  std::filesystem::create_directories(dir);
  const std::filesystem::path path = dir / (stem + "." + format.ext);
  Assimp::Exporter exporter;
  if (exporter.Export(&scene, format.assimp_id, path.string()) != AI_SUCCESS) {
    throw std::runtime_error("assimp cannot export " + path.string() + ": " +
                             exporter.GetErrorString());
  }
  return path;
}

/// The test plant as <dir>/foliage.<ext> and <dir>/fruits.<ext> in `format` plus
/// <dir>/<name>.yaml placing them (class leaf and class fruit, one fruit per connected component;
/// raw file coordinates z-up; ground at z = 0); returns the YAML's path.
inline std::filesystem::path WriteTestPlantScene(const MeshFormat& format,
                                                 const std::filesystem::path& dir,
                                                 const std::string& name) {
  const TestPlant plant;
  WriteMeshFile(plant.foliage, format, dir, "foliage", aiColor3D(0.1f, 0.4f, 0.1f));
  WriteMeshFile(plant.fruits, format, dir, "fruits", aiColor3D(0.8f, 0.1f, 0.05f));
  const std::filesystem::path yaml = dir / (name + ".yaml");
  std::ofstream(yaml) << "version: 1\nname: " << name << "\nground: true\nmeshes:\n"
                      << "  - {file: foliage." << format.ext
                      << ", up_axis: z, default_class: leaf}\n"
                      << "  - {file: fruits." << format.ext
                      << ", up_axis: z, default_class: fruit, fruit_instances: components}\n";
  return yaml;
}

}  // namespace avp::test
