// The simulated cell for rviz: the table, the parts as triangle lists, the fixtures' plates and
// the light sheet's fan (carried by the laser frame). Built by the simulator node only.
#pragma once
#include <visualization_msgs/MarkerArray.h>

#include "cellsight/sim/scene.hpp"

namespace cellsight_ros {

visualization_msgs::MarkerArray cellMarkers(const cellsight::Scene& scene);

}  // namespace cellsight_ros
