// The accumulated scan as plain arrays (no PCL type in this header), and the cloud operations
// the scanner needs; PCL does the work inside scan_cloud.cpp.
#pragma once
#include <Eigen/Geometry>
#include <string>
#include <vector>

namespace cellsight {

struct ScanCloud {
  std::vector<Eigen::Vector3f> points;   ///< metres, in `frame_id`
  std::vector<Eigen::Vector3f> normals;  ///< empty until estimateNormals
  std::vector<float> intensity;
  std::string frame_id = "base_link";
  size_t size() const { return points.size(); }
  void append(const Eigen::Vector3f& p, float i) {
    points.push_back(p);
    intensity.push_back(i);
  }
};

/// Drops points whose mean distance to their k nearest neighbours exceeds the global mean by
/// more than std_mul standard deviations (the thesis's statistical filter; PCL's SOR).
ScanCloud statisticalOutlierRemoval(const ScanCloud& in, int k = 20, double std_mul = 2.5);
/// Keeps the points inside the box.
ScanCloud cropBox(const ScanCloud& in, const Eigen::AlignedBox3f& box);
/// Normals from k neighbours, oriented towards `viewpoint` (e.g. the camera centre).
void estimateNormals(ScanCloud& cloud, int k, const Eigen::Vector3f& viewpoint);

/// Median distance from a point to its nearest neighbour, over up to `samples` points spread
/// evenly through the cloud (the scan's resolution); 0 for fewer than 2 points.
double medianPointSpacing(const ScanCloud& cloud, size_t samples = 2000);
/// The scan's scatter off its surface: the median, over up to `samples` points spread evenly
/// through the cloud, of the RMS distance of the points within `radius` of a point from their
/// best-fit plane, over n - 3 degrees of freedom (points with fewer than 6 such neighbours are
/// skipped). It holds the sensor's noise and the surface's curvature at that scale, and reads low
/// for noise near `radius` (the ball cuts it off). 0 when no point has 6 neighbours.
double medianPlaneResidual(const ScanCloud& cloud, double radius, size_t samples = 2000);
/// Removes non-finite points; returns how many were removed.
size_t removeNonFinite(ScanCloud& cloud);

/// Writes PLY (binary) or PCD (binary) by extension, atomically. Throws std::runtime_error.
void saveCloud(const std::string& path, const ScanCloud& cloud);
/// Reads PLY (ascii / binary little-endian) or PCD (ascii / binary / binary_compressed): x y z,
/// optional intensity and normals (normal_x… or nx…); non-finite points dropped. Own readers,
/// bounded by the file's size: PCL's readers trust their headers and crash on malformed files
/// (fuzz_cloud, docs/reliability.md). Throws ConfigError naming the file.
ScanCloud loadCloud(const std::string& path);
/// The same through PCL's readers (after checkCloudFile), kept for comparison; loadCloud and
/// this agree on valid files (test_common).
ScanCloud loadCloudWithPcl(const std::string& path);
/// Reads the file as loadCloud does and throws what it would (empty file, counts that are not
/// counts, fields that disagree, a body shorter than announced, text where numbers belong).
void checkCloudFile(const std::string& path);

}  // namespace cellsight
