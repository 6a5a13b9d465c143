#include "avp/ros/msg/markers.h"

#include <utility>

#include <avp/ros/msg/convert.h>

namespace avp::ros::msg {

namespace {

Marker Base(const Header& header, std::string_view ns, int id, int32_t type) {
  Marker m;
  m.header = header;
  m.ns = std::string(ns);
  m.id = id;
  m.type = type;
  m.action = Marker::kAdd;
  m.pose.orientation.w = 1.0;
  return m;
}

}  // namespace

Marker DeleteAllMarker(const Header& header) {
  Marker m;
  m.header = header;
  m.action = Marker::kDeleteAll;
  m.pose.orientation.w = 1.0;
  return m;
}

Marker ArrowMarker(const Header& header, std::string_view ns, int id, const Eigen::Vector3d& from,
                   const Eigen::Vector3d& to, const Vector3& scale, const ColorRGBA& color) {
  Marker m = Base(header, ns, id, Marker::kArrow);
  m.scale = scale;
  m.color = color;
  m.points.push_back(ToPointMsg(from));
  m.points.push_back(ToPointMsg(to));
  return m;
}

Marker ViewArrowMarker(const Header& header, std::string_view ns, int id,
                       const RigidTransform& X_WC, double length, const Vector3& scale,
                       const ColorRGBA& color) {
  const Eigen::Vector3d a = X_WC.translation();
  return ArrowMarker(header, ns, id, a, a + length * X_WC.rotation().col(2), scale, color);
}

Marker SphereMarker(const Header& header, std::string_view ns, int id,
                    const Eigen::Vector3d& center, double diameter_m, const ColorRGBA& color) {
  Marker m = Base(header, ns, id, Marker::kSphere);
  m.pose.position = ToPointMsg(center);
  m.scale = {diameter_m, diameter_m, diameter_m};
  m.color = color;
  return m;
}

Marker LineStripMarker(const Header& header, std::string_view ns, int id,
                       const std::vector<Eigen::Vector3d>& points, double width_m,
                       const ColorRGBA& color) {
  Marker m = Base(header, ns, id, Marker::kLineStrip);
  m.scale = {width_m, 0.0, 0.0};
  m.color = color;
  for (const Eigen::Vector3d& p : points) m.points.push_back(ToPointMsg(p));
  return m;
}

Marker TextMarker(const Header& header, std::string_view ns, int id,
                  const Eigen::Vector3d& position, std::string text, double height_m,
                  const ColorRGBA& color) {
  Marker m = Base(header, ns, id, Marker::kTextViewFacing);
  m.pose.position = ToPointMsg(position);
  m.scale = {0.0, 0.0, height_m};
  m.color = color;
  m.text = std::move(text);
  return m;
}

Marker CubeListMarker(const Header& header, std::string_view ns, double size_m) {
  Marker m = Base(header, ns, 0, Marker::kCubeList);
  m.scale = {size_m, size_m, size_m};
  m.color = Rgba(1, 1, 1, 1);
  return m;
}

MarkerArray FruitMarkers(const std::vector<GroundTruthFruit>& fruits, const Header& header) {
  MarkerArray out;
  for (const GroundTruthFruit& f : fruits) {
    out.markers.push_back(SphereMarker(header, "fruit", f.instance_id, f.center_W, 2.0 * f.radius_m,
                                       {1.0f, 0.2f, 0.1f, 0.5f}));
  }
  return out;
}

std::vector<GroundTruthFruit> FruitsFromMarkers(const MarkerArray& markers) {
  std::vector<GroundTruthFruit> fruits;
  for (const Marker& m : markers.markers) {
    if (m.id <= 0 || m.id > 65535) continue;
    fruits.push_back({static_cast<uint16_t>(m.id), FromPointMsg(m.pose.position), 0.5 * m.scale.x});
  }
  return fruits;
}

}  // namespace avp::ros::msg
