// RGB-D + label rendering cost of the Embree camera (sim::RgbdRenderer).
//
// Cases (each at 1 and 2 render threads; wall-clock time per 640x480 frame):
//   BM_RenderDefaultScenario    the default scenario, from its X_WC_start
//   BM_RenderSyntheticPlant     the seeded benchmark plant of docs/performance.md: 1 m stem
//                               (r = 6 mm), 60 cupped disc leaves (r = 25-60 mm), 10 fruits
//                               (r = 22-35 mm) on a floor; fruits analytic (arg fruits = 0) or
//                               tessellated as 20 480-triangle icospheres (fruits = 1)
//   BM_RenderSyntheticPlantMergedPerClass  the same plant with one mesh per class (layout check)
//   BM_RenderPacketSize         the synthetic plant at 1 thread, by ray packet size (1/4/8/16)
//   BM_BuildRenderer            BVH build time for the synthetic plant
// Counters: triangles and ellipsoids in the BVH, valid-depth pixels, Mrays/s (primary rays).
// Target (docs/performance.md context, 2 vCPUs): <= 25 ms per frame with 2 threads.

#include <cmath>
#include <map>
#include <string>

#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <avp/core/rng.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>

namespace avp::sim {
namespace {

// ---- The synthetic plant ---------------------------------------------------------------------

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

/// The seeded benchmark plant; the camera ring of docs/performance.md looks at it.
Scene SyntheticPlant(bool tessellated_fruits, uint64_t seed = 1) {
  Rng rng(seed);
  Scene scene;
  scene.name = tessellated_fruits ? "synthetic-plant-mesh-fruits" : "synthetic-plant";
  TriangleMesh floor;
  floor.vertices = {{-3, -3, 0}, {3, -3, 0}, {3, 3, 0}, {-3, 3, 0}};
  floor.triangles = {{0, 1, 2}, {0, 2, 3}};
  scene.Add(Object("floor", SemanticClass::kGround, {0.35f, 0.3f, 0.25f}, floor));
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

// ---- Benchmarks ------------------------------------------------------------------------------

/// User + system CPU seconds of the whole process (every thread).
double ProcessCpuSeconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
}

void RunRender(benchmark::State& state, const Scene& scene, int threads, int packet) {
  RendererOptions options;
  options.num_threads = threads;
  options.ray_packet_size = packet;
  const RgbdRenderer renderer(scene, options);
  const CameraIntrinsics K = CameraIntrinsics::RealSenseD435();
  size_t valid = 0;
  const double cpu_start_s = ProcessCpuSeconds();
  for (auto _ : state) {
    RenderedFrame frame = renderer.Render(K, scene.X_WC_start);
    benchmark::DoNotOptimize(frame.rgbd.depth_m.data().data());
    valid = 0;
    for (float z : frame.rgbd.depth_m.data()) valid += z > 0.0f;
  }
  // CPU time of all threads per frame: on idle cores, wall time ~ this / threads. The machine
  // these were tuned on is shared, so wall time alone over-states the cost when it is busy.
  state.counters["cpu_ms_all_threads"] =
      1e3 * (ProcessCpuSeconds() - cpu_start_s) / static_cast<double>(state.iterations());
  const double pixels = static_cast<double>(K.width) * K.height;
  state.counters["threads"] = threads;
  state.counters["packet"] = renderer.ray_packet_size();
  state.counters["triangles"] = static_cast<double>(renderer.num_triangles());
  state.counters["ellipsoids"] = static_cast<double>(renderer.num_ellipsoids());
  state.counters["valid_px"] = static_cast<double>(valid);
  state.counters["Mrays/s"] =
      benchmark::Counter(pixels * 1e-6, benchmark::Counter::kIsIterationInvariantRate);
}

void BM_RenderDefaultScenario(benchmark::State& state) {
  const Result<Scene> scene = MakeScenario(DefaultScenarioName(), 0);
  if (!scene.ok()) {
    state.SkipWithError(scene.status().ToString().c_str());
    return;
  }
  RunRender(state, *scene, static_cast<int>(state.range(0)), 8);
  state.SetLabel(scene->name);
}
BENCHMARK(BM_RenderDefaultScenario)
    ->ArgName("threads")
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_RenderSyntheticPlant(benchmark::State& state) {
  const Scene scene = SyntheticPlant(state.range(1) != 0);
  RunRender(state, scene, static_cast<int>(state.range(0)), 8);
  state.SetLabel(scene.name);
}
BENCHMARK(BM_RenderSyntheticPlant)
    ->ArgNames({"threads", "mesh_fruits"})
    ->ArgsProduct({{1, 2}, {0, 1}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

/// The synthetic plant with every mesh of a class merged into one object: measures the cost of one
/// Embree geometry per object (the renderer's layout) against one per class.
Scene MergedPerClass(const Scene& scene) {
  Scene merged;
  merged.name = scene.name + "-merged-per-class";
  merged.X_WC_start = scene.X_WC_start;
  std::map<SemanticClass, SceneObject> by_class;
  for (const SceneObject& o : scene.objects) {
    if (!std::holds_alternative<TriangleMesh>(o.shape)) {
      merged.Add(o);
      continue;
    }
    auto [it, inserted] = by_class.try_emplace(o.semantic_class, o);
    if (!inserted) {
      std::get<TriangleMesh>(it->second.shape).Append(std::get<TriangleMesh>(o.shape));
    }
  }
  for (auto& [cls, o] : by_class) merged.Add(std::move(o));
  return merged;
}

void BM_RenderSyntheticPlantMergedPerClass(benchmark::State& state) {
  const Scene scene = MergedPerClass(SyntheticPlant(false));
  RunRender(state, scene, static_cast<int>(state.range(0)), 8);
  state.counters["objects"] = static_cast<double>(scene.objects.size());
}
BENCHMARK(BM_RenderSyntheticPlantMergedPerClass)
    ->ArgName("threads")
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_RenderPacketSize(benchmark::State& state) {
  const Scene scene = SyntheticPlant(false);
  RunRender(state, scene, 1, static_cast<int>(state.range(0)));
}
BENCHMARK(BM_RenderPacketSize)
    ->ArgName("packet")
    ->Arg(1)
    ->Arg(4)
    ->Arg(8)
    ->Arg(16)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_BuildRenderer(benchmark::State& state) {
  const Scene scene = SyntheticPlant(state.range(0) != 0);
  for (auto _ : state) {
    RgbdRenderer renderer(scene);
    benchmark::DoNotOptimize(renderer.num_triangles());
  }
  state.counters["triangles"] = static_cast<double>(scene.num_triangles());
}
BENCHMARK(BM_BuildRenderer)
    ->ArgName("mesh_fruits")
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace avp::sim
