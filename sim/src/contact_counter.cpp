#include <algorithm>
#include <cmath>
#include <cstdint>
#include <exception>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include <fcl/fcl.h>
#include <fmt/format.h>

#include <avp/core/error.h>
#include <avp/sim/contact_counter.h>

namespace avp::sim {

std::string_view ToString(ContactCategory category) {
  switch (category) {
    case ContactCategory::kPlant:
      return "plant";
    case ContactCategory::kFruit:
      return "fruit";
    case ContactCategory::kSupport:
      return "support";
    case ContactCategory::kGround:
      return "ground";
    case ContactCategory::kSelf:
      return "self";
    case ContactCategory::kIgnored:
      return "ignored";
  }
  return "unknown";
}

ContactCategory ContactCategoryOf(SemanticClass semantic_class) {
  switch (semantic_class) {
    case SemanticClass::kFruit:
      return ContactCategory::kFruit;
    case SemanticClass::kLeaf:
    case SemanticClass::kStem:
      return ContactCategory::kPlant;
    case SemanticClass::kSupport:
    case SemanticClass::kOther:
      return ContactCategory::kSupport;
    case SemanticClass::kGround:
      return ContactCategory::kGround;
    case SemanticClass::kBackground:
      return ContactCategory::kIgnored;
  }
  return ContactCategory::kSupport;
}

std::string ContactInterval::Describe(bool with_position) const {
  std::string text = category == ContactCategory::kSelf
                         ? fmt::format("{} – self '{}'", body, other)
                         : fmt::format("{} – {} '{}'", body, ToString(other_class), other);
  if (with_position) {
    text += fmt::format(" at {:.0f} % of the move", 100.0 * begin_fraction);
  }
  return text;
}

namespace {

/// Steps of one segment beyond which it is cut more coarsely (a 2 km path at 2 mm): a bound on
/// the work of one call, never reached by an arm's motion.
constexpr double kMaxStepsPerSegment = 1.0e6;
/// Samples whose poses are computed together (and share one candidate list per body).
constexpr size_t kChunkSamples = 128;
/// Marks a self-contact key (the rest is the index into self_check_pairs()).
constexpr uint64_t kSelfKey = uint64_t{1} << 63;

/// A checked scene object: its FCL geometry, pose and world bounds.
struct SceneItem {
  std::string name;
  SemanticClass semantic_class = SemanticClass::kOther;
  ContactCategory category = ContactCategory::kSupport;
  std::shared_ptr<const fcl::CollisionGeometryd> geometry;
  Eigen::Isometry3d X_WG = Eigen::Isometry3d::Identity();
  Box3 bounds;
};

/// A sphere containing a robot body, in the body geometry's frame G; `bounded` false when no
/// bound is known (the body is then tested against every object).
struct BodyBound {
  Eigen::Vector3d center_G = Eigen::Vector3d::Zero();
  double radius = 0.0;
  bool bounded = false;
};

BodyBound BoundOfPoints(const Eigen::Vector3d* points, size_t n) {
  BodyBound bound;
  if (n == 0) return bound;
  Box3 box;
  for (size_t i = 0; i < n; ++i) box.Extend(points[i]);
  bound.center_G = box.center();
  double r2 = 0.0;
  for (size_t i = 0; i < n; ++i) r2 = std::max(r2, (points[i] - bound.center_G).squaredNorm());
  bound.radius = std::sqrt(r2);
  bound.bounded = std::isfinite(bound.radius);
  return bound;
}

BodyBound Bounded(double radius) {
  BodyBound bound;
  bound.radius = radius;
  bound.bounded = std::isfinite(radius) && radius >= 0.0;
  return bound;
}

/// A sphere around the body's FCL geometry (primitives and meshes), else around its sphere
/// cover, else none.
BodyBound BoundOf(const motion::RobotBody& body) {
  const fcl::CollisionGeometryd* g = body.geometry.get();
  if (g != nullptr) {
    switch (g->getNodeType()) {
      case fcl::GEOM_BOX:
        return Bounded(0.5 * static_cast<const fcl::Boxd*>(g)->side.norm());
      case fcl::GEOM_SPHERE:
        return Bounded(static_cast<const fcl::Sphered*>(g)->radius);
      case fcl::GEOM_CYLINDER: {
        const auto* c = static_cast<const fcl::Cylinderd*>(g);
        return Bounded(std::hypot(c->radius, 0.5 * c->lz));
      }
      case fcl::GEOM_CONE: {
        const auto* c = static_cast<const fcl::Coned*>(g);
        return Bounded(std::hypot(c->radius, 0.5 * c->lz));
      }
      case fcl::GEOM_CAPSULE: {
        const auto* c = static_cast<const fcl::Capsuled*>(g);
        return Bounded(c->radius + 0.5 * c->lz);
      }
      case fcl::GEOM_ELLIPSOID:
        return Bounded(static_cast<const fcl::Ellipsoidd*>(g)->radii.maxCoeff());
      case fcl::GEOM_CONVEX: {
        const auto& v = static_cast<const fcl::Convexd*>(g)->getVertices();
        return BoundOfPoints(v.data(), v.size());
      }
      default:
        break;
    }
    if (const auto* mesh = dynamic_cast<const fcl::BVHModel<fcl::OBBRSSd>*>(g);
        mesh != nullptr && mesh->vertices != nullptr && mesh->num_vertices > 0) {
      return BoundOfPoints(mesh->vertices, static_cast<size_t>(mesh->num_vertices));
    }
  }
  if (!body.spheres.empty()) {
    // The cover is in the link frame: bound it there, then express the centre in G.
    Box3 box;
    for (const motion::Sphere& s : body.spheres) {
      box.Extend(s.center - Eigen::Vector3d::Constant(s.radius));
      box.Extend(s.center + Eigen::Vector3d::Constant(s.radius));
    }
    BodyBound bound;
    bound.center_G = body.X_LG.inverse() * box.center();
    bound.radius = 0.5 * box.size().norm();
    bound.bounded = std::isfinite(bound.radius);
    return bound;
  }
  return BodyBound{};
}

double SquaredDistanceToBox(const Eigen::Vector3d& p, const Box3& box) {
  const Eigen::Vector3d d = (box.min() - p).cwiseMax(p - box.max()).cwiseMax(0.0);
  return d.squaredNorm();
}

/// Whether the two solids intersect (no margin). FCL's narrow phase can throw on touching
/// contacts (libccd, fcl#319, #390): a throw counts as a contact. The geometry-level collide()
/// neither copies oriented BVHs nor touches the shared geometry, so this is thread-safe.
bool Collide(const fcl::CollisionGeometryd& a, const Eigen::Isometry3d& X_A,
             const fcl::CollisionGeometryd& b, const Eigen::Isometry3d& X_B) {
  const fcl::CollisionRequestd request;  // one contact, no contact points: a boolean query
  fcl::CollisionResultd result;
  try {
    return fcl::collide(&a, X_A, &b, X_B, request, result) > 0;
  } catch (const std::exception&) {
    return true;
  }
}

/// The distance between the two solids (0 when they touch; FCL's distance query, which can throw
/// where collide can: then 0).
double Distance(const fcl::CollisionGeometryd& a, const Eigen::Isometry3d& X_A,
                const fcl::CollisionGeometryd& b, const Eigen::Isometry3d& X_B) {
  const fcl::DistanceRequestd request;
  fcl::DistanceResultd result;
  try {
    return std::max(0.0, fcl::distance(&a, X_A, &b, X_B, request, result));
  } catch (const std::exception&) {
    return 0.0;
  }
}

Result<std::shared_ptr<const fcl::CollisionGeometryd>> MeshGeometry(const TriangleMesh& mesh,
                                                                    const std::string& name,
                                                                    Box3& bounds,
                                                                    size_t& num_triangles) {
  std::vector<fcl::Vector3d> vertices;
  vertices.reserve(mesh.vertices.size());
  for (const Eigen::Vector3f& v : mesh.vertices) vertices.push_back(v.cast<double>());
  std::vector<fcl::Triangle> triangles;
  triangles.reserve(mesh.triangles.size());
  bounds = Box3();
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d& a = vertices[static_cast<size_t>(t[0])];
    const Eigen::Vector3d& b = vertices[static_cast<size_t>(t[1])];
    const Eigen::Vector3d& c = vertices[static_cast<size_t>(t[2])];
    if ((b - a).cross(c - a).squaredNorm() == 0.0) continue;  // zero area: touches nothing
    triangles.emplace_back(static_cast<size_t>(t[0]), static_cast<size_t>(t[1]),
                           static_cast<size_t>(t[2]));
    bounds.Extend(a);
    bounds.Extend(b);
    bounds.Extend(c);
  }
  num_triangles = triangles.size();
  if (triangles.empty()) return std::shared_ptr<const fcl::CollisionGeometryd>();
  if (vertices.size() > static_cast<size_t>(std::numeric_limits<int>::max()) ||
      triangles.size() > static_cast<size_t>(std::numeric_limits<int>::max())) {
    return InvalidArgumentError(
        fmt::format("contact counter: object '{}' has too many triangles "
                    "({}) for FCL",
                    name, triangles.size()));
  }
  auto model = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
  if (model->beginModel(static_cast<int>(triangles.size()), static_cast<int>(vertices.size())) !=
          fcl::BVH_OK ||
      model->addSubModel(vertices, triangles) != fcl::BVH_OK || model->endModel() != fcl::BVH_OK) {
    return InternalError(
        fmt::format("contact counter: FCL could not build the BVH of object '{}'", name));
  }
  model->computeLocalAABB();
  return std::shared_ptr<const fcl::CollisionGeometryd>(std::move(model));
}

}  // namespace

