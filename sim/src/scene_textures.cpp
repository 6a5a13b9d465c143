#include "scene_textures.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <span>
#include <system_error>
#include <utility>

#include <assimp/material.h>
#include <assimp/scene.h>
#include <assimp/texture.h>
#include <fmt/format.h>

#include <avp/core/text.h>
#include <avp/io/image_codec.h>
#include <avp/io/image_limits.h>
#include <avp/sim/scene_file.h>

namespace avp::sim::internal {

namespace fs = std::filesystem;

std::string LowerExtension(const fs::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

namespace {

int HexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

/// "%20" -> " " (glTF URIs are percent-encoded); anything malformed is kept as it is.
std::string PercentDecoded(std::string_view s) {
  std::string out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '%' && i + 2 < s.size()) {
      const int hi = HexValue(s[i + 1]);
      const int lo = HexValue(s[i + 2]);
      if (hi >= 0 && lo >= 0) {
        out += static_cast<char>(hi * 16 + lo);
        i += 2;
        continue;
      }
    }
    out += s[i];
  }
  return out;
}

bool IsFile(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec);
}

/// Where an external texture reference points: relative to the mesh file's folder (or
/// absolute); Windows separators accepted; a glTF URI percent-decoded; when that is no file, the
/// bare file name next to the mesh file (exporters often write the absolute path of the machine
/// the model was made on). The first candidate when none exists (for the message).
fs::path ResolveImage(const std::string& reference, const fs::path& mesh_dir) {
  std::string ref = reference;
  std::replace(ref.begin(), ref.end(), '\\', '/');
  if (ref.rfind("file://", 0) == 0) ref = ref.substr(7);
  std::vector<fs::path> candidates;
  const auto add = [&](const std::string& r) {
    const fs::path p(r);
    candidates.push_back(p.is_absolute() ? p : mesh_dir / p);
    candidates.push_back(mesh_dir / p.filename());
  };
  add(ref);
  if (ref.find('%') != std::string::npos) add(PercentDecoded(ref));
  for (const fs::path& c : candidates) {
    if (IsFile(c)) return c.lexically_normal();
  }
  return candidates.front().lexically_normal();
}

/// An embedded texture (glb buffer, data URI, FBX ...) decoded into an RGB image.
Result<ImageRgb8> DecodeEmbedded(const aiTexture& tex, const std::string& what) {
  if (tex.mHeight == 0) {
    // Compressed (PNG, JPEG ...): mWidth bytes.
    if (tex.pcData == nullptr || tex.mWidth == 0) {
      return ParseError(fmt::format("{} holds no bytes", what));
    }
    const std::span<const uint8_t> bytes(reinterpret_cast<const uint8_t*>(tex.pcData),
                                         static_cast<size_t>(tex.mWidth));
    Result<ImageRgb8> image = io::DecodeImage(bytes);
    if (!image.ok()) return image.status().WithContext(what);
    return image;
  }
  AVP_RETURN_IF_ERROR(io::CheckImageSize(tex.mWidth, tex.mHeight, what));
  if (tex.pcData == nullptr) return ParseError(fmt::format("{} holds no texels", what));
  ImageRgb8 image(static_cast<int>(tex.mWidth), static_cast<int>(tex.mHeight));
  uint8_t* out = image.data().data();
  const size_t n = image.num_pixels();
  for (size_t i = 0; i < n; ++i) {
    out[3 * i + 0] = tex.pcData[i].r;
    out[3 * i + 1] = tex.pcData[i].g;
    out[3 * i + 2] = tex.pcData[i].b;
  }
  return image;
}

std::string FactorKey(const Eigen::Vector3f& f) {
  return fmt::format("{:a},{:a},{:a}", f.x(), f.y(), f.z());
}

}  // namespace

TextureLoader::TextureLoader(const aiScene& scene, fs::path mesh_file)
    : scene_(scene), mesh_file_(std::move(mesh_file)) {
  const std::string ext = LowerExtension(mesh_file_);
  gltf_ = ext == ".gltf" || ext == ".glb";
}

void TextureLoader::Fail(const std::string& key, std::string image, std::string reason,
                         std::string_view part) {
  auto [it, inserted] = failures_.try_emplace(key);
  if (inserted) {
    it->second.image = std::move(image);
    it->second.reason = std::move(reason);
    failure_order_.push_back(key);
  }
  it->second.parts.emplace_back(part);
}

