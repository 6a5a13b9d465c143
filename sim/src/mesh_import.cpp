// A scene file's mesh entry through assimp: the file's sizes checked first (mesh_checks.cpp), then
// read, validated, post-processed, checked again, and turned into parts: one per mesh of each
// node, with its class (the first class rule matching), its colour (rule, entry, texture,
// material, class default) and its triangles in the world frame.

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <assimp/DefaultLogger.hpp>
#include <assimp/Importer.hpp>
#include <assimp/Logger.hpp>
#include <assimp/config.h>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/io/file.h>
#include <avp/sim/scene_file.h>

#include "scene_file_internal.h"
#include "scene_textures.h"

namespace avp::sim::internal {

namespace {

namespace fs = std::filesystem;

Eigen::Matrix4d ToEigen(const aiMatrix4x4& m) {
  Eigen::Matrix4d out;
  for (unsigned r = 0; r < 4; ++r) {
    for (unsigned c = 0; c < 4; ++c) out(r, c) = m[r][c];
  }
  return out;
}

/// Collects what assimp logs (warnings and errors) while alive, for the error message of a failed
/// import. Assimp's logger is process-wide: one import at a time holds it (a mutex).
class AssimpMessages {
 public:
  AssimpMessages() : lock_(Mutex()) { Assimp::DefaultLogger::set(new Collector(&text_)); }
  ~AssimpMessages() { Assimp::DefaultLogger::kill(); }
  AssimpMessages(const AssimpMessages&) = delete;
  AssimpMessages& operator=(const AssimpMessages&) = delete;
  /// "; assimp said: '...'" (escaped, shortened) or empty.
  std::string Quote() const {
    return text_.empty() ? std::string() : "; assimp said: " + QuoteText(text_, 300);
  }

 private:
  class Collector : public Assimp::Logger {
   public:
    explicit Collector(std::string* text) : Assimp::Logger(Assimp::Logger::NORMAL), text_(text) {}
    bool attachStream(Assimp::LogStream*, unsigned int) override { return false; }
    bool detachStream(Assimp::LogStream*, unsigned int) override { return false; }

