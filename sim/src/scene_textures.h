#pragma once

// Textures of a mesh file read by assimp (scene_file.cpp): the diffuse / base-colour map of a
// part's material, decoded once per image through avp's image codecs (io/image_codec.h: header
// checked against max_image_pixels before any pixel is decoded), attached to the part's mesh with
// its texture coordinates. docs/scene-format.md, "Textures".

#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <avp/sim/scene.h>

struct aiScene;
struct aiMaterial;
struct aiMesh;

namespace avp::sim::internal {

/// A file's extension in lower case, with its dot (".obj"); empty when it has none.
std::string LowerExtension(const std::filesystem::path& p);

/// Finds, decodes and attaches the textures of one imported mesh file. Not thread-safe; one per
/// import.
class TextureLoader {
 public:
  /// `scene`: what assimp imported from `mesh_file` (outlives the loader). glTF files (.gltf,
  /// .glb) multiply the texture by the material's baseColorFactor; in other formats the texture
  /// replaces the material's diffuse colour.
  TextureLoader(const aiScene& scene, std::filesystem::path mesh_file);

  /// When `material` has a diffuse or base-colour texture that can be used: sets out->texture and
  /// out->uvs (one per vertex of `mesh`, in its order: call it for the part built from `mesh`
  /// alone) and returns the part's representative colour (Texture::MeanOverTriangle of its
  /// triangles, area-weighted; at most ~16384 triangles sampled). Returns nothing when the material
  /// has no texture, or when it cannot be used (image missing or undecodable, no texture
  /// coordinates, a mapping other than UV): then a warning names the image and `part` (the caller
  /// falls back to the material colour).
  std::optional<Eigen::Vector3f> Attach(const aiMaterial& material, const aiMesh& mesh,
                                        std::string_view part, TriangleMesh* out);

  /// One sentence per image that could not be used (naming the image, the reason and the parts
  /// that fell back to their material colour); empty when all went well.
  std::vector<std::string> Warnings() const;

  /// Images decoded so far (for tests and `scene check`).
  size_t num_decoded() const { return decoded_.size(); }

 private:
  struct Failure {
    std::string image;   // the texture reference, escaped
    std::string reason;  // why it could not be used
    std::vector<std::string> parts;
  };
  /// The decoded texture for `reference` with `factor`, or null after recording a failure.
  std::shared_ptr<const Texture> Load(const std::string& reference, const Eigen::Vector3f& factor,
                                      std::string_view part);
  void Fail(const std::string& key, std::string image, std::string reason, std::string_view part);

  const aiScene& scene_;
  std::filesystem::path mesh_file_;
  bool gltf_ = false;
  std::map<std::string, std::shared_ptr<const Texture>> decoded_;  // key: reference + factor
  std::map<std::string, Failure> failures_;                        // key: reference or reason
  uint64_t kept_texels_ = 0;  // pixels of the decoded_ images (max_scene_texture_pixels)
  std::vector<std::string> failure_order_;
};

}  // namespace avp::sim::internal
