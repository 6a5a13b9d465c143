#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_set>

#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/core/text.h>
#include <avp/sim/scene.h>

namespace avp::sim {

void TriangleMesh::Append(const TriangleMesh& other, const RigidTransform& X_WO) {
  const int offset = static_cast<int>(vertices.size());
  vertices.reserve(vertices.size() + other.vertices.size());
  for (const Eigen::Vector3f& v : other.vertices) {
    vertices.push_back((X_WO * v.cast<double>()).cast<float>());
  }
  triangles.reserve(triangles.size() + other.triangles.size());
  for (const Eigen::Vector3i& t : other.triangles) {
    triangles.push_back(t + Eigen::Vector3i::Constant(offset));
  }
}

void TriangleMesh::Transform(const RigidTransform& X_WO) {
  for (Eigen::Vector3f& v : vertices) v = (X_WO * v.cast<double>()).cast<float>();
}

Box3 TriangleMesh::Bounds() const {
  Box3 box;
  for (const Eigen::Vector3f& v : vertices) box.Extend(v.cast<double>());
  return box;
}

Status TriangleMesh::Validate() const {
  const int n = static_cast<int>(vertices.size());
  for (size_t i = 0; i < vertices.size(); ++i) {
    if (!vertices[i].allFinite()) {
      return InvalidArgumentError(fmt::format("mesh vertex {} is not finite: ({}, {}, {})", i,
                                              vertices[i].x(), vertices[i].y(), vertices[i].z()));
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