std::shared_ptr<const Texture> TextureLoader::Load(const std::string& reference,
                                                   const Eigen::Vector3f& factor,
                                                   std::string_view part) {
  const std::string key = reference + '\n' + FactorKey(factor);
  if (const auto it = decoded_.find(key); it != decoded_.end()) return it->second;
  if (const auto it = failures_.find(reference); it != failures_.end()) {
    it->second.parts.emplace_back(part);
    return nullptr;
  }
  // The same image with another factor: decoded once, copied.
  for (const auto& [k, t] : decoded_) {
    if (k.compare(0, reference.size() + 1, reference + '\n') == 0) {
      auto copy = std::make_shared<Texture>(*t);
      copy->factor = factor;
      decoded_.emplace(key, copy);
      return copy;
    }
  }

  const std::string mesh_name = mesh_file_.filename().string();
  auto texture = std::make_shared<Texture>();
  texture->factor = factor;
  const aiTexture* embedded = nullptr;
  int index = -1;
  if (!reference.empty() && (reference[0] == '*' || scene_.mNumTextures > 0)) {
    std::tie(embedded, index) = scene_.GetEmbeddedTextureAndIndex(reference.c_str());
  }
  if (embedded != nullptr) {
    texture->source = fmt::format("{} embedded texture {}", QuoteText(mesh_name), index);
    Result<ImageRgb8> image = DecodeEmbedded(*embedded, texture->source);
    if (!image.ok()) {
      Fail(reference, texture->source, image.status().message(), part);
      return nullptr;
    }
    texture->image = std::move(*image);
  } else if (!reference.empty() && reference[0] == '*') {
    Fail(reference, QuoteText(reference),
         fmt::format("{} holds {} embedded textures", QuoteText(mesh_name), scene_.mNumTextures),
         part);
    return nullptr;
  } else {
    const fs::path file = ResolveImage(reference, mesh_file_.parent_path());
    texture->source = file.string();
    Result<ImageRgb8> image = io::ReadImageFile(file);
    if (!image.ok()) {
      Fail(reference, QuoteText(reference), image.status().message(), part);
      return nullptr;
    }
    texture->image = std::move(*image);
  }
  if (const Status valid = texture->Validate(); !valid.ok()) {
    Fail(reference, QuoteText(texture->source), valid.message(), part);
    return nullptr;
  }
  // Each image is bounded by max_image_pixels before it is decoded; the images a mesh file keeps
  // together by max_scene_texture_pixels (a file may name thousands of images).
  const uint64_t texels = static_cast<uint64_t>(texture->image.width()) *
                          static_cast<uint64_t>(texture->image.height());
  if (const Status budget = MaxSceneTexturePixels().Check(
          fmt::format("texture pixels of {} with {}", QuoteText(mesh_name),
                      QuoteText(texture->source)),
          kept_texels_ + texels);
      !budget.ok()) {
    Fail(reference, QuoteText(texture->source), budget.message(), part);
    return nullptr;
  }
  kept_texels_ += texels;
  decoded_.emplace(key, texture);
  return texture;
}