struct ContactCounter::Impl {
  explicit Impl(motion::RobotGeometry r) : robot(std::move(r)) {}

  motion::RobotGeometry robot;
  double max_step_m = 0.002;
  std::vector<SceneItem> objects;
  /// Per body of robot.bodies(): its bounding sphere.
  std::vector<BodyBound> bounds;
  /// Indices of the bodies with `moves`.
  std::vector<int> moving;
  size_t num_triangles = 0;

  void CheckWaypoints(const std::vector<Eigen::VectorXd>& waypoints) const;
  /// Passes the samples of the polyline, in order, to visit(states, fractions) in chunks of up
  /// to kChunkSamples (fractions: of the joint-space path length, ContactInterval's).
  template <typename Visit>
  void ForEachChunk(const std::vector<Eigen::VectorXd>& waypoints, Visit&& visit) const;
  std::vector<ContactInterval> List(const std::vector<Eigen::VectorXd>& waypoints) const;
  ContactInterval NewInterval(uint64_t key, int sample, double fraction) const;
};

void ContactCounter::Impl::CheckWaypoints(const std::vector<Eigen::VectorXd>& waypoints) const {
  const Eigen::Index n = robot.arm().num_joints();
  for (size_t i = 0; i < waypoints.size(); ++i) {
    const Eigen::VectorXd& q = waypoints[i];
    if (q.size() != n || !q.allFinite()) {
      throw Error(fmt::format(
          "ContactCounter: waypoint {} must have {} finite joint values; it has {} ({})", i, n,
          q.size(), q.allFinite() ? "all finite" : "a non-finite entry"));
    }
  }
}

