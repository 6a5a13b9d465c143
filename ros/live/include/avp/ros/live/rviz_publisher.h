#pragma once

#include <memory>
#include <string>

#include <avp/core/options.h>
#include <avp/core/status.h>
#include <avp/pipeline/episode.h>
#include <avp/ros/dds/node.h>
#include <avp/ros/msg/messages.h>

namespace avp::ros::live {

/// What avp live shows in RViz (configs/rviz/avp.rviz), all reliable + transient local so a
/// late RViz gets the latest.
struct RvizOptions {
  bool enabled = true;
  std::string frame = "igus_rebel_base_link";
  /// octomap_msgs/Octomap, binary (octomap_rviz_plugins, octomap_server).
  std::string octomap_topic = "/avp/map/octomap";
  /// MarkerArray: occupied voxels as CUBE_LISTs in namespaces "class", "instance" and
  /// "confidence" (toggle them in RViz), and the fruit found ("fruit": a sphere and a label each).
  std::string voxels_topic = "/avp/map/voxels";
  /// MarkerArray: the ranked candidate views as arrows coloured by utility (viridis).
  std::string candidates_topic = "/avp/nbv/candidates";
  /// MarkerArray: the chosen view (arrow) and its utility terms (text).
  std::string chosen_topic = "/avp/nbv/chosen";
};
const OptionTable<RvizOptions>& RvizOptionTable();

/// The markers for one map (exposed for tests): occupied voxels by class, instance and
/// confidence, and the fruit instances of `target`.
ros::msg::MarkerArray VoxelMarkers(const mapping::SemanticMap& map, SemanticClass target,
                                   const ros::msg::Header& header);
/// The ranked candidates of a step as arrows coloured by utility, and the chosen view.
ros::msg::MarkerArray CandidateMarkers(const pipeline::StepRecord& step,
                                       const ros::msg::Header& header);
ros::msg::MarkerArray ChosenMarkers(const pipeline::StepRecord& step,
                                    const ros::msg::Header& header);

/// An episode observer that publishes the map and the planner's view after every step.
/// Publishing errors are logged once per topic, never fatal.
class RvizPublisher final : public pipeline::EpisodeObserver {
 public:
  static Result<std::unique_ptr<RvizPublisher>> Create(ros::dds::Node& node,
                                                       const RvizOptions& options,
                                                       SemanticClass target);
  void OnStep(const pipeline::StepRecord& step, const mapping::SemanticMap& map) override;
  void OnEnd(const pipeline::EpisodeResult& result, const mapping::SemanticMap& map) override;
  uint64_t published() const { return published_; }

 private:
  RvizPublisher(const RvizOptions& options, SemanticClass target)
      : options_(options), target_(target) {}
  void PublishMap(const mapping::SemanticMap& map);
  void Report(const Status& s, const std::string& topic);

  RvizOptions options_;
  SemanticClass target_;
  uint64_t published_ = 0;
  std::string last_error_topic_;
  std::unique_ptr<ros::dds::Publisher<ros::msg::Octomap>> octomap_;
  std::unique_ptr<ros::dds::Publisher<ros::msg::MarkerArray>> voxels_, candidates_, chosen_;
};

}  // namespace avp::ros::live
