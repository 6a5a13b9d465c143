#include <algorithm>
#include <array>
#include <cmath>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <avp/io/label_preview.h>
#include <avp/live/ros2_rgbd_source.h>
#include <avp/live/rviz_publisher.h>
#include <avp/mapping/octomap_io.h>
#include <avp/rosmsg/convert.h>

namespace avp::live {

namespace {

using rosmsg::Rgba;
using rosmsg::Viridis;

/// A distinct colour per instance id (golden-angle hue).
rosmsg::ColorRGBA InstanceColor(uint16_t id) {
  if (id == 0) return Rgba(0.5, 0.5, 0.5);
  const double h = std::fmod(static_cast<double>(id) * 0.618033988749895, 1.0) * 6.0;
  const double x = 1.0 - std::abs(std::fmod(h, 2.0) - 1.0);
  const int sector = static_cast<int>(h);
  const std::array<std::array<double, 3>, 6> rgb = {
      {{1, x, 0}, {x, 1, 0}, {0, 1, x}, {0, x, 1}, {x, 0, 1}, {1, 0, x}}};
  const auto& c = rgb[static_cast<size_t>(std::clamp(sector, 0, 5))];
  return Rgba(0.15 + 0.85 * c[0], 0.15 + 0.85 * c[1], 0.15 + 0.85 * c[2]);
}

rosmsg::Marker CubeList(const rosmsg::Header& header, const std::string& ns, double size) {
  rosmsg::Marker m;
  m.header = header;
  m.ns = ns;
  m.id = 0;
  m.type = rosmsg::Marker::kCubeList;
  m.action = rosmsg::Marker::kAdd;
  m.pose.orientation.w = 1.0;
  m.scale = {size, size, size};
  m.color = Rgba(1, 1, 1, 1);
  return m;
}

rosmsg::Marker Arrow(const rosmsg::Header& header, const std::string& ns, int id,
                     const RigidTransform& X_WC, double length, rosmsg::ColorRGBA color) {
  // An arrow along the optical axis (+z of the optical frame): RViz arrows point along +x, so
  // give start and end points instead of a pose.
  rosmsg::Marker m;
  m.header = header;
  m.ns = ns;
  m.id = id;
  m.type = rosmsg::Marker::kArrow;
  m.action = rosmsg::Marker::kAdd;
  m.pose.orientation.w = 1.0;
  m.scale = {0.01, 0.02, 0.03};  // shaft diameter, head diameter, head length
  m.color = color;
  const Eigen::Vector3d a = X_WC.translation();
  const Eigen::Vector3d b = a + length * X_WC.rotation().col(2);
  m.points.push_back({a.x(), a.y(), a.z()});
  m.points.push_back({b.x(), b.y(), b.z()});
  return m;
}

rosmsg::Marker DeleteAll(const rosmsg::Header& header) {
  rosmsg::Marker m;
  m.header = header;
  m.action = rosmsg::Marker::kDeleteAll;
  m.pose.orientation.w = 1.0;
  return m;
}

}  // namespace

const OptionTable<RvizOptions>& RvizOptionTable() {
  static const auto* table = [] {
    using O = RvizOptions;
    auto* t = new OptionTable<O>("rviz option");
    t->Flag("enabled", &O::enabled, "publish the map and the planner's views for RViz");
    t->Text("frame", &O::frame, "the frame of the markers and the map");
    t->Text("octomap_topic", &O::octomap_topic, "octomap_msgs/Octomap (binary), transient local");
    t->Text("voxels_topic", &O::voxels_topic,
            "MarkerArray of occupied voxels (class, instance, confidence) and fruit found");
    t->Text("candidates_topic", &O::candidates_topic, "MarkerArray of candidate views by utility");
    t->Text("chosen_topic", &O::chosen_topic, "MarkerArray of the chosen view and its utility");
    return t;
  }();
  return *table;
}

rosmsg::MarkerArray VoxelMarkers(const mapping::SemanticMap& map, SemanticClass target,
                                 const rosmsg::Header& header) {
  const mapping::OccupancyGrid& grid = map.grid();
  const double s = grid.voxel_size_m();
  rosmsg::Marker by_class = CubeList(header, "class", s);
  rosmsg::Marker by_instance = CubeList(header, "instance", s);
  rosmsg::Marker by_confidence = CubeList(header, "confidence", s);
  const float occupied = grid.occupied_log_odds();
  grid.ForEachKnownVoxel([&](const VoxelKey& k, float log_odds) {
    if (log_odds < occupied) return;
    const Eigen::Vector3d c = grid.CenterOf(k);
    const rosmsg::Point p{c.x(), c.y(), c.z()};
    const mapping::SemanticCell* cell = grid.Semantic(k);
    const bool labelled = cell != nullptr && cell->has_label();
    const auto rgb = mapping::OctomapVoxelColor(cell);
    by_class.points.push_back(p);
    by_class.colors.push_back(Rgba(rgb[0] / 255.0, rgb[1] / 255.0, rgb[2] / 255.0));
    if (labelled) {
      by_instance.points.push_back(p);
      by_instance.colors.push_back(InstanceColor(cell->instance_id));
      by_confidence.points.push_back(p);
      by_confidence.colors.push_back(Viridis(cell->confidence));
    }
  });
  rosmsg::MarkerArray out;
  out.markers.push_back(DeleteAll(header));
  for (rosmsg::Marker* m : {&by_class, &by_instance, &by_confidence}) {
    if (!m->points.empty()) out.markers.push_back(std::move(*m));
  }
  int id = 0;
  for (const mapping::InstanceInfo& info : map.Instances()) {
    if (info.semantic_class != target) continue;
    rosmsg::Marker sphere;
    sphere.header = header;
    sphere.ns = "fruit";
    sphere.id = id++;
    sphere.type = rosmsg::Marker::kSphere;
    sphere.action = rosmsg::Marker::kAdd;
    sphere.pose.position = {info.centroid_W.x(), info.centroid_W.y(), info.centroid_W.z()};
    sphere.pose.orientation.w = 1.0;
    const double d = std::max(2.0 * s, std::cbrt(static_cast<double>(info.voxels)) * s);
    sphere.scale = {d, d, d};
    sphere.color = Rgba(1.0, 0.3, 0.2, 0.35);
    out.markers.push_back(sphere);
    rosmsg::Marker text = sphere;
    text.id = id++;
    text.type = rosmsg::Marker::kTextViewFacing;
    text.pose.position.z += d;
    text.scale = {0.0, 0.0, 0.03};
    text.color = Rgba(1, 1, 1, 1);
    text.text = fmt::format("#{} {} voxels {:.2f}", info.id, info.voxels, info.mean_confidence);
    out.markers.push_back(text);
  }
  return out;
}

rosmsg::MarkerArray CandidateMarkers(const pipeline::StepRecord& step,
                                     const rosmsg::Header& header) {
  rosmsg::MarkerArray out;
  out.markers.push_back(DeleteAll(header));
  if (step.top_candidates.empty()) return out;
  double lo = step.top_candidates.front().utility;
  double hi = lo;
  for (const planning::ViewCandidate& c : step.top_candidates) {
    lo = std::min(lo, c.utility);
    hi = std::max(hi, c.utility);
  }
  int id = 0;
  for (const planning::ViewCandidate& c : step.top_candidates) {
    const double t = hi > lo ? (c.utility - lo) / (hi - lo) : 1.0;
    out.markers.push_back(Arrow(header, "candidates", id++, c.X_WC, 0.08,
                                c.reachable ? Viridis(t) : Rgba(0.6, 0.6, 0.6, 0.6)));
  }
  return out;
}

rosmsg::MarkerArray ChosenMarkers(const pipeline::StepRecord& step, const rosmsg::Header& header) {
  rosmsg::MarkerArray out;
  out.markers.push_back(DeleteAll(header));
  if (step.chosen_rank < 0) return out;
  out.markers.push_back(Arrow(header, "chosen", 0, step.chosen.X_WC, 0.15, Rgba(1, 0.1, 0.6)));
  rosmsg::Marker text;
  text.header = header;
  text.ns = "chosen";
  text.id = 1;
  text.type = rosmsg::Marker::kTextViewFacing;
  text.action = rosmsg::Marker::kAdd;
  const Eigen::Vector3d p = step.chosen.X_WC.translation();
  text.pose.position = {p.x(), p.y(), p.z() + 0.06};
  text.pose.orientation.w = 1.0;
  text.scale = {0.0, 0.0, 0.03};
  text.color = Rgba(1, 1, 1, 1);
  text.text = fmt::format("view {} (rank {}): utility {:.3g}, gain {:.3g}, cost {:.3g} rad [{}]",
                          step.view + 1, step.chosen_rank, step.chosen.utility, step.chosen.gain,
                          step.chosen.cost, step.chosen.source);
  out.markers.push_back(text);
  return out;
}

Result<std::unique_ptr<RvizPublisher>> RvizPublisher::Create(ros2::Node& node,
                                                             const RvizOptions& options,
                                                             SemanticClass target) {
  std::unique_ptr<RvizPublisher> p(new RvizPublisher(options, target));
  const ros2::QosProfile latched = ros2::QosProfile::Latched();
  AVP_ASSIGN_OR_RETURN(p->octomap_,
                       node.CreatePublisher<rosmsg::Octomap>(options.octomap_topic, latched));
  AVP_ASSIGN_OR_RETURN(p->voxels_,
                       node.CreatePublisher<rosmsg::MarkerArray>(options.voxels_topic, latched));
  AVP_ASSIGN_OR_RETURN(
      p->candidates_, node.CreatePublisher<rosmsg::MarkerArray>(options.candidates_topic, latched));
  AVP_ASSIGN_OR_RETURN(p->chosen_,
                       node.CreatePublisher<rosmsg::MarkerArray>(options.chosen_topic, latched));
  return p;
}

void RvizPublisher::Report(const Status& s, const std::string& topic) {
  if (s.ok()) {
    ++published_;
    return;
  }
  if (last_error_topic_ != topic) {
    spdlog::warn("publishing {} failed: {}", topic, s.message());
    last_error_topic_ = topic;
  }
}

void RvizPublisher::PublishMap(const mapping::SemanticMap& map) {
  rosmsg::Header header;
  header.stamp = rosmsg::Time::FromNanoseconds(NowNs());
  header.frame_id = options_.frame;
  Result<mapping::OctomapBinaryData> tree = mapping::OctomapBinaryMessageData(map.grid());
  if (tree.ok()) {
    rosmsg::Octomap msg;
    msg.header = header;
    msg.binary = true;
    msg.id = tree->id;
    msg.resolution = tree->resolution_m;
    msg.data.assign(tree->data.begin(), tree->data.end());
    Report(octomap_->Publish(msg), options_.octomap_topic);
  } else {
    Report(tree.status(), options_.octomap_topic);
  }
  Report(voxels_->Publish(VoxelMarkers(map, target_, header)), options_.voxels_topic);
}

void RvizPublisher::OnStep(const pipeline::StepRecord& step, const mapping::SemanticMap& map) {
  PublishMap(map);
  rosmsg::Header header;
  header.stamp = rosmsg::Time::FromNanoseconds(NowNs());
  header.frame_id = options_.frame;
  Report(candidates_->Publish(CandidateMarkers(step, header)), options_.candidates_topic);
  Report(chosen_->Publish(ChosenMarkers(step, header)), options_.chosen_topic);
}

void RvizPublisher::OnEnd(const pipeline::EpisodeResult&, const mapping::SemanticMap& map) {
  PublishMap(map);
}

}  // namespace avp::live
