// Private to the core's PCL translation units: ScanCloud → PCL cloud (x y z intensity).
#pragma once
#include <pcl/point_cloud.h>

#include "cellsight/common/scan_cloud.hpp"

namespace cellsight {

/// PointT needs x, y, z and intensity; other fields are left default.
template <typename PointT>
typename pcl::PointCloud<PointT>::Ptr toPclXyzi(const ScanCloud& c) {
  typename pcl::PointCloud<PointT>::Ptr out(new pcl::PointCloud<PointT>);
  out->resize(c.size());
  for (size_t i = 0; i < c.size(); ++i) {
    PointT& p = (*out)[i];
    p.x = c.points[i].x();
    p.y = c.points[i].y();
    p.z = c.points[i].z();
    p.intensity = i < c.intensity.size() ? c.intensity[i] : 0.f;
  }
  out->width = static_cast<uint32_t>(c.size());
  out->height = 1;
  out->is_dense = true;
  return out;
}

}  // namespace cellsight
