#include <algorithm>
#include <array>
#include <cmath>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <avp/io/label_preview.h>
#include <avp/mapping/octomap_io.h>
#include <avp/ros/live/ros2_rgbd_source.h>
#include <avp/ros/live/rviz_publisher.h>
#include <avp/ros/msg/convert.h>
#include <avp/ros/msg/markers.h>

namespace avp::ros::live {

namespace {

using ros::msg::ArrowMarker;
using ros::msg::CubeListMarker;
using ros::msg::DeleteAllMarker;
using ros::msg::LineStripMarker;
using ros::msg::Rgba;
using ros::msg::SphereMarker;
using ros::msg::TextMarker;
using ros::msg::ViewArrowMarker;
using ros::msg::Viridis;

/// RViz's view arrows: shaft diameter, head diameter, head length.
constexpr ros::msg::Vector3 kArrowScale{0.01, 0.02, 0.03};

/// A distinct colour per instance id (golden-angle hue).
ros::msg::ColorRGBA InstanceColor(uint16_t id) {
  if (id == 0) return Rgba(0.5, 0.5, 0.5);
  const double h = std::fmod(static_cast<double>(id) * 0.618033988749895, 1.0) * 6.0;
  const double x = 1.0 - std::abs(std::fmod(h, 2.0) - 1.0);
  const int sector = static_cast<int>(h);
  const std::array<std::array<double, 3>, 6> rgb = {
      {{1, x, 0}, {x, 1, 0}, {0, 1, x}, {0, x, 1}, {x, 0, 1}, {1, 0, x}}};
  const auto& c = rgb[static_cast<size_t>(std::clamp(sector, 0, 5))];
  return Rgba(0.15 + 0.85 * c[0], 0.15 + 0.85 * c[1], 0.15 + 0.85 * c[2]);
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

ros::msg::MarkerArray VoxelMarkers(const mapping::SemanticMap& map, SemanticClass target,
                                   const ros::msg::Header& header) {
  const mapping::OccupancyGrid& grid = map.grid();
  const double s = grid.voxel_size_m();
  ros::msg::Marker by_class = CubeListMarker(header, "class", s);
  ros::msg::Marker by_instance = CubeListMarker(header, "instance", s);
  ros::msg::Marker by_confidence = CubeListMarker(header, "confidence", s);
  const float occupied = grid.occupied_log_odds();
  grid.ForEachKnownVoxel([&](const VoxelKey& k, float log_odds) {
    if (log_odds < occupied) return;
    const Eigen::Vector3d c = grid.CenterOf(k);
    const ros::msg::Point p{c.x(), c.y(), c.z()};
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
  ros::msg::MarkerArray out;
  out.markers.push_back(DeleteAllMarker(header));
  for (ros::msg::Marker* m : {&by_class, &by_instance, &by_confidence}) {
    if (!m->points.empty()) out.markers.push_back(std::move(*m));
  }
  int id = 0;
  for (const mapping::InstanceInfo& info : map.Instances()) {
    if (info.semantic_class != target) continue;
    const double d = std::max(2.0 * s, std::cbrt(static_cast<double>(info.voxels)) * s);
    out.markers.push_back(
        SphereMarker(header, "fruit", id++, info.centroid_W, d, Rgba(1.0, 0.3, 0.2, 0.35)));
    out.markers.push_back(
        TextMarker(header, "fruit", id++, info.centroid_W + Eigen::Vector3d(0, 0, d),
                   fmt::format("#{} {} voxels {:.2f}", info.id, info.voxels, info.mean_confidence),
                   0.03, Rgba(1, 1, 1, 1)));
  }
  return out;
}

ros::msg::MarkerArray CandidateMarkers(const pipeline::StepRecord& step,
                                       const ros::msg::Header& header) {
  ros::msg::MarkerArray out;
  out.markers.push_back(DeleteAllMarker(header));
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
    out.markers.push_back(ViewArrowMarker(header, "candidates", id++, c.X_WC, 0.08, kArrowScale,
                                          c.reachable ? Viridis(t) : Rgba(0.6, 0.6, 0.6, 0.6)));
  }
  return out;
}

ros::msg::MarkerArray ChosenMarkers(const pipeline::StepRecord& step,
                                    const ros::msg::Header& header) {
  ros::msg::MarkerArray out;
  out.markers.push_back(DeleteAllMarker(header));
  if (step.chosen_rank < 0) return out;
  out.markers.push_back(
      ViewArrowMarker(header, "chosen", 0, step.chosen.X_WC, 0.15, kArrowScale, Rgba(1, 0.1, 0.6)));
  out.markers.push_back(
      TextMarker(header, "chosen", 1, step.chosen.X_WC.translation() + Eigen::Vector3d(0, 0, 0.06),
                 fmt::format("view {} (rank {}): utility {:.3g}, gain {:.3g}, cost {:.3g} rad [{}]",
                             step.view + 1, step.chosen_rank, step.chosen.utility, step.chosen.gain,
                             step.chosen.cost, step.chosen.source),
                 0.03, Rgba(1, 1, 1, 1)));
  // The camera's planned path to it (docs/motion.md): red when the simulator saw a contact.
  if (step.motion.camera_path_W.size() >= 2) {
    const bool touched = step.motion.contacts && step.motion.contacts->total() > 0;
    out.markers.push_back(LineStripMarker(header, "path", 2, step.motion.camera_path_W, 0.005,
                                          touched ? Rgba(1, 0.1, 0.1) : Rgba(0.2, 0.9, 1.0)));
  }
  return out;
}

Result<std::unique_ptr<RvizPublisher>> RvizPublisher::Create(ros::dds::Node& node,
                                                             const RvizOptions& options,
                                                             SemanticClass target) {
  std::unique_ptr<RvizPublisher> p(new RvizPublisher(options, target));
  const ros::dds::QosProfile latched = ros::dds::QosProfile::Latched();
  AVP_ASSIGN_OR_RETURN(p->octomap_,
                       node.CreatePublisher<ros::msg::Octomap>(options.octomap_topic, latched));
  AVP_ASSIGN_OR_RETURN(p->voxels_,
                       node.CreatePublisher<ros::msg::MarkerArray>(options.voxels_topic, latched));
  AVP_ASSIGN_OR_RETURN(p->candidates_, node.CreatePublisher<ros::msg::MarkerArray>(
                                           options.candidates_topic, latched));
  AVP_ASSIGN_OR_RETURN(p->chosen_,
                       node.CreatePublisher<ros::msg::MarkerArray>(options.chosen_topic, latched));
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
  ros::msg::Header header;
  header.stamp = ros::msg::Time::FromNanoseconds(NowNs());
  header.frame_id = options_.frame;
  Result<mapping::OctomapBinaryData> tree = mapping::OctomapBinaryMessageData(map.grid());
  if (tree.ok()) {
    ros::msg::Octomap msg;
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
  ros::msg::Header header;
  header.stamp = ros::msg::Time::FromNanoseconds(NowNs());
  header.frame_id = options_.frame;
  Report(candidates_->Publish(CandidateMarkers(step, header)), options_.candidates_topic);
  Report(chosen_->Publish(ChosenMarkers(step, header)), options_.chosen_topic);
}

void RvizPublisher::OnEnd(const pipeline::EpisodeResult&, const mapping::SemanticMap& map) {
  PublishMap(map);
}

}  // namespace avp::ros::live