   private:
    void OnDebug(const char*) override {}
    void OnVerboseDebug(const char*) override {}
    void OnInfo(const char*) override {}
    void OnWarn(const char* message) override { Add("warning", message); }
    void OnError(const char* message) override { Add("error", message); }
    void Add(std::string_view kind, const char* message) {
      if (text_->size() > 4096) return;
      if (!text_->empty()) *text_ += " | ";
      *text_ += fmt::format("{}: {}", kind, message);
    }
    std::string* text_;
  };
  static std::mutex& Mutex() {
    static std::mutex mutex;
    return mutex;
  }
  std::lock_guard<std::mutex> lock_;
  std::string text_;
};

/// The file's size, and a PLY's declared counts or an OBJ's or STL's lines, before assimp reads
/// anything.
Status CheckMeshFileSizes(const MeshEntry& entry, const std::string& ext,
                          const std::string& context) {
  AVP_ASSIGN_OR_RETURN(const uint64_t file_bytes, io::CheckReadableFile(entry.file, "mesh file"));
  AVP_RETURN_IF_ERROR(MaxMeshFileBytes().Check(
      fmt::format("{}.file: mesh '{}' of {} bytes", context, entry.file.string(), file_bytes),
      file_bytes));
  if (ext == ".ply") AVP_RETURN_IF_ERROR(CheckPlyHeader(entry.file, file_bytes, context));
  if (ext == ".obj" || ext == ".stl") {
    AVP_RETURN_IF_ERROR(CheckObjOrStlCounts(entry.file, file_bytes, ext, context));
  }
  return Status::Ok();
}

/// Sets the importer's options; returns whether the file's coordinates are Y-up.
bool ConfigureImporter(Assimp::Importer& importer, const MeshEntry& entry, const std::string& ext) {
  const bool is_collada = ext == ".dae";
  const bool is_gltf = ext == ".gltf" || ext == ".glb";
  // Up axis: COLLADA declares one (assimp turns the file into its Y-up convention unless told to
  // ignore it), glTF is Y-up by specification, other formats are taken as Z-up (ROS/URDF habit).
  // An explicit up_axis describes the raw file coordinates and switches assimp's conversion off.
  bool y_up = is_collada || is_gltf;
  if (entry.up_axis != UpAxis::kAuto) {
    importer.SetPropertyBool(AI_CONFIG_IMPORT_COLLADA_IGNORE_UP_DIRECTION, true);
    y_up = entry.up_axis == UpAxis::kY;
  }
  importer.SetPropertyBool(AI_CONFIG_IMPORT_COLLADA_USE_COLLADA_NAMES, true);
  importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE,
                              aiPrimitiveType_POINT | aiPrimitiveType_LINE);
  return y_up;
}

/// Each mesh's primitive types recomputed from its faces; a face of no vertex is refused.
Status RecomputePrimitiveTypes(const aiScene& ai, const MeshEntry& entry,
                               const std::string& context, const AssimpMessages& messages) {
  for (unsigned i = 0; i < ai.mNumMeshes; ++i) {
    aiMesh* m = ai.mMeshes[i];
    if (m == nullptr) continue;
    unsigned types = 0;
    for (unsigned f = 0; f < m->mNumFaces; ++f) {
      const unsigned n = m->mFaces[f].mNumIndices;
      if (n == 0) {
        return ParseError(
            fmt::format("{}.file: mesh '{}': face {} of mesh {} has no vertex (a corrupt face "
                        "list){}",
                        context, entry.file.string(), f, i, messages.Quote()));
      }
      types |= n == 1   ? aiPrimitiveType_POINT
               : n == 2 ? aiPrimitiveType_LINE
               : n == 3 ? aiPrimitiveType_TRIANGLE
                        : aiPrimitiveType_POLYGON;
    }
    m->mPrimitiveTypes = types;
  }
  return Status::Ok();
}

/// What assimp read, triangulated, or the error (with what assimp logged in `assimp_said`).
Result<const aiScene*> ReadWithAssimp(Assimp::Importer& importer, const MeshEntry& entry,
                                      const std::string& context, std::string& assimp_said) {
  const aiScene* ai = nullptr;
  {
    AssimpMessages messages;
    // Read and validated first, post-processed after: a malformed file can leave a mesh with a
    // face of no vertex, or primitive types that disagree with its faces (an ASCII PLY face list
    // cut short), and assimp's triangulation then aborts the process on an assertion
    // (fuzz/regressions/scene_file). Such a face is refused and the types are recomputed from the
    // faces before it runs.
    ai = importer.ReadFile(entry.file.string(), aiProcess_ValidateDataStructure);
    if (ai != nullptr && (ai->mFlags & AI_SCENE_FLAGS_INCOMPLETE) == 0) {
      AVP_RETURN_IF_ERROR(RecomputePrimitiveTypes(*ai, entry, context, messages));
      ai = importer.ApplyPostProcessing(aiProcess_Triangulate | aiProcess_JoinIdenticalVertices |
                                        aiProcess_SortByPType);
    }
    assimp_said = messages.Quote();
  }
  if (ai == nullptr || ai->mRootNode == nullptr || (ai->mFlags & AI_SCENE_FLAGS_INCOMPLETE) != 0) {
    return ParseError(
        fmt::format("{}.file: cannot import mesh '{}': {}{}", context, entry.file.string(),
                    ai == nullptr ? EscapeText(importer.GetErrorString(), 300) : "incomplete scene",
                    assimp_said));
  }
  return ai;
}

/// What assimp read: the counts against the limits, every vertex finite, every index in range.
Status CheckImportedMeshes(const aiScene& ai, const MeshEntry& entry, const std::string& context,
                           const std::string& assimp_said) {
  uint64_t vertices = 0, faces = 0;
  for (unsigned i = 0; i < ai.mNumMeshes; ++i) {
    const aiMesh* m = ai.mMeshes[i];
    if (m == nullptr) {
      return ParseError(fmt::format("{}.file: mesh '{}': assimp returned an empty mesh {}{}",
                                    context, entry.file.string(), i, assimp_said));
    }
    vertices += m->mNumVertices;
    faces += m->mNumFaces;
  }
  AVP_RETURN_IF_ERROR(MaxMeshVertices().Check(
      fmt::format("{}.file: vertices of mesh '{}'", context, entry.file.string()), vertices));
  AVP_RETURN_IF_ERROR(MaxMeshFaces().Check(
      fmt::format("{}.file: faces of mesh '{}'", context, entry.file.string()), faces));
  for (unsigned i = 0; i < ai.mNumMeshes; ++i) {
    const aiMesh* m = ai.mMeshes[i];
    for (unsigned v = 0; v < m->mNumVertices; ++v) {
      const aiVector3D& p = m->mVertices[v];
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
        return ParseError(fmt::format(
            "{}.file: mesh '{}': vertex {} of mesh {} is ({}, {}, {}); coordinates must be finite",
            context, entry.file.string(), v, i, p.x, p.y, p.z));
      }
    }
    for (unsigned f = 0; f < m->mNumFaces; ++f) {
      const aiFace& face = m->mFaces[f];
      for (unsigned k = 0; k < face.mNumIndices; ++k) {
        if (face.mIndices[k] >= m->mNumVertices) {
          return ParseError(
              fmt::format("{}.file: mesh '{}': face {} of mesh {} uses vertex {} of {}", context,
                          entry.file.string(), f, i, face.mIndices[k], m->mNumVertices));
        }
      }
    }
  }
  return Status::Ok();
}

