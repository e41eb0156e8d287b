// Grasps for a parallel-jaw gripper. A grasp is the tool centre point's pose in the part's model
// frame (T_model_tcp): tcp z points into the part (the approach), the jaws close along tcp x.
// Candidates come from the part's model.yaml (grasp_frame: z normal to the gripped face, the tcp
// `grip_depth` below it, the jaws turned about z in steps) and, beyond the thesis, from antipodal
// sampling on the mesh (a surface point, the ray through the part to its far side, contact
// normals inside the friction cone, several approach directions about the closing axis).
// Symmetric parts add their equivalent grasps. Every candidate is measured between the pads (ray
// casts across the pad area): opening, contact normals, centring; what fails is kept with its reason.
#pragma once
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "cellsight/common/mesh.hpp"
#include "cellsight/common/model_info.hpp"

namespace cellsight {

struct GripperConfig {
  double max_opening = 0.08;   ///< m between the pads, fully open (the URDF's finger travel)
  double clearance = 0.005;    ///< m opened beyond the part on each side before closing
  double min_width = 0.003;    ///< m: narrower is not a grip
  double pad_length = 0.02;    ///< m along tcp z, centred on the tcp
  double pad_width = 0.02;     ///< m along tcp y
  double grip_depth = 0.008;   ///< m: model grasps put the tcp this far below the grasp frame
  double friction = 0.4;       ///< Coulomb μ: contact normals within atan(μ) of the closing axis
  int yaw_steps = 8;           ///< model grasps: jaw directions tried about the grasp z
  int antipodal_samples = 400; ///< surface points tried per part
  int approach_steps = 8;      ///< antipodal grasps: approach directions about the closing axis
  int axial_steps = 12;        ///< axial symmetry: equivalents per grasp
  uint64_t seed = 1;
};

struct GraspCandidate {
  Eigen::Isometry3d T_model_tcp = Eigen::Isometry3d::Identity();
  double width = 0;           ///< m, the part between the pads
  double friction_margin = 0; ///< rad: the friction cone's half angle minus the worse contact angle
  double centroid_distance = 0;  ///< m from the tcp to the part's surface centroid
  std::string source;         ///< "model", "antipodal"; "+symmetry" for an equivalent
  bool valid = false;
  std::string reason;         ///< why not valid
};

/// Every candidate of a part (valid or not, with the reason), in model coordinates.
std::vector<GraspCandidate> graspCandidates(const ModelInfo& info, const TriangleMesh& mesh, const GripperConfig& config);

/// Measures one tcp pose between the pads: fills width, friction margin, centroid distance, and
/// re-centres the tcp along x between the contacts. Sets valid/reason.
GraspCandidate measureGrasp(const TriangleMesh& mesh, const Eigen::Isometry3d& T_model_tcp, const GripperConfig& config,
                            const std::string& source);

/// The motions of the model frame that leave the part unchanged (identity first): discrete
/// order n gives n turns about the axis through the model origin, axial `axial_steps`, none 1;
/// spherical gives `axial_steps` turns about z through `centroid` (the sphere's centre).
std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>> symmetryRotations(
    const ModelInfo& info, int axial_steps, const Eigen::Vector3d& centroid = Eigen::Vector3d::Zero());

}  // namespace cellsight
