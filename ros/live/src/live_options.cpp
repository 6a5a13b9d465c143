#include <fmt/format.h>

#include <avp/ros/live/live_options.h>

namespace avp::ros::live {

const OptionTable<LiveOptions>& LiveOptionTable() {
  static const auto* table = [] {
    using O = LiveOptions;
    auto* t = new OptionTable<O>("live option");
    t->Text("node_name", &O::node_name, "the ROS 2 node's name");
    t->Text("node_namespace", &O::node_namespace, "the ROS 2 node's namespace");
    t->Integer("domain_id", &O::domain_id, "", ValueRange::Closed(-1, 232),
               "ROS_DOMAIN_ID (-1: the environment's, else 0)");
    t->Choice("distro", &O::distro,
              {{ros::msg::RosDistro::kHumble, "humble"}, {ros::msg::RosDistro::kJazzy, "jazzy"}},
              "the peers' ROS 2 distribution (humble, or jazzy for Iron and later)");
    t->Nested("camera", &O::camera, CameraTopicsOptionTable());
    t->Nested("arm", &O::arm, ArmTopicsOptionTable());
    t->Nested("rviz", &O::rviz, RvizOptionTable());
    t->RealList("roi_min_m", &O::roi_min_m, "m", ValueRange::Closed(-100, 100), 0, 3,
                "the region of interest's min corner in the base frame (x,y,z)");
    t->RealList("roi_max_m", &O::roi_max_m, "m", ValueRange::Closed(-100, 100), 0, 3,
                "the region of interest's max corner in the base frame (x,y,z)");
    t->Real("timeout_s", &O::timeout_s, "s", ValueRange::Closed(0, 1e6),
            "stop the episode after this long (0: no limit)");
    t->AddRule([](const O& o, std::vector<std::string>& errors) {
      if (o.roi_min_m.size() != o.roi_max_m.size() ||
          (!o.roi_min_m.empty() && o.roi_min_m.size() != 3)) {
        errors.push_back("roi_min_m and roi_max_m must both be x,y,z (or both empty)");
      } else if (!o.roi_min_m.empty()) {
        for (size_t i = 0; i < 3; ++i) {
          if (!(o.roi_min_m[i] < o.roi_max_m[i])) {
            errors.push_back(
                fmt::format("roi_min_m ({}) must be below roi_max_m ({}) on every axis",
                            fmt::join(o.roi_min_m, ","), fmt::join(o.roi_max_m, ",")));
            break;
          }
        }
      }
    });
    return t;
  }();
  return *table;
}

Result<Box3> LiveOptions::Roi() const {
  if (roi_min_m.size() != 3 || roi_max_m.size() != 3) {
    return InvalidArgumentError(
        "live.roi_min_m and live.roi_max_m (the plant's region of interest in the base frame) are "
        "required when no scenario or scene is named");
  }
  return Box3(Eigen::Vector3d(roi_min_m[0], roi_min_m[1], roi_min_m[2]),
              Eigen::Vector3d(roi_max_m[0], roi_max_m[1], roi_max_m[2]));
}

ros::dds::NodeOptions NodeOptionsOf(const LiveOptions& options) {
  ros::dds::NodeOptions n;
  n.name = options.node_name;
  n.namespace_ = options.node_namespace;
  n.domain_id = options.domain_id;
  n.distro = options.distro;
  return n;
}

}  // namespace avp::ros::live
