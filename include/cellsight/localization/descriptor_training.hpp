// Training material and training for the learned descriptor, with no download: single views of
// meshes scanned by a laser-line model (the fixed camera's visibility, the moving light sheet's
// shadows, depth noise along the camera ray), voxelised as the matcher sees a cluster, with the
// true model-frame position of every point, so the correspondences of two views are known.
// Meshes: our parts (config/models) and generated ones (unions of boxes, cylinders and tubes).
#pragma once
#include <Eigen/Geometry>
#include <functional>
#include <string>
#include <vector>

#include "cellsight/common/mesh.hpp"
#include "cellsight/common/scan_cloud.hpp"
#include "cellsight/localization/learned_descriptor.hpp"

namespace cellsight {

/// How a view is scanned. Frames: the mesh is placed by `pose` in a world whose z is up.
struct LaserViewSetup {
  Eigen::Vector3f eye = Eigen::Vector3f(0.f, -0.35f, 0.65f);  ///< camera centre
  Eigen::Vector3f projector = Eigen::Vector3f(0.f, 0.2f, 0.35f);  ///< light source at the sweep's middle
  Eigen::Vector3f sweep = Eigen::Vector3f::UnitX();  ///< direction the projector moves (unit)
  Eigen::Vector3f sheet_normal = Eigen::Vector3f::UnitX();  ///< of the light sheet (unit; sweep · normal ≠ 0)
  double sample_spacing = 0.0007;  ///< m, surface samples before the voxel grid
  double noise = 0.00005;          ///< m, depth noise along the camera ray (1 σ)
  double max_view_angle = 1.40;    ///< rad, beyond it neither camera nor laser sees a face
  double voxel = 0.002;            ///< m, the matcher's coarse grid
  double normal_radius = 0.005;    ///< m, PCA normals as the matcher estimates them
};

/// A random scanning geometry around a part at the origin: the camera 0.5–0.8 m away within
/// 35° of vertical, the light sheet 15–40° from the camera's rays, any sweep direction.
LaserViewSetup randomLaserSetup(uint64_t seed);

struct LaserView {
  ScanCloud cloud;  ///< world frame, voxel centroids with PCA normals towards the eye
  std::vector<Eigen::Vector3f> truth;  ///< model frame: where each point is on the part (noise-free)
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  ///< model → world
};

/// One single view of `mesh` placed at `pose`. Points the camera does not see, or the light
/// sheet never reaches unshadowed, are missing. `samples`: the mesh's dense surface samples
/// (sampleMesh at setup.sample_spacing), when the caller keeps them for many views.
LaserView laserView(const TriangleMesh& mesh, const Eigen::Isometry3d& pose, const LaserViewSetup& setup, uint64_t seed,
                    const ScanCloud* samples = nullptr);

/// The whole model as the matcher prepares it: the mesh sampled at `voxel` (cell centroids) with
/// PCA normals over normal_radius, turned outwards; truth = the points themselves.
LaserView modelCloud(const TriangleMesh& mesh, double voxel = 0.002, double normal_radius = 0.005, uint64_t seed = 1);

/// A generated training mesh: 1–4 boxes, cylinders or tubes of 8–80 mm overlapping or touching.
TriangleMesh randomPartMesh(uint64_t seed);

/// A generated freeform mesh (toys, animals, fruit, castings): 1–5 smooth blobs — spheres with
/// rippled radii, stretched, bent and twisted — a body of 15–60 mm and limbs rooted on it.
TriangleMesh randomFreeformMesh(uint64_t seed);

/// Pairs (index in a, index in b) whose true positions lie within `tolerance` (each point of a
/// with its nearest in b).
std::vector<std::pair<int, int>> trueCorrespondences(const LaserView& a, const LaserView& b, double tolerance);

/// FPFH of a cloud with normals (PCL, support `radius`) as descriptor rows, for matchDescriptors.
Eigen::MatrixXf fpfhRows(const ScanCloud& cloud_with_normals, double radius);

/// A pair counts towards feature-match recall when at least this share of its matches is
/// correct (the 3DMatch convention).
constexpr double kMatchedPairShare = 0.05;

/// The 3DMatch-style figures of one pair: descriptors matched (nearest in b for every point of a,
/// mutual when enough), a match correct when its true positions lie within `tolerance`.
struct PairMatchFigures {
  size_t matches = 0, correct = 0;
  double inlier_ratio = 0;  ///< correct / matches
  bool matched() const { return inlier_ratio >= kMatchedPairShare; }
};
PairMatchFigures pairMatchFigures(const LaserView& a, const Eigen::MatrixXf& da, const LaserView& b,
                                  const Eigen::MatrixXf& db, double tolerance);

// ------------------------------------------------------------------------------- training

struct DescriptorTrainingConfig {
  DescriptorNetConfig net;
  std::string output = "config/descriptors/learned_k16.pt";  ///< the model file (atomic writes)
  std::string checkpoint;          ///< resumable state (weights, optimiser, step); empty: output + ".ckpt"
  bool resume = false;             ///< continue from the checkpoint if there is one
  int steps = 6000;                ///< optimiser steps (one pair of views each)
  double time_limit_s = 0;         ///< stop (and save) after this many seconds; 0: none
  double learning_rate = 1e-3;     ///< Adam
  std::string loss = "contrastive";  ///< contrastive (margin, hardest negative) | triplet (hardest in batch)
  double margin = 1.0;             ///< of the hinge on descriptor distance
  int anchors = 256;               ///< corresponding points per pair in the loss
  double positive_radius = 0.0015; ///< m, true distance for a correspondence
  double negative_radius = 0.010;  ///< m, a negative lies farther than this from the positive
  int negative_pool = 512;         ///< random points of each side the hardest negative is taken from
  double model_pair_share = 0.5;   ///< share of pairs that are (view, whole model) — the matcher's use
  std::vector<std::string> model_meshes;  ///< our parts' meshes used in training
  int generated_meshes = 200;      ///< plus this many generated ones (randomPartMesh)
  int freeform_meshes = 0;         ///< plus this many generated freeform ones (randomFreeformMesh)
  double noise_max = 0;            ///< m; > 0: each view's depth noise drawn log-uniformly from
                                   ///< 30 µm to this (other sensors than ours); 0: the laser scanner's
  std::string init_model;          ///< start from this model file's weights (fine-tuning); empty: fresh
  int validate_every = 250;        ///< steps between validation figures (and checkpoints)
  int validation_pairs = 24;       ///< fixed pairs of held-out viewpoints of the training meshes
  int threads = 2;                 ///< libtorch intra-op threads
  uint64_t seed = 7;
  bool progress = true;            ///< a progress bar on stderr
};

struct DescriptorTrainingReport {
  int steps = 0;
  double seconds = 0, last_loss = 0, validation_recall = 0, best_validation_recall = 0;
  size_t parameters = 0;
};

/// Trains (or resumes) and writes the model file with the best validation figure (feature-match
/// recall, share of validation pairs with ≥ 5 % correct matches). `log` gets one line per
/// validation.
DescriptorTrainingReport trainDescriptor(const DescriptorTrainingConfig& config,
                                         const std::function<void(const std::string&)>& log = {});

}  // namespace cellsight
