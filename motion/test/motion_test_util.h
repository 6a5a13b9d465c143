#pragma once

#include <cmath>
#include <initializer_list>

#include <Eigen/Core>

#include <avp/core/box.h>
#include <avp/mapping/voxel_grid.h>
#include <avp/motion/robot_geometry.h>
#include <avp/robot/arm_model.h>

namespace avp::motion::testing {

inline const robot::ArmModel& DefaultArm() {
  static const robot::ArmModel model = robot::LoadDefaultArm(AVP_CONFIG_DIR).value();
  return model;
}

inline const RobotGeometry& DefaultGeometry() {
  static const RobotGeometry geometry = RobotGeometry::Create(DefaultArm()).value();
  return geometry;
}

inline Eigen::VectorXd Deg(std::initializer_list<double> degrees) {
  Eigen::VectorXd q(static_cast<Eigen::Index>(degrees.size()));
  Eigen::Index i = 0;
  for (double d : degrees) q[i++] = d * M_PI / 180.0;
  return q;
}

/// Marks every voxel whose centre lies in `box` occupied (log-odds +2) in `grid`.
inline void FillOccupied(mapping::OccupancyGrid& grid, const Box3& box) {
  const double s = grid.voxel_size_m();
  const VoxelKey lo = grid.KeyOf(box.min());
  const VoxelKey hi = grid.KeyOf(box.max());
  for (int x = lo.x; x <= hi.x; ++x) {
    for (int y = lo.y; y <= hi.y; ++y) {
      for (int z = lo.z; z <= hi.z; ++z) {
        const VoxelKey k{x, y, z};
        if (box.Contains(k.Center(s))) grid.SetLogOdds(k, 2.0f);
      }
    }
  }
}

/// The distance from p to the closest point of an axis-aligned cube of edge `s` at `center`.
inline double DistanceToCube(const Eigen::Vector3d& p, const Eigen::Vector3d& center, double s) {
  const Eigen::Vector3d d = ((p - center).cwiseAbs().array() - 0.5 * s).cwiseMax(0.0).matrix();
  return d.norm();
}

}  // namespace avp::motion::testing
