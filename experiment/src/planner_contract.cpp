#include <fmt/format.h>

#include <avp/core/segmentation.h>
#include <avp/experiment/planner_contract.h>
#include <avp/pipeline/view_fusion.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scenario.h>

namespace avp::experiment {

Result<std::unique_ptr<ContractWorld>> MakeContractWorld() {
  auto w = std::make_unique<ContractWorld>();
  AVP_ASSIGN_OR_RETURN(robot::ArmModel arm, robot::LoadDefaultArm());
  w->arm = std::make_unique<robot::ArmModel>(std::move(arm));
  AVP_ASSIGN_OR_RETURN(sim::Scene scene, sim::MakeScenario("tomato-multiple-clusters", 1));
  w->scene = std::make_unique<sim::Scene>(std::move(scene));
  w->map = std::make_unique<mapping::SemanticMap>(mapping::MapOptions{});
  w->q0 = Eigen::Map<const Eigen::VectorXd>(
      w->scene->start_joints_rad.data(),
      static_cast<Eigen::Index>(w->scene->start_joints_rad.size()));
  w->X0 = w->arm->CameraPose(w->q0);
  const sim::RgbdRenderer renderer(*w->scene);
  sim::RenderedFrame f = renderer.Render(CameraIntrinsics::RealSenseD435(), w->X0, 0);
  Segmentation seg = Segmentation::FromLabelImages(f.instance_ids, f.class_ids, 0.8f);
  // Fused as every view is (pipeline::ViewFusion), with the simulator's labels as the masks.
  pipeline::EpisodeOptions options;
  options.integrator.carving = mapping::FreeSpaceCarving::kProjective;
  pipeline::ViewFusion fusion(*w->map, options);
  pipeline::StepRecord step;
  pipeline::ViewSeen seen;
  fusion.Fuse(robot::Observation{std::move(f.rgbd), std::nullopt}, std::move(seg), step, seen);
  AVP_RETURN_IF_ERROR(step.integrate_status);
  return w;
}

planning::PlanningRequest ContractRequest(const ContractWorld& w) {
  planning::PlanningRequest r;
  r.map = w.map.get();
  r.arm = w.arm.get();
  r.q_current = r.q_start = w.q0;
  r.X_WC_current = r.X_WC_start = w.X0;
  r.K = CameraIntrinsics::RealSenseD435();
  r.roi = w.scene->plant_bounds.Inflated(0.05);
  r.view_index = 1;
  r.views_total = 8;
  r.fused_views = {w.X0};
  r.prompt = "tomato";
  return r;
}

namespace {

/// The checks of one ranked candidate against the same one of the second plan.
void CheckRanked(const planning::PlanResult& a, const planning::PlanResult& b, size_t i,
                 const ContractWorld& w, std::vector<std::string>& out) {
  const planning::ViewCandidate& v = a.ranked[i];
  if (v.X_WC.translation() != b.ranked[i].X_WC.translation() ||
      !(v.utility == b.ranked[i].utility)) {
    out.push_back(fmt::format("candidate {} differs between two plans with the same seed", i));
  }
  if (!v.reachable) out.push_back(fmt::format("candidate {} is ranked but not reachable", i));
  if (v.q.size() != w.arm->num_joints() || !w.arm->WithinLimits(v.q)) {
    out.push_back(fmt::format("candidate {}: joints missing or outside the limits", i));
    return;
  }
  const double error = (w.arm->CameraPose(v.q).translation() - v.X_WC.translation()).norm();
  if (error >= 2e-3) {
    out.push_back(fmt::format("candidate {}: its joints put the camera {:.1f} mm from its pose", i,
                              error * 1e3));
  }
  if (planning::IsNearAny(v.X_WC, {w.X0})) {
    out.push_back(fmt::format("candidate {} is the view already fused", i));
  }
  if (i > 0 && v.utility > a.ranked[i - 1].utility) {
    out.push_back(
        fmt::format("candidate {}'s utility ({}) is above candidate {}'s ({}): ranked "
                    "best first means utilities do not rise",
                    i, v.utility, i - 1, a.ranked[i - 1].utility));
  }
}

/// A bad request must be a status: `what` names it.
void CheckBadRequest(planning::ViewPlanner& planner, const planning::PlanningRequest& r,
                     const char* what, std::vector<std::string>& out) {
  Rng rng(1);
  try {
    const planning::PlanResult res = planner.Plan(r, rng);
    if (res.status.ok()) out.push_back(fmt::format("a request {} was answered OK", what));
    if (!res.ranked.empty()) out.push_back(fmt::format("a request {} got candidates", what));
  } catch (const std::exception& e) {
    out.push_back(
        fmt::format("a request {} threw instead of answering a status: {}", what, e.what()));
  }
}

}  // namespace

std::vector<std::string> PlannerContractViolations(planning::ViewPlanner& planner,
                                                   const ContractWorld& w) {
  std::vector<std::string> out;
  Rng ra(21), rb(21);
  planning::PlanResult a, b;
  try {
    a = planner.Plan(ContractRequest(w), ra);
    b = planner.Plan(ContractRequest(w), rb);
  } catch (const std::exception& e) {
    out.push_back(fmt::format("planning threw: {}", e.what()));
    return out;
  }
  if (!a.status.ok()) out.push_back(fmt::format("the plan failed: {}", a.status.ToString()));
  if (a.ranked.empty()) out.push_back("the plan ranked no candidate");
  if (a.generated < a.reachable || a.reachable < a.ranked.size()) {
    out.push_back(fmt::format("counts out of order: {} generated, {} reachable, {} ranked",
                              a.generated, a.reachable, a.ranked.size()));
  }
  if (a.ranked.size() != b.ranked.size()) {
    out.push_back(fmt::format("two plans with the same seed ranked {} and {} candidates",
                              a.ranked.size(), b.ranked.size()));
  }
  for (size_t i = 0; i < a.ranked.size() && i < b.ranked.size(); ++i) CheckRanked(a, b, i, w, out);
  planning::PlanningRequest r = ContractRequest(w);
  r.map = nullptr;
  CheckBadRequest(planner, r, "without a map", out);
  r = ContractRequest(w);
  r.q_current = Eigen::VectorXd::Zero(3);
  CheckBadRequest(planner, r, "with 3 joints for a 6-joint arm", out);
  return out;
}

}  // namespace avp::experiment