template <typename Visit>
void ContactCounter::Impl::ForEachChunk(const std::vector<Eigen::VectorXd>& waypoints,
                                        Visit&& visit) const {
  if (waypoints.empty()) return;
  double total = 0.0;
  for (size_t j = 1; j < waypoints.size(); ++j) total += (waypoints[j] - waypoints[j - 1]).norm();
  std::vector<Eigen::VectorXd> qs;
  std::vector<double> fractions;
  qs.reserve(kChunkSamples);
  fractions.reserve(kChunkSamples);
  auto flush = [&] {
    if (qs.empty()) return;
    visit(qs, fractions);
    qs.clear();
    fractions.clear();
  };
  auto add = [&](Eigen::VectorXd q, double length_so_far) {
    qs.push_back(std::move(q));
    fractions.push_back(total > 0.0 ? std::clamp(length_so_far / total, 0.0, 1.0) : 0.0);
    if (qs.size() == kChunkSamples) flush();
  };
  add(waypoints.front(), 0.0);
  double before = 0.0;
  for (size_t j = 1; j < waypoints.size(); ++j) {
    const Eigen::VectorXd& a = waypoints[j - 1];
    const Eigen::VectorXd dq = waypoints[j] - a;
    const double length = dq.norm();
    if (length > 0.0) {
      const double steps =
          std::clamp(std::ceil(robot.MaxDisplacement(dq) / max_step_m), 1.0, kMaxStepsPerSegment);
      const int n = static_cast<int>(steps);
      for (int k = 1; k <= n; ++k) {
        const double t = static_cast<double>(k) / static_cast<double>(n);
        add(k == n ? Eigen::VectorXd(waypoints[j]) : Eigen::VectorXd(a + t * dq),
            before + t * length);
      }
    }
    before += length;
  }
  flush();
}

