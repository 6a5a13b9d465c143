#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <span>
#include <unordered_set>

#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/core/text.h>
#include <avp/sim/scene.h>

namespace avp::sim {

namespace {

/// 8-bit sRGB -> linear [0, 1] (IEC 61966-2-1).
const std::array<float, 256>& SrgbToLinearLut() {
  static const std::array<float, 256> lut = [] {
    std::array<float, 256> t{};
    for (size_t i = 0; i < t.size(); ++i) {
      const double s = static_cast<double>(i) / 255.0;
      t[i] = static_cast<float>(s <= 0.04045 ? s / 12.92 : std::pow((s + 0.055) / 1.055, 2.4));
    }
    return t;
  }();
  return lut;
}

/// floor(x) for finite |x| < 2^23 without a libm call (the baseline x86-64 build has no
/// roundss); larger floats are whole numbers already.
inline float FastFloor(float x) {
  if (!(std::abs(x) < 8388608.0f)) return x;
  const float t = static_cast<float>(static_cast<int32_t>(x));
  return t > x ? t - 1.0f : t;
}

/// Fractional part in [0, 1) (repeat wrap); x finite.
inline float Wrap01(float x) {
  const float f = x - FastFloor(x);
  return f < 1.0f ? f : 0.0f;  // x slightly below an integer can round up to 1
}

}  // namespace

Eigen::Vector3f Texture::Sample(const Eigen::Vector2f& st) const {
  if (image.empty()) return Eigen::Vector3f::Zero();
  if (!st.allFinite()) return MeanColor();
  const int w = image.width();
  const int h = image.height();
  // Continuous texel coordinates with texel centres at integers; row 0 is the top (t = 1).
  const float x = Wrap01(st.x()) * static_cast<float>(w) - 0.5f;
  const float y = (1.0f - Wrap01(st.y())) * static_cast<float>(h) - 0.5f;
  const float fx0 = FastFloor(x);
  const float fy0 = FastFloor(y);
  const float ax = x - fx0;
  const float ay = y - fy0;
  // Neighbours wrap around the edges (repeat); floor(x) >= -1 and <= w - 1.
  int x0 = static_cast<int>(fx0);
  int y0 = static_cast<int>(fy0);
  int x1 = x0 + 1;
  int y1 = y0 + 1;
  if (x0 < 0) x0 += w;
  if (y0 < 0) y0 += h;
  if (x1 >= w) x1 -= w;
  if (y1 >= h) y1 -= h;
  x0 = std::clamp(x0, 0, w - 1);
  x1 = std::clamp(x1, 0, w - 1);
  y0 = std::clamp(y0, 0, h - 1);
  y1 = std::clamp(y1, 0, h - 1);
  const auto& lut = SrgbToLinearLut();
  const uint8_t* data = image.data().data();
  const auto texel = [&](int u, int v) {
    const uint8_t* p = data + 3 * (static_cast<size_t>(v) * w + u);
    return Eigen::Vector3f(lut[p[0]], lut[p[1]], lut[p[2]]);
  };
  const Eigen::Vector3f top = (1.0f - ax) * texel(x0, y0) + ax * texel(x1, y0);
  const Eigen::Vector3f bottom = (1.0f - ax) * texel(x0, y1) + ax * texel(x1, y1);
  return ((1.0f - ay) * top + ay * bottom).cwiseProduct(factor);
}

Eigen::Vector3f Texture::MeanOverTriangle(const Eigen::Vector2f& a, const Eigen::Vector2f& b,
                                          const Eigen::Vector2f& c) const {
  constexpr int kSteps = 8;
  Eigen::Vector3f sum = Eigen::Vector3f::Zero();
  int n = 0;
  for (int i = 0; i <= kSteps; ++i) {
    for (int j = 0; i + j <= kSteps; ++j) {
      const float wb = static_cast<float>(i) / kSteps;
      const float wc = static_cast<float>(j) / kSteps;
      sum += Sample((1.0f - wb - wc) * a + wb * b + wc * c);
      ++n;
    }
  }
  return sum / static_cast<float>(n);
}

Eigen::Vector3f Texture::MeanColor() const {
  if (image.empty()) return Eigen::Vector3f::Zero();
  const auto& lut = SrgbToLinearLut();
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  const std::span<const uint8_t> data = image.data();
  for (size_t i = 0; i + 2 < data.size(); i += 3) {
    sum += Eigen::Vector3d(lut[data[i]], lut[data[i + 1]], lut[data[i + 2]]);
  }
  return (sum / static_cast<double>(image.num_pixels())).cast<float>().cwiseProduct(factor);
}

Status Texture::Validate() const {
  if (image.empty()) {
    return InvalidArgumentError(fmt::format("texture {} has no texels ({} x {})", QuoteText(source),
                                            image.width(), image.height()));
  }
  if (!factor.allFinite() || (factor.array() < 0.0f).any() || (factor.array() > 1.0f).any()) {
    return InvalidArgumentError(fmt::format("texture {}: factor ({}, {}, {}) must be in [0, 1]",
                                            QuoteText(source), factor.x(), factor.y(), factor.z()));
  }
  return Status::Ok();
}

std::vector<Eigen::Vector3f> TriangleMesh::FaceColors(const Eigen::Vector3f& albedo) const {
  std::vector<Eigen::Vector3f> colors;
  colors.reserve(triangles.size());
  for (size_t i = 0; i < triangles.size(); ++i) {
    const Eigen::Vector3i& t = triangles[i];
    if (texture != nullptr && uvs.size() == vertices.size()) {
      colors.push_back(texture->MeanOverTriangle(uvs[t[0]], uvs[t[1]], uvs[t[2]]));
    } else if (face_albedo.size() == triangles.size()) {
      colors.push_back(face_albedo[i]);
    } else {
      colors.push_back(albedo);
    }
  }
  return colors;
}

namespace {

void AppendColored(TriangleMesh& self, const TriangleMesh& other, const RigidTransform& X_WO,
                   const Eigen::Vector3f* albedo, const Eigen::Vector3f* other_albedo) {
  if (other.vertices.empty() && other.triangles.empty()) return;
  const bool self_blank = self.vertices.empty() && self.triangles.empty();
  // Colours of the result, decided before the geometry changes.
  enum class Mode { kPlain, kTexture, kFaces };
  Mode mode = Mode::kFaces;
  if (self_blank) {
    mode = other.texture != nullptr                          ? Mode::kTexture
           : !other.face_albedo.empty()                      ? Mode::kFaces
           : (albedo == nullptr || *albedo == *other_albedo) ? Mode::kPlain
                                                             : Mode::kFaces;
  } else if (!self.has_own_colors() && !other.has_own_colors()) {
    mode = (albedo == nullptr || *albedo == *other_albedo) ? Mode::kPlain : Mode::kFaces;
  } else if (self.texture != nullptr && self.texture == other.texture) {
    mode = Mode::kTexture;
  } else if (self.triangles.empty() && other.texture != nullptr) {
    mode = Mode::kTexture;
  }
  const bool keep_uvs = self_blank || (!self.uvs.empty() && !other.uvs.empty()) ||
                        (self.vertices.empty() && !other.uvs.empty());
  if (mode == Mode::kFaces) {
    // Per-triangle colours on both sides; a side without colours of its own needs its albedo.
    const auto faces_of = [&](const TriangleMesh& m, const Eigen::Vector3f* a, const char* which) {
      if (a == nullptr && !m.has_own_colors() && !m.triangles.empty()) {
        throw Error(fmt::format(
            "TriangleMesh::Append: {} has no colours of its own and the other is textured or "
            "per-triangle coloured; merging them needs the objects' albedos (the four-argument "
            "Append)",
            which));
      }
      return m.FaceColors(a != nullptr ? *a : Eigen::Vector3f::Zero());
    };
    std::vector<Eigen::Vector3f> faces = faces_of(self, albedo, "this mesh");
    const std::vector<Eigen::Vector3f> more = faces_of(other, other_albedo, "the appended mesh");
    faces.insert(faces.end(), more.begin(), more.end());
    self.face_albedo = std::move(faces);
    self.texture.reset();
  } else if (mode == Mode::kTexture) {
    self.texture = other.texture != nullptr ? other.texture : self.texture;
    self.face_albedo.clear();
  } else {
    self.texture.reset();
    self.face_albedo.clear();
  }
  if (keep_uvs && (mode == Mode::kTexture || !other.uvs.empty())) {
    self.uvs.insert(self.uvs.end(), other.uvs.begin(), other.uvs.end());
  } else {
    self.uvs.clear();
  }

  const int offset = static_cast<int>(self.vertices.size());
  self.vertices.reserve(self.vertices.size() + other.vertices.size());
  for (const Eigen::Vector3f& v : other.vertices) {
    self.vertices.push_back((X_WO * v.cast<double>()).cast<float>());
  }
  self.triangles.reserve(self.triangles.size() + other.triangles.size());
  for (const Eigen::Vector3i& t : other.triangles) {
    self.triangles.push_back(t + Eigen::Vector3i::Constant(offset));
  }
}

}  // namespace

void TriangleMesh::Append(const TriangleMesh& other, const RigidTransform& X_WO) {
  if (!has_own_colors() && !other.has_own_colors() && uvs.empty() && other.uvs.empty()) {
    // The common case (procedural geometry): vertices and triangles only.
    const int offset = static_cast<int>(vertices.size());
    vertices.reserve(vertices.size() + other.vertices.size());
    for (const Eigen::Vector3f& v : other.vertices) {
      vertices.push_back((X_WO * v.cast<double>()).cast<float>());
    }
    triangles.reserve(triangles.size() + other.triangles.size());
    for (const Eigen::Vector3i& t : other.triangles) {
      triangles.push_back(t + Eigen::Vector3i::Constant(offset));
    }
    return;
  }
  AppendColored(*this, other, X_WO, nullptr, nullptr);
}

void TriangleMesh::Append(const TriangleMesh& other, const RigidTransform& X_WO,
                          const Eigen::Vector3f& albedo, const Eigen::Vector3f& other_albedo) {
  AppendColored(*this, other, X_WO, &albedo, &other_albedo);
}

void TriangleMesh::Transform(const RigidTransform& X_WO) {
  for (Eigen::Vector3f& v : vertices) v = (X_WO * v.cast<double>()).cast<float>();
}

Box3 TriangleMesh::Bounds() const {
  Box3 box;
  for (const Eigen::Vector3f& v : vertices) box.Extend(v.cast<double>());
  return box;
}

/// How far from the origin (the robot's base) a scene's vertex may lie, metres: a robot's scene is
/// metres across; a vertex farther away is a wrong unit or pose, and would overflow the cameras'
/// geometry long before it rendered.
constexpr double kMaxVertexDistanceM = 1e4;

Status TriangleMesh::Validate() const {
  const int n = static_cast<int>(vertices.size());
  for (size_t i = 0; i < vertices.size(); ++i) {
    const Eigen::Vector3f& v = vertices[i];
    if (!v.allFinite()) {
      return InvalidArgumentError(
          fmt::format("mesh vertex {} is not finite: ({}, {}, {})", i, v.x(), v.y(), v.z()));
    }
    if (v.cast<double>().cwiseAbs().maxCoeff() > kMaxVertexDistanceM) {
      return InvalidArgumentError(fmt::format(
          "mesh vertex {} at ({:.6g}, {:.6g}, {:.6g}) m is more than {:g} m from the robot's base: "
          "a scene is in metres (a mesh in millimetres needs scale: 0.001; check its pose)",
          i, v.x(), v.y(), v.z(), kMaxVertexDistanceM));
    }
  }
  for (size_t i = 0; i < triangles.size(); ++i) {
    const Eigen::Vector3i& t = triangles[i];
    if ((t.array() < 0).any() || (t.array() >= n).any()) {
      return InvalidArgumentError(
          fmt::format("mesh triangle {} has index out of range [0, {}): ({}, {}, {})", i, n, t.x(),
                      t.y(), t.z()));
    }
  }
  if (!uvs.empty() && uvs.size() != vertices.size()) {
    return InvalidArgumentError(
        fmt::format("mesh has {} texture coordinates for {} vertices (one per vertex, or none)",
                    uvs.size(), vertices.size()));
  }
  for (size_t i = 0; i < uvs.size(); ++i) {
    if (!uvs[i].allFinite()) {
      return InvalidArgumentError(fmt::format("mesh texture coordinate {} is not finite: ({}, {})",
                                              i, uvs[i].x(), uvs[i].y()));
    }
  }
  if (texture != nullptr) {
    if (uvs.empty() && !vertices.empty()) {
      return InvalidArgumentError(fmt::format("mesh has texture {} but no texture coordinates",
                                              QuoteText(texture->source)));
    }
    AVP_RETURN_IF_ERROR(texture->Validate());
    if (!face_albedo.empty()) {
      return InvalidArgumentError(
          fmt::format("mesh has both texture {} and per-triangle colours (one or the other)",
                      QuoteText(texture->source)));
    }
  }
  if (!face_albedo.empty() && face_albedo.size() != triangles.size()) {
    return InvalidArgumentError(
        fmt::format("mesh has {} per-triangle colours for {} triangles (one per triangle, or none)",
                    face_albedo.size(), triangles.size()));
  }
  for (size_t i = 0; i < face_albedo.size(); ++i) {
    const Eigen::Vector3f& c = face_albedo[i];
    if (!c.allFinite() || (c.array() < 0.0f).any() || (c.array() > 1.0f).any()) {
      return InvalidArgumentError(
          fmt::format("mesh colour of triangle {} is ({}, {}, {}); must be linear RGB in [0, 1]", i,
                      c.x(), c.y(), c.z()));
    }
  }
  return Status::Ok();
}

double Ellipsoid::Implicit(const Eigen::Vector3d& p_W) const {
  const Eigen::Vector3d q = (R_WE.transpose() * (p_W - center_W)).cwiseQuotient(radii);
  return q.squaredNorm() - 1.0;
}

Box3 Ellipsoid::Bounds() const {
  // Half extent along world axis k: sqrt(sum_j (R_kj r_j)^2).
  Eigen::Vector3d half;
  for (int k = 0; k < 3; ++k) half[k] = (R_WE.row(k).transpose().cwiseProduct(radii)).norm();
  return Box3::FromCenterAndHalfSize(center_W, half);
}

Box3 SceneObject::Bounds() const {
  return std::visit([](const auto& s) { return s.Bounds(); }, shape);
}

size_t SceneObject::num_triangles() const {
  if (const auto* mesh = std::get_if<TriangleMesh>(&shape)) return mesh->num_triangles();
  return 0;
}

uint16_t Scene::Add(SceneObject object) {
  uint16_t max_id = 0;
  for (const SceneObject& o : objects) max_id = std::max(max_id, o.instance_id);
  const size_t next = static_cast<size_t>(max_id) + 1;
  AVP_THROW_UNLESS(next <= std::numeric_limits<uint16_t>::max(), next, objects.size());
  object.instance_id = static_cast<uint16_t>(next);
  objects.push_back(std::move(object));
  return objects.back().instance_id;
}

uint16_t Scene::Add(std::string object_name, SemanticClass semantic_class,
                    const Eigen::Vector3f& albedo, std::variant<TriangleMesh, Ellipsoid> shape) {
  SceneObject object;
  object.name = std::move(object_name);
  object.semantic_class = semantic_class;
  object.albedo = albedo;
  object.shape = std::move(shape);
  return Add(std::move(object));
}

std::vector<FruitTruth> Scene::Fruits() const {
  std::vector<FruitTruth> fruits;
  for (const SceneObject& o : objects) {
    if (o.semantic_class != SemanticClass::kFruit) continue;
    FruitTruth f;
    f.instance_id = o.instance_id;
    f.name = o.name;
    if (const auto* e = std::get_if<Ellipsoid>(&o.shape)) {
      f.center_W = e->center_W;
      f.radii = e->radii;
    } else {
      const Box3 b = o.Bounds();
      f.center_W = b.center();
      f.radii = 0.5 * b.size();
    }
    fruits.push_back(std::move(f));
  }
  std::sort(fruits.begin(), fruits.end(),
            [](const FruitTruth& a, const FruitTruth& b) { return a.instance_id < b.instance_id; });
  return fruits;
}

size_t Scene::num_triangles() const {
  size_t n = 0;
  for (const SceneObject& o : objects) n += o.num_triangles();
  return n;
}

const SceneObject* Scene::FindInstance(uint16_t instance_id) const {
  for (const SceneObject& o : objects) {
    if (o.instance_id == instance_id) return &o;
  }
  return nullptr;
}

void Scene::UpdatePlantBounds() {
  plant_bounds = Box3();
  for (const SceneObject& o : objects) {
    if (o.semantic_class == SemanticClass::kGround ||
        o.semantic_class == SemanticClass::kBackground) {
      continue;
    }
    plant_bounds.Extend(o.Bounds());
  }
}

Status Scene::Validate() const {
  // Names come from files (mesh nodes, scene files): quoted escaped in messages.
  std::unordered_set<uint16_t> ids;
  for (const SceneObject& o : objects) {
    if (o.instance_id == 0) {
      return InvalidArgumentError(
          fmt::format("scene {}: object {} has instance id 0 (reserved "
                      "for background)",
                      QuoteText(name), QuoteText(o.name)));
    }
    if (!ids.insert(o.instance_id).second) {
      return InvalidArgumentError(fmt::format("scene {}: instance id {} is used twice (object {})",
                                              QuoteText(name), o.instance_id, QuoteText(o.name)));
    }
    if (const auto* mesh = std::get_if<TriangleMesh>(&o.shape)) {
      AVP_RETURN_IF_ERROR(mesh->Validate().WithContext(
          fmt::format("scene {}, object {}", QuoteText(name), QuoteText(o.name))));
    } else {
      const Ellipsoid& e = std::get<Ellipsoid>(o.shape);
      if (!e.center_W.allFinite() || !e.radii.allFinite() || (e.radii.array() <= 0.0).any()) {
        return InvalidArgumentError(fmt::format(
            "scene {}, object {}: ellipsoid centre ({}, {}, {}) radii ({}, {}, {}) must be "
            "finite with radii > 0",
            QuoteText(name), QuoteText(o.name), e.center_W.x(), e.center_W.y(), e.center_W.z(),
            e.radii.x(), e.radii.y(), e.radii.z()));
      }
    }
  }
  return Status::Ok();
}

std::string DescribeDifference(const Scene& a, const Scene& b) {
  if (a.objects.size() != b.objects.size()) {
    return fmt::format("{} objects vs {}", a.objects.size(), b.objects.size());
  }
  for (size_t i = 0; i < a.objects.size(); ++i) {
    const SceneObject& x = a.objects[i];
    const SceneObject& y = b.objects[i];
    if (x.name != y.name || x.semantic_class != y.semantic_class ||
        x.instance_id != y.instance_id || x.albedo != y.albedo ||
        x.shape.index() != y.shape.index()) {
      return fmt::format("object {}: '{}' vs '{}'", i, x.name, y.name);
    }
    if (const auto* m = std::get_if<TriangleMesh>(&x.shape)) {
      const TriangleMesh& n = std::get<TriangleMesh>(y.shape);
      if (m->vertices != n.vertices || m->triangles != n.triangles) {
        return fmt::format("object {}: mesh of '{}' differs", i, x.name);
      }
      if (m->uvs != n.uvs || m->face_albedo != n.face_albedo) {
        return fmt::format("object {}: texture coordinates or triangle colours of '{}' differ", i,
                           x.name);
      }
      if ((m->texture == nullptr) != (n.texture == nullptr) ||
          (m->texture != nullptr && m->texture != n.texture &&
           (m->texture->image != n.texture->image || m->texture->factor != n.texture->factor))) {
        return fmt::format("object {}: texture of '{}' differs", i, x.name);
      }
    } else {
      const Ellipsoid& e = std::get<Ellipsoid>(x.shape);
      const Ellipsoid& f = std::get<Ellipsoid>(y.shape);
      if (e.center_W != f.center_W || e.radii != f.radii || e.R_WE != f.R_WE) {
        return fmt::format("object {}: ellipsoid '{}' differs", i, x.name);
      }
    }
  }
  return {};
}

}  // namespace avp::sim