std::optional<Eigen::Vector3f> TextureLoader::Attach(const aiMaterial& material, const aiMesh& mesh,
                                                     std::string_view part, TriangleMesh* out) {
  // glTF's base colour map (assimp also files it as the diffuse map); the diffuse map otherwise.
  const aiTextureType types[2] = {gltf_ ? aiTextureType_BASE_COLOR : aiTextureType_DIFFUSE,
                                  gltf_ ? aiTextureType_DIFFUSE : aiTextureType_BASE_COLOR};
  aiString path;
  aiTextureMapping mapping = aiTextureMapping_UV;
  unsigned uv_index = 0;
  bool found = false;
  for (const aiTextureType type : types) {
    if (material.GetTextureCount(type) == 0) continue;
    mapping = aiTextureMapping_UV;
    uv_index = 0;
    if (material.GetTexture(type, 0, &path, &mapping, &uv_index) == AI_SUCCESS && path.length > 0) {
      found = true;
      break;
    }
  }
  if (!found) return std::nullopt;
  const std::string reference(path.C_Str(), path.length);
  if (mapping != aiTextureMapping_UV) {
    Fail("mapping\n" + reference, QuoteText(reference),
         fmt::format("its projection (assimp mapping {}) is not a UV map; only UV-mapped "
                     "textures are rendered",
                     static_cast<int>(mapping)),
         part);
    return std::nullopt;
  }
  // Texture coordinates: the channel the material names, else the first.
  const aiVector3D* coords =
      uv_index < AI_MAX_NUMBER_OF_TEXTURECOORDS ? mesh.mTextureCoords[uv_index] : nullptr;
  if (coords == nullptr) coords = mesh.mTextureCoords[0];
  if (coords == nullptr || mesh.mNumVertices == 0) {
    Fail("no uvs\n" + reference, QuoteText(reference),
         "the parts using it have no texture coordinates", part);
    return std::nullopt;
  }
  for (unsigned v = 0; v < mesh.mNumVertices; ++v) {
    if (!std::isfinite(coords[v].x) || !std::isfinite(coords[v].y)) {
      Fail("bad uvs\n" + reference, QuoteText(reference),
           fmt::format("texture coordinate {} ({}, {}) is not finite", v, coords[v].x, coords[v].y),
           part);
      return std::nullopt;
    }
  }

  Eigen::Vector3f factor = Eigen::Vector3f::Ones();
  if (gltf_) {
    aiColor4D base;
    aiColor3D diffuse;
    if (material.Get(AI_MATKEY_BASE_COLOR, base) == AI_SUCCESS) {
      factor = Eigen::Vector3f(base.r, base.g, base.b);
    } else if (material.Get(AI_MATKEY_COLOR_DIFFUSE, diffuse) == AI_SUCCESS) {
      factor = Eigen::Vector3f(diffuse.r, diffuse.g, diffuse.b);
    }
    if (!factor.allFinite()) factor = Eigen::Vector3f::Ones();
    factor = factor.cwiseMax(0.0f).cwiseMin(1.0f);
  }
  std::shared_ptr<const Texture> texture = Load(reference, factor, part);
  if (texture == nullptr) return std::nullopt;

  out->uvs.clear();
  out->uvs.reserve(mesh.mNumVertices);
  for (unsigned v = 0; v < mesh.mNumVertices; ++v) out->uvs.emplace_back(coords[v].x, coords[v].y);

  // Representative colour: the texture's mean over each triangle (Texture::MeanOverTriangle),
  // weighted by the triangle's area (in file coordinates); at most ~16384 triangles sampled.
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double weight = 0.0;
  const unsigned stride = std::max(1u, mesh.mNumFaces / 16384u);
  for (unsigned f = 0; f < mesh.mNumFaces; f += stride) {
    const aiFace& face = mesh.mFaces[f];
    if (face.mNumIndices != 3) continue;
    const unsigned a = face.mIndices[0], b = face.mIndices[1], c = face.mIndices[2];
    if (a >= mesh.mNumVertices || b >= mesh.mNumVertices || c >= mesh.mNumVertices) continue;
    const aiVector3D& pa = mesh.mVertices[a];
    const aiVector3D e1 = mesh.mVertices[b] - pa;
    const aiVector3D e2 = mesh.mVertices[c] - pa;
    const double area = 0.5 * static_cast<double>((e1 ^ e2).Length());
    if (!(area > 0.0) || !std::isfinite(area)) continue;
    sum += area * texture->MeanOverTriangle(out->uvs[a], out->uvs[b], out->uvs[c]).cast<double>();
    weight += area;
  }
  const Eigen::Vector3f color = weight > 0.0 ? (sum / weight).cast<float>() : texture->MeanColor();
  out->texture = std::move(texture);
  out->face_albedo.clear();
  return color.cwiseMax(0.0f).cwiseMin(1.0f);
}

std::vector<std::string> TextureLoader::Warnings() const {
  std::vector<std::string> out;
  for (const std::string& key : failure_order_) {
    const Failure& f = failures_.at(key);
    std::string parts;
    constexpr size_t kShown = 3;
    for (size_t i = 0; i < f.parts.size() && i < kShown; ++i) {
      if (i > 0) parts += ", ";
      parts += QuoteText(f.parts[i]);
    }
    if (f.parts.size() > kShown) parts += fmt::format(" and {} more", f.parts.size() - kShown);
    out.push_back(fmt::format(
        "mesh {}: texture {} is not rendered: {}; {} part{} ({}) use{} the material colour",
        QuoteText(mesh_file_.filename().string()), f.image, f.reason, f.parts.size(),
        f.parts.size() == 1 ? "" : "s", parts, f.parts.size() == 1 ? "s" : ""));
  }
  return out;
}

}  // namespace avp::sim::internal
