#include "cell_markers.hpp"

#include <cmath>

#include "cellsight/common/mesh.hpp"
#include "cellsight_ros/conversions.hpp"

namespace cellsight_ros {

visualization_msgs::MarkerArray cellMarkers(const cellsight::Scene& s) {
  visualization_msgs::MarkerArray arr;
  int id = 0;
  auto base = [&](const std::string& ns) {
    visualization_msgs::Marker m;
    m.header.frame_id = s.base_frame;
    m.ns = ns;
    m.id = id++;
    m.action = visualization_msgs::Marker::ADD;
    m.pose.orientation.w = 1;
    m.scale.x = m.scale.y = m.scale.z = 1;
    m.color.a = 1;
    return m;
  };
  visualization_msgs::Marker table = base("table");
  table.type = visualization_msgs::Marker::CUBE;
  table.pose.position.x = s.table.center.x();
  table.pose.position.y = s.table.center.y();
  table.pose.position.z = s.table.z - 0.01;
  table.scale.x = s.table.size.x();
  table.scale.y = s.table.size.y();
  table.scale.z = 0.02;
  table.color.r = table.color.g = table.color.b = 0.45f;
  arr.markers.push_back(table);
  for (const auto& o : s.objects) {
    visualization_msgs::Marker m = base("objects");
    m.type = visualization_msgs::Marker::TRIANGLE_LIST;
    m.pose = cellsight_ros::toPoseMsg(o.T_base_object);
    m.points = cellsight_ros::meshTriangles(cellsight::loadValidMesh(o.info.mesh_file));
    m.color.r = 0.2f + 0.6f * static_cast<float>(o.reflectivity);
    m.color.g = 0.55f;
    m.color.b = 0.75f;
    arr.markers.push_back(m);
  }
  for (const auto& f : s.fixtures) {
    visualization_msgs::Marker m = base("fixtures");
    m.type = visualization_msgs::Marker::CUBE;
    m.pose = cellsight_ros::toPoseMsg(f.T_base_fixture);
    m.scale.x = m.scale.y = f.plate_size;
    m.scale.z = 0.003;
    m.color.r = m.color.g = m.color.b = 0.95f;
    arr.markers.push_back(m);
  }
  // The light sheet as a translucent fan in the laser frame: rviz carries it with the flange.
  visualization_msgs::Marker fan = base("laser_sheet");
  fan.header.frame_id = s.laser_frame;
  fan.type = visualization_msgs::Marker::TRIANGLE_LIST;
  const double reach = 0.45, half = s.laser.fan_angle / 2;
  const int n = 24;
  for (int i = 0; i < n; ++i) {
    const double a0 = -half + 2 * half * i / n, a1 = -half + 2 * half * (i + 1) / n;
    geometry_msgs::Point o, p0, p1;
    p0.x = reach * std::sin(a0);
    p0.z = reach * std::cos(a0);
    p1.x = reach * std::sin(a1);
    p1.z = reach * std::cos(a1);
    fan.points.insert(fan.points.end(), {o, p0, p1});
  }
  fan.color.r = 1.0f;
  fan.color.g = 0.1f;
  fan.color.b = 0.1f;
  fan.color.a = 0.25f;
  arr.markers.push_back(fan);
  return arr;
}

}  // namespace cellsight_ros
