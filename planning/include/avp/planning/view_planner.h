#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/core/camera.h>
#include <avp/core/rng.h>
#include <avp/core/semantic_class.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/mapping/semantic_map.h>
#include <avp/motion/collision_checker.h>
#include <avp/robot/arm_model.h>

namespace avp::planning {

/// One candidate camera view.
struct ViewCandidate {
  /// Camera optical frame pose in the world (robot base) frame.
  RigidTransform X_WC;
  /// Joints that reach X_WC (URDF convention); empty when the candidate was not IK-checked.
  Eigen::VectorXd q;
  /// IK found joints within the limits (and, with a collision checker, joints free of collision).
  bool reachable = false;
  /// IK found joints, but the arm there is in collision (PlanningRequest::collision): dropped.
  bool in_collision = false;
  /// Expected information gain (the planner's own units; bits for the entropy-based planners).
  double gain = 0.0;
  /// Motion cost: Euclidean joint-space distance |q - q_current| (radians).
  double cost = 0.0;
  /// What the planner ranks by (higher is better).
  double utility = 0.0;
  /// Where the candidate came from: "fruit-shell", "frontier", "roi", "grid", "waypoint", ...
  std::string source;
  /// The gain by part (name, the planner's units), summing to `gain`, when the planner records
  /// them (avp-nbv's record_gain_terms); empty otherwise.
  std::vector<std::pair<std::string, double>> gain_terms;
};

/// Everything a planner may look at to choose the next view. Pointers are non-owning and
/// required unless stated otherwise.
struct PlanningRequest {
  const mapping::SemanticMap* map = nullptr;
  const robot::ArmModel* arm = nullptr;
  /// Current joints and the camera pose they give.
  Eigen::VectorXd q_current;
  RigidTransform X_WC_current;
  /// Joints and camera pose of the episode's first view (the reference planner samples around it).
  Eigen::VectorXd q_start;
  RigidTransform X_WC_start;
  /// The camera: its true field of view is used for ray casting.
  CameraIntrinsics K;
  /// The plant's region of interest in the world frame (scene plant bounds, or configured).
  Box3 roi;
  /// Index of the view to choose: 1 for the second fused view (view 0 is the start view).
  int view_index = 1;
  /// Total fused views of the episode (the budget).
  int views_total = 8;
  /// Camera poses already fused, in order (never re-chosen by the planners).
  std::vector<RigidTransform> fused_views;
  /// The class the prompt names.
  SemanticClass target_class = SemanticClass::kFruit;
  /// The text prompt itself ("tomato"; planners written in Python see it, docs/python.md).
  std::string prompt;
  /// The world the arm may not touch (the map's obstacles, declared objects, itself), or null:
  /// then IK is the only filter. Candidates whose IK joints collide are dropped before scoring.
  const motion::CollisionChecker* collision = nullptr;
  /// With `collision`: a candidate whose joints collide is moved back along its optical axis, in
  /// steps of 5 cm up to this far (metres), keeping its viewing direction, to the first pose
  /// where IK finds free joints and the camera stands in space the map has seen free (no point
  /// within kSeenClearance_m of the eye inside the ROI unseen or occupied): the view from a step
  /// further away. 0: a colliding candidate is dropped at once.
  double collision_step_back_m = 0.0;
};

/// The ball about a stepped-back camera's eye that must lie in seen free space (inside the ROI):
/// the camera's body (the D435 reaches 6 cm from its optical frame) and the 2 cm margin.
inline constexpr double kSeenClearance_m = 0.08;

/// A planner's answer.
struct PlanResult {
  /// OK when `ranked` holds at least one reachable candidate; NotFound ("no valid candidate")
  /// otherwise, naming how many were generated and why they were dropped.
  Status status;
  /// Reachable candidates, best first (the loop tries them in order until one move succeeds).
  std::vector<ViewCandidate> ranked;
  /// Candidates generated, how many of them passed the reachability check, and how many IK
  /// reached but the collision check dropped.
  size_t generated = 0;
  size_t reachable = 0;
  size_t in_collision = 0;
  /// The planner's stopping rule fired (e.g. best gain below a threshold): the loop ends early.
  bool stop = false;
  std::string stop_reason;
  /// What the planner wants a person to know about this step (e.g. a learned gain that failed
  /// and the hand-written gain it fell back to); logged and kept in record.json.
  std::vector<std::string> warnings;
};

/// Chooses the next camera view. Implementations must be deterministic given the request and
/// the state of `rng`, must never return an unreachable candidate in `ranked`, and report "no
/// valid candidate" as a status, never by throwing.
class ViewPlanner {
 public:
  virtual ~ViewPlanner() = default;
  /// "predefined", "reference-nbv", "avp-nbv", "random", "isler-oa", ...
  virtual std::string_view name() const = 0;
  virtual PlanResult Plan(const PlanningRequest& request, Rng& rng) = 0;
};

/// Checks a request's pointers, joint sizes, intrinsics and ROI; InvalidArgument naming the bad
/// field otherwise.
Status ValidateRequest(const PlanningRequest& request);

/// Horizontal distance of `p` from the plant's core: the ROI's medial axis in the horizontal
/// plane, a vertical segment through the ROI's centre along its longer horizontal side, as long
/// as that side minus the shorter one. For a square ROI (a tomato plant) it is the vertical axis
/// through the centre (the stem); for a long, thin one (an espalier) the wall's mid-plane.
double PlantCoreDistance(const Eigen::Vector3d& p, const Box3& roi);

/// With request.collision, moves every reachable candidate whose joints are in collision back
/// along its optical axis (PlanningRequest::collision_step_back_m; its pose, joints and cost
/// change), and marks those that stay in collision unreachable and in_collision (in parallel,
/// deterministic); returns how many. Without a collision checker, 0.
size_t DropCollidingCandidates(const PlanningRequest& request,
                               std::vector<ViewCandidate>& candidates);

/// True when every point within `radius` of `p` (sampled every centimetre) that lies inside
/// `roi` is in a voxel the map has seen free.
bool InSeenFreeSpace(const mapping::OccupancyGrid& grid, const Box3& roi, const Eigen::Vector3d& p,
                     double radius);

/// Sorts by utility (descending; ties by lower cost, then generation order), drops unreachable
/// candidates and fills the status ("no valid candidate: N generated, M reachable, ...").
PlanResult RankCandidates(std::vector<ViewCandidate> candidates, size_t generated,
                          std::string_view planner_name);

/// True when `X_WC` is within `position_tol_m` and `angle_tol_rad` of one of `views`.
bool IsNearAny(const RigidTransform& X_WC, const std::vector<RigidTransform>& views,
               double position_tol_m = 0.02, double angle_tol_rad = 0.1745);

}  // namespace avp::planning
