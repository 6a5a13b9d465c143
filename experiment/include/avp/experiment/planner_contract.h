#pragma once

// The planner contract (docs/extending.md, "The planner contract"): what every planner a user
// picks by name must do, checked on the map a real episode has after its start view. The C++
// planners' suite (tests/planner_contract_test.cpp) and avp.check_planner (Python planners,
// docs/python.md) run the same checks from here.

#include <memory>
#include <string>
#include <vector>

#include <avp/core/status.h>
#include <avp/mapping/semantic_map.h>
#include <avp/planning/view_planner.h>
#include <avp/robot/arm_model.h>
#include <avp/sim/scene.h>

namespace avp::experiment {

/// The contract's world: the default arm, tomato-multiple-clusters seed 1, and the map after its
/// start view (rendered, labelled by the simulator, fused with projective carving).
struct ContractWorld {
  std::unique_ptr<robot::ArmModel> arm;
  std::unique_ptr<sim::Scene> scene;
  std::unique_ptr<mapping::SemanticMap> map;
  Eigen::VectorXd q0;
  RigidTransform X0;
};

/// Builds it (a second or so). Errors: the arm's or the scene's.
Result<std::unique_ptr<ContractWorld>> MakeContractWorld();

/// The request of the episode's first plan: view 1 of 8, the start view fused, the plant's
/// bounds inflated by 5 cm as the region of interest.
planning::PlanningRequest ContractRequest(const ContractWorld& world);

/// Every way `planner` breaks the contract on `world`, one sentence each (empty: it keeps it):
///   - planned twice with Rng(21), it answers OK with at least one candidate, the same
///     candidates (poses and utilities) both times, generated >= reachable >= ranked;
///   - every ranked candidate is reachable, its joints are within the limits and put the camera
///     within 2 mm of the candidate's pose, it is not a fused view, and utilities do not rise;
///   - a request without a map, or with joints of the wrong size, is answered with a status,
///     neither an exception nor a candidate.
std::vector<std::string> PlannerContractViolations(planning::ViewPlanner& planner,
                                                   const ContractWorld& world);

}  // namespace avp::experiment