ContactInterval ContactCounter::Impl::NewInterval(uint64_t key, int sample, double fraction) const {
  const std::vector<motion::RobotBody>& bodies = robot.bodies();
  ContactInterval c;
  if ((key & kSelfKey) != 0) {
    const std::pair<int, int>& pair =
        robot.self_check_pairs()[static_cast<size_t>(key & ~kSelfKey)];
    c.body = bodies[static_cast<size_t>(pair.first)].name;
    c.other = bodies[static_cast<size_t>(pair.second)].name;
    c.category = ContactCategory::kSelf;
  } else {
    const SceneItem& o = objects[static_cast<size_t>(key & 0xffffffffu)];
    c.body = bodies[static_cast<size_t>(key >> 32)].name;
    c.other = o.name;
    c.other_class = o.semantic_class;
    c.category = o.category;
  }
  c.first_sample = c.last_sample = sample;
  c.begin_fraction = c.end_fraction = fraction;
  return c;
}

std::vector<ContactInterval> ContactCounter::Impl::List(
    const std::vector<Eigen::VectorXd>& waypoints) const {
  CheckWaypoints(waypoints);
  const std::vector<motion::RobotBody>& bodies = robot.bodies();
  const std::vector<std::pair<int, int>>& self_pairs = robot.self_check_pairs();

  std::vector<ContactInterval> intervals;
  // Open intervals (key, index into intervals), sorted by key; the keys hit at this sample.
  std::vector<std::pair<uint64_t, size_t>> open;
  std::vector<std::pair<uint64_t, size_t>> still_open;
  std::vector<uint64_t> hits;
  int sample = 0;

  std::vector<std::vector<Eigen::Isometry3d>> poses;
  std::vector<std::vector<uint32_t>> candidates(bodies.size());
  ForEachChunk(waypoints,
               [&](const std::vector<Eigen::VectorXd>& qs, const std::vector<double>& fractions) {
                 poses.resize(qs.size());
                 for (size_t s = 0; s < qs.size(); ++s) poses[s] = robot.BodyPoses(qs[s]);
                 // Per moving body: the objects whose bounds its sphere reaches somewhere in this
                 // chunk.
                 for (const int i : moving) {
                   const size_t b = static_cast<size_t>(i);
                   std::vector<uint32_t>& list = candidates[b];
                   list.clear();
                   const BodyBound& bound = bounds[b];
                   if (!bound.bounded) {
                     for (size_t o = 0; o < objects.size(); ++o)
                       list.push_back(static_cast<uint32_t>(o));
                     continue;
                   }
                   Box3 swept;
                   for (size_t s = 0; s < qs.size(); ++s)
                     swept.Extend(poses[s][b] * bound.center_G);
                   swept = swept.Inflated(bound.radius);
                   for (size_t o = 0; o < objects.size(); ++o) {
                     if (objects[o].bounds.Intersects(swept))
                       list.push_back(static_cast<uint32_t>(o));
                   }
                 }
                 for (size_t s = 0; s < qs.size(); ++s, ++sample) {
                   const std::vector<Eigen::Isometry3d>& X = poses[s];
                   hits.clear();
                   for (const int i : moving) {
                     const size_t b = static_cast<size_t>(i);
                     const BodyBound& bound = bounds[b];
                     const Eigen::Vector3d center_W = X[b] * bound.center_G;
                     const double r2 = bound.radius * bound.radius;
                     for (const uint32_t o : candidates[b]) {
                       const SceneItem& item = objects[o];
                       if (bound.bounded && SquaredDistanceToBox(center_W, item.bounds) > r2)
                         continue;
                       if (Collide(*bodies[b].geometry, X[b], *item.geometry, item.X_WG)) {
                         hits.push_back((uint64_t{static_cast<uint32_t>(i)} << 32) | o);
                       }
                     }
                   }
                   for (size_t p = 0; p < self_pairs.size(); ++p) {
                     const size_t a = static_cast<size_t>(self_pairs[p].first);
                     const size_t b = static_cast<size_t>(self_pairs[p].second);
                     if (bounds[a].bounded && bounds[b].bounded) {
                       const double reach = bounds[a].radius + bounds[b].radius;
                       if ((X[a] * bounds[a].center_G - X[b] * bounds[b].center_G).squaredNorm() >
                           reach * reach) {
                         continue;
                       }
                     }
                     if (Collide(*bodies[a].geometry, X[a], *bodies[b].geometry, X[b])) {
                       hits.push_back(kSelfKey | uint64_t{p});
                     }
                   }
                   // hits is sorted (bodies, then objects, ascending; self keys last): merge with
                   // the open intervals; those not hit again end here.
                   still_open.clear();
                   size_t k = 0;
                   for (const uint64_t key : hits) {
                     while (k < open.size() && open[k].first < key) ++k;
                     size_t index = 0;
                     if (k < open.size() && open[k].first == key) {
                       index = open[k].second;
                       intervals[index].last_sample = sample;
                       intervals[index].end_fraction = fractions[s];
                     } else {
                       index = intervals.size();
                       intervals.push_back(NewInterval(key, sample, fractions[s]));
                     }
                     still_open.emplace_back(key, index);
                   }
                   open.swap(still_open);
                 }
               });
  return intervals;
}

