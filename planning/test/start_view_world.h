#pragma once
// A planner test's world: the map of a built-in scenario after its start view (perfect masks,
// projective carving), the arm and the request the loop makes for the second view. Shared by the
// avp-nbv and learned-gain tests.

#include <memory>
#include <string>

#include <avp/core/camera.h>
#include <avp/core/segmentation.h>
#include <avp/mapping/integrator.h>
#include <avp/mapping/semantic_map.h>
#include <avp/planning/view_planner.h>
#include <avp/robot/arm_model.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>

namespace avp::planning::test {

struct StartViewWorld {
  robot::ArmModel arm;
  sim::Scene scene;
  mapping::SemanticMap map;
  Eigen::VectorXd q0;
  RigidTransform X0;

  /// The request for view 1 of 8, the ROI the plant's bounds + 5 cm.
  PlanningRequest Request() const {
    PlanningRequest r;
    r.map = &map;
    r.arm = &arm;
    r.q_current = r.q_start = q0;
    r.X_WC_current = r.X_WC_start = X0;
    r.K = CameraIntrinsics::RealSenseD435();
    r.roi = scene.plant_bounds.Inflated(0.05);
    r.view_index = 1;
    r.views_total = 8;
    r.fused_views = {X0};
    return r;
  }
};

/// The world of `scenario` (seed `seed`) with a map of `voxel_m` voxels; nullptr (and a
/// message in `error`) when the arm, the scene or the integration fails.
inline std::unique_ptr<StartViewWorld> MakeStartViewWorld(const std::string& scenario,
                                                          uint64_t seed, double voxel_m,
                                                          std::string* error) {
  Result<robot::ArmModel> arm = robot::LoadDefaultArm();
  Result<sim::Scene> scene = sim::MakeScenario(scenario, seed);
  if (!arm.ok() || !scene.ok()) {
    *error = !arm.ok() ? arm.status().ToString() : scene.status().ToString();
    return nullptr;
  }
  mapping::MapOptions mo;
  mo.grid.voxel_size_m = voxel_m;
  auto w = std::unique_ptr<StartViewWorld>(
      new StartViewWorld{*arm, *scene, mapping::SemanticMap(mo), {}, {}});
  const sim::RgbdRenderer renderer(w->scene);
  w->q0 = Eigen::Map<const Eigen::VectorXd>(w->scene.start_joints_rad.data(), 6);
  w->X0 = w->arm.CameraPose(w->q0);
  const sim::RenderedFrame f = renderer.Render(CameraIntrinsics::RealSenseD435(), w->X0, 0);
  const Segmentation seg = Segmentation::FromLabelImages(f.instance_ids, f.class_ids, 0.8f);
  mapping::IntegratorOptions io;
  io.carving = mapping::FreeSpaceCarving::kProjective;
  const auto integrated = mapping::Integrator(io).Integrate(f.rgbd, &seg, w->map);
  if (!integrated.ok()) {
    *error = integrated.status().ToString();
    return nullptr;
  }
  return w;
}

}  // namespace avp::planning::test
