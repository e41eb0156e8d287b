// A learned per-point descriptor (thesis ch. 6) that replaces FPFH in the same correspondence
// search → RANSAC / FGR → ICP → validation: a PointNet++ segmentation network (farthest-point
// sampling, ball query, multi-scale grouping, feature propagation back to every point, a linear
// head to K features, L2-normalised) run with libtorch on the CPU. libtorch stays inside
// src/localization/learned_descriptor*.cpp and descriptor_training.cpp: this header has no torch.
//
// Rotation handling (DescriptorNetConfig::rotation):
//  - "lrf": every group's coordinates (and, in the first layer, its normals) are expressed in a
//    local reference frame of its centre (PCA of the group, z along the point's normal, x along
//    the major axis with its sign taken towards the heavier side): the output does not change
//    when the cloud is turned, up to flips of that sign on near-isotropic patches.
//  - "augment": the thesis's way, coordinates in the cloud's frame, the network trained on turned
//    copies; the matcher then computes the model's descriptors at several rotations and keeps
//    the best RANSAC result (MatchingConfig::learned_rotations).
// docs/learned_descriptors.md has the figures.
#pragma once
#include <Eigen/Core>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace cellsight {

/// A model file that cannot be used (missing, truncated, wrong shapes, K different from the
/// configuration's): the message names the file and the cause.
struct DescriptorModelError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// The architecture; written into the model file and read back with it.
struct DescriptorNetConfig {
  int dims = 16;                  ///< K, features per point (16 or 32)
  std::string rotation = "lrf";   ///< "lrf" | "augment"
  double unit = 0.01;             ///< metres per network length unit (the parts are 5-12 units)
  int width = 32;                 ///< channels of the first layers (deeper layers: 2x, 4x)
  /// set-abstraction levels: centres (farthest-point sampling), two ball radii each (units),
  /// and the group sizes of the two scales. Two levels (the widest ball 15 mm): a local
  /// descriptor like FPFH's 10 mm; with a third (30 mm) the descriptors learn a view's context,
  /// which the whole model does not share, and validation recall fell as training went on.
  std::vector<int> centres = {512, 128};
  /// When set (one per level, units): farthest-point sampling goes on until every point lies
  /// within this distance of a centre, whatever the cloud's extent, and `centres` is not used.
  /// A fixed count spreads its centres over the whole cloud: a part inside a whole scene then
  /// gets far fewer of them than the part alone, and its descriptors differ.
  std::vector<double> centre_spacing;
  std::vector<double> radius_small = {0.4, 1.0};
  std::vector<double> radius_large = {0.8, 1.5};
  std::vector<int> samples_small = {16, 16};
  std::vector<int> samples_large = {32, 32};
  /// > 0 (units): every point's FPFH over this radius is an input too, through its own MLP
  /// added at the head (zero-initialised: a network fine-tuned with it starts where it was).
  double fpfh_radius = 0;
  double point_radius = 0.5;      ///< units, the per-point encoder's neighbourhood
  int point_samples = 16;
};

/// Throws DescriptorModelError naming the first invalid setting.
void checkDescriptorNetConfig(const DescriptorNetConfig& c);

/// Wall-clock seconds of the stages of one compute() call.
struct DescriptorTiming {
  double structure_seconds = 0;  ///< sampling, ball queries, reference frames
  double network_seconds = 0;    ///< the forward pass
};

class LearnedDescriptor {
 public:
  /// A network with fresh (seeded) weights.
  explicit LearnedDescriptor(const DescriptorNetConfig& config, uint64_t seed = 1);
  ~LearnedDescriptor();
  LearnedDescriptor(LearnedDescriptor&&) noexcept;
  LearnedDescriptor& operator=(LearnedDescriptor&&) noexcept;

  /// Loads a model file written by save(); `expected_dims` > 0 must equal its K. Throws
  /// DescriptorModelError (missing, truncated, not a model, a tensor of the wrong shape, K).
  static LearnedDescriptor load(const std::string& path, int expected_dims = 0);
  /// Writes the weights and the architecture atomically (a temporary file renamed).
  void save(const std::string& path) const;

  const DescriptorNetConfig& config() const;
  /// The same weights under `config`, which may differ from config() only in the centres'
  /// sampling (`centres`, `centre_spacing`: no weight depends on how many centres there are) and
  /// in an added FPFH input (`fpfh_radius`; its branch starts at zero). Throws
  /// DescriptorModelError for any other difference, a dropped tensor or an invalid setting.
  LearnedDescriptor withConfig(const DescriptorNetConfig& config) const;
  size_t parameterCount() const;

  /// Descriptors of every point: rows = points, K columns, unit length. `points` and `normals`
  /// (unit, oriented: towards the camera for a scan, outwards for a model) in metres, any
  /// frame; `scale` multiplies the coordinates before the network (parts far larger or smaller
  /// than those it was trained on). Non-finite points get a zero row. Throws
  /// std::invalid_argument for fewer than 2 finite points or a points/normals size mismatch.
  /// Clouds above `max_points` are refused the same way (memory grows with the points).
  Eigen::MatrixXf compute(const std::vector<Eigen::Vector3f>& points, const std::vector<Eigen::Vector3f>& normals,
                          double scale = 1.0, DescriptorTiming* timing = nullptr) const;
  static constexpr size_t max_points = 200000;

  /// intra-op threads of libtorch for this process (the matcher runs one pair per thread: 1)
  static void setThreads(int threads);

  struct Impl;  // the torch module (descriptor_training.cpp trains it)
  Impl& impl() const { return *impl_; }

 private:
  LearnedDescriptor() = default;
  std::unique_ptr<Impl> impl_;
};

/// The turns of the multi-rotation matching: the identity, then n − 1 uniform rotations from a
/// fixed seeded sequence (the matcher and the evaluation use the same ones).
std::vector<Eigen::Matrix3f> descriptorTurns(int n);

/// Mutual nearest neighbours (Euclidean) between two descriptor sets (rows; learned or FPFH),
/// the distances from one matrix product; one-way when fewer than `min_mutual` are mutual.
/// Pairs (row of a, row of b). Rows that are all zero (no descriptor) take no part.
std::vector<std::pair<int, int>> matchDescriptors(const Eigen::MatrixXf& a, const Eigen::MatrixXf& b, bool mutual = true,
                                                  int min_mutual = 12);

/// The k nearest rows of b (Euclidean) for every row of a, nearest first: pairs (row of a, row
/// of b), one way. Rows that are all zero or not finite take no part; k larger than b's usable
/// rows gives them all.
std::vector<std::pair<int, int>> nearestDescriptors(const Eigen::MatrixXf& a, const Eigen::MatrixXf& b, int k);

}  // namespace cellsight