Result<ContactCounter> ContactCounter::Create(const Scene& scene, motion::RobotGeometry robot,
                                              double max_step_m) {
  if (!(std::isfinite(max_step_m) && max_step_m > 0.0)) {
    return InvalidArgumentError(fmt::format(
        "contact counter: max_step_m must be finite and > 0 (metres), got {}", max_step_m));
  }
  AVP_RETURN_IF_ERROR(scene.Validate().WithContext("contact counter"));
  auto impl = std::make_shared<Impl>(std::move(robot));
  impl->max_step_m = max_step_m;
  const std::vector<motion::RobotBody>& bodies = impl->robot.bodies();
  for (size_t i = 0; i < bodies.size(); ++i) {
    if (bodies[i].geometry == nullptr) {
      return InvalidArgumentError(fmt::format(
          "contact counter: the robot's body '{}' has no collision geometry", bodies[i].name));
    }
    impl->bounds.push_back(BoundOf(bodies[i]));
    if (bodies[i].moves) impl->moving.push_back(static_cast<int>(i));
  }
  if (bodies.size() > std::numeric_limits<uint32_t>::max() ||
      scene.objects.size() > std::numeric_limits<uint32_t>::max()) {
    return InvalidArgumentError("contact counter: too many bodies or scene objects");
  }

  for (const SceneObject& object : scene.objects) {
    SceneItem item;
    item.name = object.name;
    item.semantic_class = object.semantic_class;
    item.category = ContactCategoryOf(object.semantic_class);
    if (item.category == ContactCategory::kIgnored) continue;
    if (const auto* mesh = std::get_if<TriangleMesh>(&object.shape)) {
      size_t num_triangles = 0;
      AVP_ASSIGN_OR_RETURN(item.geometry,
                           MeshGeometry(*mesh, object.name, item.bounds, num_triangles));
      if (item.geometry == nullptr) continue;  // no triangle with an area
      impl->num_triangles += num_triangles;
    } else {
      const Ellipsoid& e = std::get<Ellipsoid>(object.shape);
      item.geometry = std::make_shared<const fcl::Ellipsoidd>(e.radii);
      item.X_WG.linear() = e.R_WE;
      item.X_WG.translation() = e.center_W;
      item.bounds = e.Bounds();
    }
    impl->objects.push_back(std::move(item));
  }
  return ContactCounter(std::move(impl));
}

