#include "synthetic_plant.h"

#include <cmath>
#include <string>
#include <utility>
#include <variant>

#include <Eigen/Geometry>

#include <avp/core/rng.h>
#include <avp/sim/mesh_builder.h>

namespace avp::bench {
namespace {

using sim::Ellipsoid;
using sim::MakeIcosphere;
using sim::Scene;
using sim::SceneObject;
using sim::TriangleMesh;

TriangleMesh Cylinder(const Eigen::Vector3d& base, double height, double radius, int sides,
                      int rings) {
  TriangleMesh m;
  for (int k = 0; k <= rings; ++k) {
    for (int i = 0; i < sides; ++i) {
      const double a = 2.0 * M_PI * i / sides;
      m.vertices.push_back(
          (base + Eigen::Vector3d(radius * std::cos(a), radius * std::sin(a), height * k / rings))
              .cast<float>());
    }
  }
  for (int k = 0; k < rings; ++k) {
    for (int i = 0; i < sides; ++i) {
      const int a = k * sides + i;
      const int b = k * sides + (i + 1) % sides;
      m.triangles.emplace_back(a, b, b + sides);
      m.triangles.emplace_back(a, b + sides, a + sides);
    }
  }
  return m;
}

/// A cupped disc leaf of radius r centred at `centre`, tilted by R, tessellated in polar rings.
TriangleMesh Leaf(const Eigen::Vector3d& centre, const Eigen::Matrix3d& R, double r, int rings,
                  int sectors) {
  TriangleMesh m;
  m.vertices.push_back(centre.cast<float>());
  for (int k = 1; k <= rings; ++k) {
    const double rho = r * k / rings;
    for (int i = 0; i < sectors; ++i) {
      const double a = 2.0 * M_PI * i / sectors;
      const Eigen::Vector3d p_L(rho * std::cos(a), rho * std::sin(a),
                                0.25 * rho * rho / r);  // cupped
      m.vertices.push_back((centre + R * p_L).cast<float>());
    }
  }
  for (int i = 0; i < sectors; ++i) m.triangles.emplace_back(0, 1 + i, 1 + (i + 1) % sectors);
  for (int k = 1; k < rings; ++k) {
    const int inner = 1 + (k - 1) * sectors;
    const int outer = 1 + k * sectors;
    for (int i = 0; i < sectors; ++i) {
      const int j = (i + 1) % sectors;
      m.triangles.emplace_back(inner + i, outer + i, outer + j);
      m.triangles.emplace_back(inner + i, outer + j, inner + j);
    }
  }
  return m;
}

/// Icosphere of radius r about `centre` (the mesh builder's tessellation, moved).
TriangleMesh Icosphere(const Eigen::Vector3d& centre, double r, int levels) {
  TriangleMesh mesh = MakeIcosphere(r, levels);
  mesh.Transform(RigidTransform(centre));
  return mesh;
}

SceneObject Object(std::string name, SemanticClass cls, Eigen::Vector3f albedo,
                   std::variant<TriangleMesh, Ellipsoid> shape) {
  SceneObject o;
  o.name = std::move(name);
  o.semantic_class = cls;
  o.albedo = albedo;
  o.shape = std::move(shape);
  return o;
}

/// A square of half size `half` in the z = 0 plane, centred on the origin.
TriangleMesh Square(float half) {
  TriangleMesh m;
  m.vertices = {{-half, -half, 0}, {half, -half, 0}, {half, half, 0}, {-half, half, 0}};
  m.triangles = {{0, 1, 2}, {0, 2, 3}};
  return m;
}

const char* BackgroundName(PlantBackground background) {
  switch (background) {
    case PlantBackground::kFloor:
      return "synthetic-plant";
    case PlantBackground::kTableTop:
      return "synthetic-plant-table-top";
    case PlantBackground::kFloorAndBackdrop:
      return "synthetic-plant-backdrop";
  }
  return "synthetic-plant";
}

}  // namespace

Scene SyntheticPlant(PlantBackground background, bool tessellated_fruits, uint64_t seed) {
  Rng rng(seed);
  Scene scene;
  scene.name = std::string(BackgroundName(background)) + (tessellated_fruits ? "-mesh-fruits" : "");
  scene.seed = seed;
  switch (background) {
    case PlantBackground::kFloor:
      scene.Add(Object("floor", SemanticClass::kGround, {0.35f, 0.3f, 0.25f}, Square(3.0)));
      break;
    case PlantBackground::kTableTop:
      scene.Add(Object("table", SemanticClass::kGround, {0.55f, 0.45f, 0.35f}, Square(0.45)));
      break;
    case PlantBackground::kFloorAndBackdrop:
      scene.Add(Object("floor", SemanticClass::kGround, {0.35f, 0.3f, 0.25f}, Square(40.0)));
      scene.Add(Object("backdrop", SemanticClass::kOther, {0.6f, 0.6f, 0.65f},
                       Cylinder(Eigen::Vector3d::Zero(), 3.0, 0.9, 256, 1)));
      break;
  }
  scene.Add(Object("stem", SemanticClass::kStem, {0.25f, 0.45f, 0.15f},
                   Cylinder(Eigen::Vector3d::Zero(), 1.0, 0.006, 24, 100)));
  for (int i = 0; i < 60; ++i) {
    const double z = rng.Uniform(0.15, 0.95);
    const double yaw = rng.Uniform(0.0, 2.0 * M_PI);
    const double r = rng.Uniform(0.025, 0.06);
    const Eigen::Vector3d out(std::cos(yaw), std::sin(yaw), 0.0);
    const Eigen::Vector3d centre = Eigen::Vector3d(0, 0, z) + (0.006 + r) * out;
    const Eigen::Matrix3d R = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(rng.Uniform(-0.6, 0.6), Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(rng.Uniform(-0.3, 0.3), Eigen::Vector3d::UnitX()))
                                  .toRotationMatrix();
    scene.Add(Object("leaf" + std::to_string(i), SemanticClass::kLeaf, {0.15f, 0.5f, 0.12f},
                     Leaf(centre, R, r, 6, 32)));
  }
  for (int i = 0; i < 10; ++i) {
    const double z = rng.Uniform(0.2, 0.8);
    const double yaw = rng.Uniform(0.0, 2.0 * M_PI);
    const double r = rng.Uniform(0.022, 0.035);
    const Eigen::Vector3d c =
        Eigen::Vector3d(0, 0, z) + (0.01 + r) * Eigen::Vector3d(std::cos(yaw), std::sin(yaw), 0);
    const Eigen::Vector3f albedo(0.75f, 0.08f, 0.05f);
    if (tessellated_fruits) {
      scene.Add(
          Object("fruit" + std::to_string(i), SemanticClass::kFruit, albedo, Icosphere(c, r, 5)));
    } else {
      Ellipsoid e;
      e.center_W = c;
      e.radii = Eigen::Vector3d::Constant(r);
      scene.Add(Object("fruit" + std::to_string(i), SemanticClass::kFruit, albedo, e));
    }
  }
  scene.UpdatePlantBounds();
  scene.X_WC_start =
      RigidTransform::LookAt(Eigen::Vector3d(0.6, 0.0, 0.55), Eigen::Vector3d(0.0, 0.0, 0.5));
  return scene;
}

}  // namespace avp::bench
