#pragma once

// The RViz markers avp writes (visualization_msgs/Marker), built in one place: the recorder's
// candidate arrows (ros/bag), the live RViz publisher's map, candidates and chosen view
// (ros/live), and the simulator's fruit (ros/simrobot), which `avp live` reads back
// (FruitsFromMarkers).

#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include <avp/core/simulator_labels.h>
#include <avp/core/transform.h>
#include <avp/ros/msg/messages.h>

namespace avp::ros::msg {

/// DELETEALL: clears the namespace's earlier markers (the first marker of every array avp
/// publishes, so that an array replaces the previous one).
Marker DeleteAllMarker(const Header& header);

/// An arrow from `from` to `to` (RViz arrows given by points: the pose is the identity). `scale`
/// is shaft diameter, head diameter, head length.
Marker ArrowMarker(const Header& header, std::string_view ns, int id, const Eigen::Vector3d& from,
                   const Eigen::Vector3d& to, const Vector3& scale, const ColorRGBA& color);

/// An arrow along a camera's optical axis (+z of its optical frame), `length` metres from its
/// centre: how avp draws views.
Marker ViewArrowMarker(const Header& header, std::string_view ns, int id,
                       const RigidTransform& X_WC, double length, const Vector3& scale,
                       const ColorRGBA& color);

/// A sphere of `diameter_m` at `center`.
Marker SphereMarker(const Header& header, std::string_view ns, int id,
                    const Eigen::Vector3d& center, double diameter_m, const ColorRGBA& color);

/// A LINE_STRIP through `points` (a path), `width_m` wide.
Marker LineStripMarker(const Header& header, std::string_view ns, int id,
                       const std::vector<Eigen::Vector3d>& points, double width_m,
                       const ColorRGBA& color);

/// View-facing text of `height_m` at `position`.
Marker TextMarker(const Header& header, std::string_view ns, int id,
                  const Eigen::Vector3d& position, std::string text, double height_m,
                  const ColorRGBA& color);

/// An empty CUBE_LIST of cubes of `size_m` (the caller adds points and colours).
Marker CubeListMarker(const Header& header, std::string_view ns, double size_m);

/// The simulator's fruit as markers: DELETEALL-free, one sphere per fruit (ns "fruit", id = its
/// instance id, diameter twice its radius), half-transparent red.
MarkerArray FruitMarkers(const std::vector<GroundTruthFruit>& fruits, const Header& header);
/// FruitMarkers read back: each marker with an id in [1, 65535] is a fruit (centre = position,
/// radius = half of scale.x).
std::vector<GroundTruthFruit> FruitsFromMarkers(const MarkerArray& markers);

}  // namespace avp::ros::msg