robot::MotionContacts ContactCounter::Summarize(const std::vector<ContactInterval>& contacts,
                                                bool with_position) {
  robot::MotionContacts counts;
  for (const ContactInterval& c : contacts) {
    switch (c.category) {
      case ContactCategory::kPlant:
        ++counts.plant;
        break;
      case ContactCategory::kFruit:
        ++counts.fruit;
        break;
      case ContactCategory::kSupport:
        ++counts.support;
        break;
      case ContactCategory::kGround:
        ++counts.ground;
        break;
      case ContactCategory::kSelf:
        ++counts.self;
        break;
      case ContactCategory::kIgnored:
        break;
    }
  }
  if (!contacts.empty()) counts.first = contacts.front().Describe(with_position);
  return counts;
}

robot::MotionContacts ContactCounter::CountAlong(
    const std::vector<Eigen::VectorXd>& waypoints) const {
  return Summarize(impl_->List(waypoints), waypoints.size() >= 2);
}

robot::MotionContacts ContactCounter::CountAt(const Eigen::VectorXd& q) const {
  return Summarize(impl_->List({q}), false);
}

robot::TrueClearance ContactCounter::NearestAt(const Eigen::VectorXd& q, double up_to_m) const {
  impl_->CheckWaypoints({q});
  if (!(std::isfinite(up_to_m) && up_to_m >= 0.0)) {
    throw Error(
        fmt::format("ContactCounter::NearestAt: up_to_m ({}) must be finite and >= 0", up_to_m));
  }
  const std::vector<motion::RobotBody>& bodies = impl_->robot.bodies();
  const std::vector<Eigen::Isometry3d> X = impl_->robot.BodyPoses(q);
  robot::TrueClearance nearest;
  uint64_t nearest_key = 0;  // the body and the object, as a contact's key
  for (const int i : impl_->moving) {
    const size_t b = static_cast<size_t>(i);
    const BodyBound& bound = impl_->bounds[b];
    const Eigen::Vector3d center_W = X[b] * bound.center_G;
    const double reach = bound.radius + up_to_m;
    for (size_t o = 0; o < impl_->objects.size(); ++o) {
      const SceneItem& item = impl_->objects[o];
      if (bound.bounded && SquaredDistanceToBox(center_W, item.bounds) > reach * reach) continue;
      const double d = Distance(*bodies[b].geometry, X[b], *item.geometry, item.X_WG);
      if (d <= up_to_m && d < nearest.distance_m) {
        nearest.distance_m = d;
        nearest_key = (uint64_t{static_cast<uint32_t>(i)} << 32) | o;
      }
    }
  }
  // Named as a contact is: "flange/d435 – leaf 'tomato/leaf_11'".
  if (std::isfinite(nearest.distance_m)) {
    nearest.nearest = impl_->NewInterval(nearest_key, 0, 0.0).Describe(/*with_position=*/false);
  }
  return nearest;
}

std::vector<ContactInterval> ContactCounter::ListAlong(
    const std::vector<Eigen::VectorXd>& waypoints) const {
  return impl_->List(waypoints);
}

std::vector<Eigen::VectorXd> ContactCounter::SampleAlong(
    const std::vector<Eigen::VectorXd>& waypoints) const {
  impl_->CheckWaypoints(waypoints);
  std::vector<Eigen::VectorXd> samples;
  impl_->ForEachChunk(waypoints,
                      [&](const std::vector<Eigen::VectorXd>& qs, const std::vector<double>&) {
                        samples.insert(samples.end(), qs.begin(), qs.end());
                      });
  return samples;
}

const motion::RobotGeometry& ContactCounter::robot() const { return impl_->robot; }
double ContactCounter::max_step_m() const { return impl_->max_step_m; }
size_t ContactCounter::num_objects() const { return impl_->objects.size(); }
size_t ContactCounter::num_triangles() const { return impl_->num_triangles; }

}  // namespace avp::sim
