#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include <avp/core/image.h>

namespace avp {

/// One ground-truth fruit as a simulator knows it (for segmenters that imitate a detector).
struct GroundTruthFruit {
  uint16_t instance_id = 0;
  Eigen::Vector3d center_W = Eigen::Vector3d::Zero();
  double radius_m = 0.0;
};

/// What a simulator knows about a frame: its label images and fruits. Only simulation segmenters
/// (oracle) read it; real segmenters ignore it.
struct SimulatorLabels {
  InstanceImage instance_ids;  ///< object instance id per pixel, 0 = background
  ClassImage class_ids;        ///< SemanticClass per pixel, 0 = background
  std::vector<GroundTruthFruit> fruits;
};

}  // namespace avp
