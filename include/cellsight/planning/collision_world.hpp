// The cell as the planner avoids it: the table as a box, every located part as its model mesh at
// the located pose, and whatever else the scan saw (unknown objects, parts not found) as an
// OctoMap of the scan points that no located part explains. Collision checks with FCL for the
// arm's link shapes, the gripper's fingers and a carried part; self-collision of the tool and the
// carried part against the base, column and upper arm. FCL and OctoMap stay behind the pimpl.
#pragma once
#include <Eigen/Geometry>
#include <memory>
#include <string>
#include <vector>

#include "cellsight/common/mesh.hpp"
#include "cellsight/planning/arm_model.hpp"

namespace cellsight {

struct CollisionWorldConfig {
  double octree_resolution = 0.004;  ///< m, voxel edge of the unexplained scan points
  double table_margin = 0.003;       ///< m: scan points lower than table z + this are the table
  double explained_margin = 0.004;   ///< m: scan points this close to a located part are that part
  double padding = 0.002;            ///< m added around the arm's and gripper's shapes
  /// m: the carried part may sink this far into the table without counting as a collision (the
  /// parts rest on it; a located pose may lie a little low). The object a part is inserted into
  /// is left out of check() by `ignore_object` (GraspPlanner: on the insertion's last stretch only).
  double contact_allowance = 0.004;
  int min_voxel_points = 2;          ///< scan points needed before a voxel counts as occupied
};

/// What collides with what (empty when nothing does).
struct CollisionReport {
  bool collides = false;
  /// m: when free, a lower bound of the gap between the padded shapes and everything they were
  /// checked against (bounding-box distances; 0 when a box overlaps one; pairs of moving shapes
  /// count half). The motion may move every point this far (plus the padding) before the next check.
  double clearance = 0;
  std::string first;   ///< e.g. "finger_left" or "carried part"
  std::string second;  ///< e.g. "scan voxels", "table", "object housing", "link_1"
  std::string text() const { return collides ? first + " vs " + second : "free"; }
};

/// A part held in the gripper: its mesh and its pose in the tcp frame. It is checked as its
/// bounding box in the model frame, padded like the arm (conservative for concave parts).
struct CarriedPart {
  std::shared_ptr<const TriangleMesh> mesh;
  Eigen::Isometry3d T_tcp_part = Eigen::Isometry3d::Identity();
  std::string name;
};

class CollisionWorld {
 public:
  /// The table: its top at `table_z`, `table_size` (x, y) around `table_center`.
  CollisionWorld(const CollisionWorldConfig& config, double table_z, const Eigen::Vector2d& table_center,
                 const Eigen::Vector2d& table_size);
  ~CollisionWorld();
  CollisionWorld(const CollisionWorld&);  ///< deep enough: obstacles are shared read-only
  CollisionWorld& operator=(const CollisionWorld&) = delete;

  /// A located part as an obstacle; returns its id. Throws std::invalid_argument on an empty mesh.
  int addObject(const std::string& name, std::shared_ptr<const TriangleMesh> mesh, const Eigen::Isometry3d& pose);
  void removeObject(int id);
  /// Moves an object (a part placed elsewhere).
  void moveObject(int id, const Eigen::Isometry3d& pose);
  bool hasObject(int id) const;
  /// Builds the OctoMap from the scan points that no object explains and that lie above the
  /// table; non-finite points are skipped. Returns the number of occupied voxels.
  size_t setScan(const std::vector<Eigen::Vector3f>& points);
  size_t occupiedVoxels() const;
  /// Occupied voxel centres (for markers).
  std::vector<Eigen::Vector3d> voxelCentres() const;
  double voxelSize() const { return config_.octree_resolution; }

  /// The arm at q with the jaws `opening` apart, optionally carrying a part. `ignore_object`:
  /// an object the carried part may touch (the one it is inserted into); −1 for none.
  CollisionReport check(const ArmModel& arm, const JointVector& q, double opening, const CarriedPart* carried = nullptr,
                        int ignore_object = -1) const;

  const CollisionWorldConfig& config() const { return config_; }
  /// Another padding around the arm's shapes from now on (0: the bare shapes, for re-checks).
  void setPadding(double padding);

 private:
  CollisionWorldConfig config_;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace cellsight
