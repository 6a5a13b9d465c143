#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include <avp/core/semantic_class.h>
#include <avp/core/status.h>
#include <avp/motion/robot_geometry.h>
#include <avp/robot/arm.h>
#include <avp/sim/scene.h>

namespace avp::sim {

/// What a contact touched, as robot::MotionContacts counts it.
enum class ContactCategory : uint8_t {
  kPlant,    ///< leaves and stems
  kFruit,    ///< fruit
  kSupport,  ///< supports and other objects: stakes, posts, wires, walls
  kGround,   ///< the ground
  kSelf,     ///< another body of the arm
  kIgnored,  ///< background: never checked
};
std::string_view ToString(ContactCategory category);
/// fruit → kFruit; leaf, stem → kPlant; support, other → kSupport; ground → kGround;
/// background → kIgnored.
ContactCategory ContactCategoryOf(SemanticClass semantic_class);

/// One contact: a maximal run of consecutive sampled states in which one moving body of the arm
/// touches one scene object (or, for kSelf, another body of the arm).
struct ContactInterval {
  /// The arm's body (RobotBody::name, e.g. "link_7" or "flange/d435").
  std::string body;
  /// What it touched: the scene object's name, or the other body's name for kSelf.
  std::string other;
  /// The scene object's class (kOther for self contacts).
  SemanticClass other_class = SemanticClass::kOther;
  ContactCategory category = ContactCategory::kSupport;
  /// Indices of the first and last colliding sample (ContactCounter::SampleAlong's order).
  int first_sample = 0;
  int last_sample = 0;
  /// Where along the move it starts and ends: the fraction of the joint-space path length
  /// Σ|Δq| (0 at the first waypoint, 1 at the last; 0 for a move of zero length).
  double begin_fraction = 0.0;
  double end_fraction = 0.0;

  /// "link_7 – leaf 'tomato/leaf_3' at 42 % of the move" ("... – self 'link_2' ..." for self
  /// contacts; without the "at" part when `with_position` is false).
  std::string Describe(bool with_position = true) const;
};

/// Counts the contacts between the arm's collision geometry and the TRUE scene (exact meshes and
/// analytic ellipsoids, no margin) along a joint-space motion, as only a simulator can. See
/// docs/motion.md and the design notes (motion-and-python.md, A4).
///
/// The scene's geometry is built once in Create: one FCL BVHModel<OBBRSS> per mesh object (its
/// world-frame triangles; zero-area triangles dropped) and one fcl::Ellipsoid per ellipsoid
/// object, each with its world axis-aligned bounds for a prefilter. Background objects are not
/// checked. Copies are cheap (the data is shared and immutable); every method is const and safe
/// to call from several threads at once.
///
/// Sampling: each straight joint segment a → b of a motion is cut into
/// n = max(1, ⌈robot.MaxDisplacement(b − a) / max_step_m⌉) equal steps, so that no point of the
/// arm moves more than max_step_m between two samples; both ends are sampled (a shared vertex of
/// the polyline once). At each sample every moving body (RobotBody::moves) is checked against
/// every scene object whose bounds its bounding sphere reaches (fcl::collide, boolean), and
/// every pair of robot.self_check_pairs() against each other. A throw from FCL's narrow phase
/// (libccd on touching contacts) counts as a collision.
///
/// Limits: a contact is a sample at which the solid robot body intersects the object's surface
/// triangles (mesh objects) or the solid ellipsoid: a body that passes entirely into a closed
/// mesh larger than itself (a thick wall, the space below the ground quad) is in contact while
/// it crosses the surface, so leaving it again starts a second contact. A surface thinner than
/// max_step_m that a body crosses between two samples within a step is not seen if no sample
/// intersects it; bodies are solid and at least a few centimetres thick, so with the default
/// 2 mm step this needs a body edge thinner than 2 mm.
class ContactCounter {
 public:
  /// Errors: InvalidArgument for a max_step_m that is not finite and > 0, a scene that fails
  /// Scene::Validate (naming the object), or a robot whose bodies have no geometry.
  static Result<ContactCounter> Create(const Scene& scene, motion::RobotGeometry robot,
                                       double max_step_m = 0.002);

  /// Contacts along the polyline through `waypoints` (joint vectors of the robot's arm, start
  /// first), sampled as described above. An empty list counts nothing; one waypoint is CountAt.
  /// `first` describes the first contact (the earliest; at equal samples, in body order, world
  /// contacts before self contacts).
  ///
  /// Cost: (samples) × (forward kinematics + a sphere-box test per moving body and nearby
  /// object + one FCL narrow-phase query per body whose sphere reaches an object's bounds + one
  /// per self-check pair whose spheres overlap). Samples ≈ Σ MaxDisplacement / max_step_m: about
  /// 500 per metre of the fastest point's path at the default 2 mm.
  /// @throws avp::Error if a waypoint has the wrong size or a non-finite entry.
  robot::MotionContacts CountAlong(const std::vector<Eigen::VectorXd>& waypoints) const;
  /// Contacts of the single state `q`: one sample, each touched object (and self pair) once.
  /// Cost: one sample of CountAlong (tens of microseconds to a few milliseconds, depending on
  /// how much of the scene the arm's bodies reach). @throws avp::Error as CountAlong.
  robot::MotionContacts CountAt(const Eigen::VectorXd& q) const;
  /// The scene object nearest to the arm's moving bodies at `q`, if within `up_to_m` (FCL
  /// distance between the true shapes, 0 when they touch), else distance_m = +infinity.
  /// Cost: one FCL distance query per moving body and object whose bounds it reaches within
  /// up_to_m. @throws avp::Error as CountAlong, or for an up_to_m that is not finite and >= 0.
  robot::TrueClearance NearestAt(const Eigen::VectorXd& q, double up_to_m) const;

  /// The contacts CountAlong counts, one entry per interval, in order of their first sample.
  /// @throws avp::Error as CountAlong.
  std::vector<ContactInterval> ListAlong(const std::vector<Eigen::VectorXd>& waypoints) const;
  /// The sampled states of the polyline, in order (CountAlong's samples; for tests and tools).
  /// @throws avp::Error as CountAlong.
  std::vector<Eigen::VectorXd> SampleAlong(const std::vector<Eigen::VectorXd>& waypoints) const;

  /// Sums ContactIntervals into robot::MotionContacts (`first` from the first interval).
  static robot::MotionContacts Summarize(const std::vector<ContactInterval>& contacts,
                                         bool with_position = true);

  const motion::RobotGeometry& robot() const;
  double max_step_m() const;
  /// Scene objects checked (every object that is not background and not an empty mesh).
  size_t num_objects() const;
  /// Triangles of the checked mesh objects (zero-area ones excluded).
  size_t num_triangles() const;

  struct Impl;

 private:
  explicit ContactCounter(std::shared_ptr<const Impl> impl) : impl_(std::move(impl)) {}
  std::shared_ptr<const Impl> impl_;
};

}  // namespace avp::sim