/// X_WM * diag(scale) * U, U: the up-axis correction (p_W = this * M_node * p_file).
Eigen::Matrix4d FileToWorld(const MeshEntry& entry, bool y_up) {
  Eigen::Matrix4d pre = Eigen::Matrix4d::Identity();
  if (y_up) {
    pre.topLeftCorner<3, 3>() =
        Eigen::AngleAxisd(EIGEN_PI / 2.0, Eigen::Vector3d::UnitX()).toRotationMatrix();
  }
  pre.topLeftCorner<3, 3>() = entry.scale.asDiagonal() * pre.topLeftCorner<3, 3>();
  return entry.X_WM.ToMatrix4() * pre;
}

/// Class: the first rule matching the node, mesh or material name (else default_class); returns
/// the rule's colour, else the entry's, when there is one.
std::optional<Eigen::Vector3f> ClassifyPart(const MeshEntry& entry, ImportedPart& part) {
  part.semantic_class = entry.default_class;
  std::optional<Eigen::Vector3f> color;
  for (size_t r = 0; r < entry.rules.size(); ++r) {
    const ClassRule& rule = entry.rules[r];
    if (GlobMatch(rule.pattern, part.node_name) || GlobMatch(rule.pattern, part.mesh_name) ||
        (!part.material.empty() && GlobMatch(rule.pattern, part.material))) {
      part.semantic_class = rule.semantic_class;
      part.rule = static_cast<int>(r);
      if (rule.color) {
        color = rule.color;
        part.color_source = ColorSource::kRule;
      }
      break;
    }
  }
  if (!color && entry.color) {
    color = entry.color;
    part.color_source = ColorSource::kEntry;
  }
  return color;
}

/// The material (texture, then diffuse colour) unless `materials: ignore`; assimp's default
/// material (a mesh without one) gives nothing. Placeholders (`materials: auto`) are replaced
/// after every part of the file is read (ReplacePlaceholderColors).
std::optional<Eigen::Vector3f> MaterialColor(const MeshEntry& entry, const aiMaterial* material,
                                             const aiMesh& m, const std::string& stem,
                                             internal::TextureLoader& textures,
                                             ImportedPart& part) {
  if (entry.materials == MaterialMode::kIgnore || material == nullptr) return std::nullopt;
  // A diffuse / base-colour texture: texture coordinates and image onto the part's mesh,
  // its colour over the part as albedo (scene_textures.h; unusable: a warning, then Kd).
  const std::string& node_name = part.node_name;
  const std::string& mesh_name = part.mesh_name;
  const std::string label =
      fmt::format("{}/{}{}", stem, node_name.empty() ? stem : node_name,
                  mesh_name.empty() || mesh_name == node_name ? std::string() : "/" + mesh_name);
  if (const std::optional<Eigen::Vector3f> mean =
          textures.Attach(*material, m, label, &part.mesh)) {
    part.color_source = ColorSource::kTexture;
    return *mean;
  }
  if (!part.material.empty() && part.material != AI_DEFAULT_MATERIAL_NAME) {
    aiColor3D kd;
    if (material->Get(AI_MATKEY_COLOR_DIFFUSE, kd) == AI_SUCCESS) {
      part.color_source = ColorSource::kMaterial;
      return Eigen::Vector3f(std::clamp(kd.r, 0.0f, 1.0f), std::clamp(kd.g, 0.0f, 1.0f),
                             std::clamp(kd.b, 0.0f, 1.0f));
    }
  }
  return std::nullopt;
}

/// The mesh's vertices through X (to the world frame) and its triangles.
void AppendWorldTriangles(const aiMesh& m, const Eigen::Matrix4d& X, TriangleMesh& mesh) {
  for (unsigned v = 0; v < m.mNumVertices; ++v) {
    const aiVector3D& p = m.mVertices[v];
    const Eigen::Vector4d p_W = X * Eigen::Vector4d(p.x, p.y, p.z, 1.0);
    mesh.vertices.emplace_back(p_W.head<3>().cast<float>());
  }
  for (unsigned f = 0; f < m.mNumFaces; ++f) {
    const aiFace& face = m.mFaces[f];
    if (face.mNumIndices != 3) continue;
    mesh.triangles.emplace_back(static_cast<int>(face.mIndices[0]),
                                static_cast<int>(face.mIndices[1]),
                                static_cast<int>(face.mIndices[2]));
  }
}

