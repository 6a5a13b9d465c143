// SaveSceneFiles: a scene as a scene file of its own (OBJ + MTL + YAML, docs/scene-format.md),
// every object a named OBJ object with its material colour, read back by LoadSceneFile.

#include <algorithm>
#include <cctype>
#include <iterator>
#include <string>
#include <string_view>
#include <system_error>
#include <variant>
#include <vector>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <avp/core/semantic_class.h>
#include <avp/core/text.h>
#include <avp/io/file.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/scenario.h>
#include <avp/sim/scene_file.h>

namespace avp::sim {

namespace {

namespace fs = std::filesystem;

std::string FileSafe(std::string_view name) {
  std::string out;
  for (const char c : name) {
    out +=
        (std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.') ? c : '_';
  }
  return out.empty() ? "scene" : out;
}

/// OBJ object names: no whitespace (assimp would split them).
std::string ObjSafe(std::string_view name) {
  std::string out;
  for (const char c : name) out += std::isspace(static_cast<unsigned char>(c)) ? '_' : c;
  return out;
}

/// The scene's objects as OBJ text and their colours as MTL text, with the classes they use.
struct SceneMeshText {
  std::string obj;
  std::string mtl;
  std::vector<SemanticClass> classes_used;
};

SceneMeshText SceneMeshFiles(const Scene& scene, const std::string& mtl_name) {
  SceneMeshText text;
  std::string& obj = text.obj;
  obj += fmt::format("# avp scene {} (seed {}), world frame, metres\nmtllib {}\n",
                     QuoteText(scene.name), scene.seed, mtl_name);
  size_t vertex_base = 1;
  for (const SceneObject& o : scene.objects) {
    const TriangleMesh mesh = std::holds_alternative<TriangleMesh>(o.shape)
                                  ? std::get<TriangleMesh>(o.shape)
                                  : TessellateEllipsoid(std::get<Ellipsoid>(o.shape), 3);
    const std::string material = fmt::format("m{}", o.instance_id);
    fmt::format_to(std::back_inserter(text.mtl), "newmtl {}\nKd {:.6f} {:.6f} {:.6f}\n", material,
                   o.albedo.x(), o.albedo.y(), o.albedo.z());
    fmt::format_to(std::back_inserter(obj), "o {}__{}__{}\nusemtl {}\n", ToString(o.semantic_class),
                   o.instance_id, ObjSafe(o.name), material);
    for (const Eigen::Vector3f& v : mesh.vertices) {
      fmt::format_to(std::back_inserter(obj), "v {:.7g} {:.7g} {:.7g}\n", v.x(), v.y(), v.z());
    }
    for (const Eigen::Vector3i& t : mesh.triangles) {
      fmt::format_to(
          std::back_inserter(obj), "f {} {} {}\n", vertex_base + static_cast<size_t>(t[0]),
          vertex_base + static_cast<size_t>(t[1]), vertex_base + static_cast<size_t>(t[2]));
    }
    vertex_base += mesh.vertices.size();
    if (std::find(text.classes_used.begin(), text.classes_used.end(), o.semantic_class) ==
        text.classes_used.end()) {
      text.classes_used.push_back(o.semantic_class);
    }
  }
  return text;
}

/// The scene file naming the saved mesh `obj_name`, with one class rule per class used.
std::string SceneYaml(const Scene& scene, const std::string& obj_name,
                      const std::vector<SemanticClass>& classes_used) {
  YAML::Emitter out;
  out.SetDoublePrecision(10);
  out << YAML::BeginMap;
  out << YAML::Key << "version" << YAML::Value << kSceneFileVersion;
  out << YAML::Key << "name" << YAML::Value << scene.name;
  out << YAML::Key << "description" << YAML::Value << scene.description;
  if (!scene.start_joints_rad.empty()) {
    std::vector<double> deg;
    for (const double q : scene.start_joints_rad) deg.push_back(RadToDeg(q));
    out << YAML::Key << "start_joints_deg" << YAML::Value << YAML::Flow << deg;
  }
  const Eigen::Vector3d eye = scene.X_WC_start.translation();
  const Eigen::Vector3d target = eye + scene.X_WC_start.rotation().col(2);
  const Eigen::Vector3d up = -scene.X_WC_start.rotation().col(1);
  const auto vec = [](const Eigen::Vector3d& v) {
    return std::vector<double>{v.x(), v.y(), v.z()};
  };
  out << YAML::Key << "start_camera" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "eye" << YAML::Value << YAML::Flow << vec(eye);
  out << YAML::Key << "target" << YAML::Value << YAML::Flow << vec(target);
  out << YAML::Key << "up" << YAML::Value << YAML::Flow << vec(up);
  out << YAML::EndMap;
  out << YAML::Key << "ground" << YAML::Value << false;  // a ground object is saved as a mesh
  out << YAML::Key << "meshes" << YAML::Value << YAML::BeginSeq << YAML::BeginMap;
  out << YAML::Key << "file" << YAML::Value << obj_name;
  out << YAML::Key << "up_axis" << YAML::Value << "z";
  out << YAML::Key << "fruit_instances" << YAML::Value << "objects";
  out << YAML::Key << "default_class" << YAML::Value << "other";
  // The materials are the objects' own colours: never taken for placeholders.
  out << YAML::Key << "materials" << YAML::Value << "use";
  out << YAML::Key << "classes" << YAML::Value << YAML::BeginSeq;
  for (const SemanticClass c : classes_used) {
    out << YAML::Flow << YAML::BeginMap;
    out << YAML::Key << "match" << YAML::Value << fmt::format("{}__*", ToString(c));
    out << YAML::Key << "class" << YAML::Value << std::string(ToString(c));
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap << YAML::EndSeq << YAML::EndMap;
  return std::string("# Written by avp::sim::SaveSceneFiles (format: docs/scene-format.md)\n") +
         out.c_str() + "\n";
}

}  // namespace

Status SaveSceneFiles(const Scene& scene, const fs::path& dir) {
  AVP_RETURN_IF_ERROR(scene.Validate());
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) {
    return IoError(fmt::format("cannot create directory '{}': {}", dir.string(), ec.message()));
  }
  const std::string stem = FileSafe(scene.name);
  const fs::path obj_path = dir / (stem + ".obj");
  const fs::path mtl_path = dir / (stem + ".mtl");
  const fs::path yaml_path = dir / (stem + ".yaml");

  // Both meshes in memory first, then each file atomically: the YAML last, so it never names a
  // mesh that is not complete.
  const SceneMeshText mesh = SceneMeshFiles(scene, mtl_path.filename().string());
  AVP_RETURN_IF_ERROR(io::WriteFileAtomic(mtl_path, mesh.mtl, "scene materials (MTL)"));
  AVP_RETURN_IF_ERROR(io::WriteFileAtomic(obj_path, mesh.obj, "scene mesh (OBJ)"));
  const std::string yaml_text = SceneYaml(scene, obj_path.filename().string(), mesh.classes_used);
  AVP_RETURN_IF_ERROR(io::WriteFileAtomic(yaml_path, yaml_text, "scene file"));
  return Status::Ok();
}

}  // namespace avp::sim