/// Where a node is in the traversal: the node and its transform to the world frame.
struct NodeItem {
  const aiNode* node;
  Eigen::Matrix4d X;
};

/// The part of mesh `k` of `item`'s node, or nothing when it holds no triangle.
std::optional<ImportedPart> MakePart(const aiScene& ai, const NodeItem& item, unsigned k,
                                     const MeshEntry& entry, const std::string& stem,
                                     internal::TextureLoader& textures) {
  const std::string node_name = item.node->mName.C_Str();
  const aiMesh* m = ai.mMeshes[item.node->mMeshes[k]];
  if ((m->mPrimitiveTypes & aiPrimitiveType_TRIANGLE) == 0 || m->mNumFaces == 0) {
    return std::nullopt;
  }
  const aiMaterial* material =
      m->mMaterialIndex < ai.mNumMaterials ? ai.mMaterials[m->mMaterialIndex] : nullptr;
  aiString material_name;
  if (material != nullptr) material->Get(AI_MATKEY_NAME, material_name);
  const std::string mesh_name = m->mName.C_Str();

  ImportedPart part;
  part.node_name = node_name;
  part.mesh_name = mesh_name;
  part.material = material_name.C_Str();
  std::optional<Eigen::Vector3f> color = ClassifyPart(entry, part);
  if (!color) color = MaterialColor(entry, material, *m, stem, textures, part);
  part.albedo = color.value_or(DefaultClassColor(part.semantic_class));

  AppendWorldTriangles(*m, item.X, part.mesh);
  if (part.mesh.empty()) return std::nullopt;
  std::string name = fmt::format("{}/{}", stem, node_name.empty() ? stem : node_name);
  if (!mesh_name.empty() && mesh_name != node_name) name += "/" + mesh_name;
  if (item.node->mNumMeshes > 1 && mesh_name.empty()) name += fmt::format("/{}", k);
  part.name = std::move(name);
  return part;
}

/// Every node's meshes as parts: an iterative depth-first traversal (children in file order) with
/// accumulated transforms.
std::vector<ImportedPart> CollectParts(const aiScene& ai, const MeshEntry& entry,
                                       const Eigen::Matrix4d& X_WM,
                                       internal::TextureLoader& textures) {
  std::vector<ImportedPart> parts;
  const std::string stem = entry.file.stem().string();
  std::vector<NodeItem> stack = {{ai.mRootNode, X_WM * ToEigen(ai.mRootNode->mTransformation)}};
  while (!stack.empty()) {
    const NodeItem item = std::move(stack.back());
    stack.pop_back();
    for (unsigned k = 0; k < item.node->mNumMeshes; ++k) {
      std::optional<ImportedPart> part = MakePart(ai, item, k, entry, stem, textures);
      if (part) parts.push_back(std::move(*part));
    }
    for (unsigned c = item.node->mNumChildren; c-- > 0;) {
      const aiNode* child = item.node->mChildren[c];
      stack.push_back({child, item.X * ToEigen(child->mTransformation)});
    }
  }
  return parts;
}

}  // namespace

Result<std::vector<ImportedPart>> ImportMesh(const MeshEntry& entry, const std::string& context,
                                             std::vector<std::string>& warnings) {
  const std::string ext = LowerExtension(entry.file);
  AVP_RETURN_IF_ERROR(CheckMeshFileSizes(entry, ext, context));
  Assimp::Importer importer;
  const bool y_up = ConfigureImporter(importer, entry, ext);
  std::string assimp_said;
  AVP_ASSIGN_OR_RETURN(const aiScene* ai, ReadWithAssimp(importer, entry, context, assimp_said));
  AVP_RETURN_IF_ERROR(CheckImportedMeshes(*ai, entry, context, assimp_said));

  internal::TextureLoader textures(*ai, entry.file);
  std::vector<ImportedPart> parts = CollectParts(*ai, entry, FileToWorld(entry, y_up), textures);
  if (parts.empty()) {
    return ParseError(
        fmt::format("{}.file: mesh '{}' contains no triangles", context, entry.file.string()));
  }
  for (const std::string& w : textures.Warnings()) warnings.push_back(context + ": " + w);
  return parts;
}

}  // namespace avp::sim::internal
