// Private to src/localization/matching/: the data shared by the matching stages (per-model
// index with its distance field, prepared scene, coarse hypotheses, ICP rows) and the stage
// functions' declarations. PCL types stay here and in the stage files, out of the public header.
#pragma once
#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_types.h>

#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "cellsight/common/closest_point_grid.hpp"
#include "cellsight/common/mesh.hpp"
#include "cellsight/common/point_grid.hpp"
#include "cellsight/common/raycaster.hpp"
#include "cellsight/common/scan_cloud.hpp"
#include "cellsight/localization/model_library.hpp"
#include "cellsight/localization/model_matching.hpp"
#include "cellsight/localization/rest_poses.hpp"

namespace cellsight {
namespace matching_detail {

using Clock = std::chrono::steady_clock;
using Vec3 = Eigen::Vector3f;

inline double seconds(Clock::time_point a) { return std::chrono::duration<double>(Clock::now() - a).count(); }

template <typename Fn>
void parallelFor(size_t n, int threads, Fn fn) {
  const int t = std::max(1, std::min<int>(threads, static_cast<int>(n)));
  if (t <= 1) {
    for (size_t i = 0; i < n; ++i) fn(i);
    return;
  }
  std::atomic<size_t> next{0};
  std::vector<std::thread> pool;
  for (int k = 0; k < t; ++k) {
    pool.emplace_back([&] {
      for (size_t i = next++; i < n; i = next++) fn(i);
    });
  }
  for (auto& th : pool) th.join();
}

/// Regular grid over the model's neighbourhood: per cell, the index of the fine model point
/// nearest to the cell centre (−1 outside the margin).
struct DistanceField {
  Vec3 origin = Vec3::Zero();
  float cell = 0.001f;
  Eigen::Vector3i dims = Eigen::Vector3i::Zero();
  std::vector<int32_t> nearest;
  int lookup(const Vec3& q) const {
    const Eigen::Vector3f g = (q - origin) / cell;
    if (!(g.x() >= 0 && g.y() >= 0 && g.z() >= 0 && g.x() < dims.x() && g.y() < dims.y() && g.z() < dims.z())) return -1;
    const int x = static_cast<int>(g.x()), y = static_cast<int>(g.y()), z = static_cast<int>(g.z());
    return nearest[(static_cast<size_t>(z) * dims.y() + y) * dims.x() + x];
  }
};

/// Angle bin of a cosine (acos quantised through a table: the same function builds the model
/// table and keys the scene, so the bins only need to be consistent, and 8192 steps of the
/// cosine keep them within a fraction of a bin of acos).
class AngleBins {
 public:
  AngleBins() = default;
  explicit AngleBins(int bins) : bins_(bins), lut_(kSize + 1) {
    for (int i = 0; i <= kSize; ++i) {
      const float c = -1.f + 2.f * static_cast<float>(i) / kSize;
      lut_[i] = static_cast<uint8_t>(std::min(bins - 1, static_cast<int>(std::acos(c) * bins / static_cast<float>(M_PI))));
    }
  }
  int operator()(float c) const {
    const int i = static_cast<int>((std::clamp(c, -1.f, 1.f) + 1.f) * (0.5f * kSize) + 0.5f);
    return lut_[i];
  }
  int bins() const { return bins_; }

 private:
  static constexpr int kSize = 8192;
  int bins_ = 0;
  std::vector<uint8_t> lut_;
};

/// Point pair feature hash table of a model: key → (reference point, angle α_m of the pair
/// about the reference normal).
struct PpfTable {
  float dist_step = 0.003f;
  int angle_bins = 30;
  AngleBins angles;  // bins of angle_bins, shared by the model table and the scene's keys
  struct Entry {
    int32_t cell;   // first accumulator cell of the reference point: ref × angle_bins
    float alpha;    // α_m in bins: (α_m + π) · angle_bins / 2π, in [0, angle_bins)
  };
  std::vector<Entry> entries;    // sorted by key
  std::vector<uint32_t> offset;  // entries of key k: [offset[k], offset[k + 1]) (dense: O(1) lookup)
  std::vector<uint64_t> keys;    // instead of `offset` when the key range is too large for it:
                                 // each entry's key, searched (two binary searches)
  static constexpr uint64_t kMaxDenseKeys = 1ull << 24;  // 64 MB of offsets
  std::pair<size_t, size_t> range(uint64_t key) const {
    if (!keys.empty()) {
      auto lo = std::lower_bound(keys.begin(), keys.end(), key);
      auto hi = std::upper_bound(lo, keys.end(), key);
      return {static_cast<size_t>(lo - keys.begin()), static_cast<size_t>(hi - keys.begin())};
    }
    if (key + 1 >= offset.size()) return {0, 0};
    return {offset[key], offset[key + 1]};
  }
};

}  // namespace matching_detail

namespace matching_detail {
/// A flat face of a model mesh (a group of coplanar triangles): outward normal, centroid,
/// major in-plane axis, area. A cluster that is mostly one flat patch is aligned with these.
struct FacePatch {
  Vec3 n = Vec3::UnitZ(), c = Vec3::Zero(), axis = Vec3::UnitX();
  float area = 0;
};
std::vector<FacePatch> facePatches(const TriangleMesh& mesh, const PlanarFaces& faces, float min_area);
}  // namespace matching_detail

struct ModelMatcher::ModelIndex {
  std::string id;
  ModelInfo info;
  std::shared_ptr<const ScanCloud> coarse;  // at config.voxel, PCA normals (as a scan sees them)
  std::vector<Fpfh> fpfh;                   // of coarse (invalid ones zeroed)
  pcl::KdTreeFLANN<pcl::FPFHSignature33> fpfh_tree;
  std::vector<int> fpfh_valid;              // coarse indices with a valid descriptor
  std::vector<Eigen::MatrixXf> learned;     // descriptor: learned, per turn of learned_rotations (rows: coarse)
  std::shared_ptr<const ScanCloud> fine;    // at config.icp_spacing
  pcl::KdTreeFLANN<pcl::PointXYZ> fine_tree;
  matching_detail::DistanceField field;
  ScanCloud ppf_cloud;  // coarse cloud thinned to ppf_sampling
  matching_detail::PpfTable ppf;  // its point pair features (Drost et al. 2010)
  RayCaster caster;  // the mesh in the model frame (self-occlusion)
  ClosestPointGrid closest;  // candidate triangles per cell for the polish (empty: Embree only)
  PlanarFaces faces;         // flat faces and their creases (slack centring)
  std::vector<matching_detail::FacePatch> patches;  // the larger flat faces (planar-view hypotheses)
  bool has_mesh = true;  // false for a cloud model: visibility from the normals only
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  float diameter = 0;
  std::vector<Eigen::Vector3f> extremes;  // mesh vertices (cloud models: coarse points), for the support test
  std::vector<RestPose> rests;            // how it can lie on a table (rest hypotheses; none for a sphere)
  std::vector<Eigen::Vector2f> rest_top;  // per rest: the in-plane centroid of its upward faces (rest frame)
  std::vector<std::vector<Eigen::Vector2f>> rest_top_hull;  // ... and their outline (convex hull, rest frame)
};

namespace matching_detail {

/// Where the support (the table the clustering removed) was seen: a bitmap of cells on the
/// plane, eroded by one cell so that silhouettes blurred by calibration and mixed pixels do not
/// count. A model point the camera would see, whose view ray runs on to a seen cell, cannot be
/// there: the camera saw through it (free-space violation).
struct SupportSeen {
  Eigen::Vector3f n = Eigen::Vector3f::UnitZ(), u = Eigen::Vector3f::UnitX(), v = Eigen::Vector3f::UnitY();
  float d = 0, cell = 0.002f;
  Eigen::Vector2f lo = Eigen::Vector2f::Zero();
  int nu = 0, nv = 0;
  std::vector<uint8_t> seen;
  PointGrid points;  ///< the support's points themselves
  bool empty() const { return seen.empty(); }
  /// the view ray eye → p meets the plane on a seen cell (p above the plane by > min_height)
  bool seenBehind(const Vec3& eye, const Vec3& p, float min_height) const;
  /// the view ray eye → p meets the plane within r of a support point (p above it by > min_height)
  bool measuredBehind(const Vec3& eye, const Vec3& p, float min_height, float r) const;
  /// the view ray eye → p continued to the plane, at *q (false: p within min_height of the plane,
  /// or the eye not above it)
  bool behind(const Vec3& eye, const Vec3& p, float min_height, Vec3* q) const;
};
SupportSeen buildSupportSeen(const std::vector<Vec3>& points, const Eigen::Vector4f& plane, float cell);

/// The plane most of a cluster lies on, when it does (a part seen only by one flat face).
struct ScenePlane {
  bool found = false;
  Vec3 n = Vec3::UnitZ(), c = Vec3::Zero(), axis = Vec3::UnitX();  // normal towards the viewpoint, centroid, major axis
  float area = 0;  // m², from the inliers' voxel count
};

/// Points less than this far inside the sheet's fan (rad) lie at its edge: the calibrated laser
/// frame puts the fan's apex and axis within about a degree of the projector's, and the line
/// extraction loses the last millimetres of a line. The unseen test counts only points farther
/// in; the rest hypotheses take a cluster ending there as cut by the fan.
constexpr float kFanEdgeMargin = 0.035f;

/// One cluster prepared once for every model: coarse points with normals and FPFH, the points
/// ICP uses, and a k-d tree over all its points for the fitness test.
struct SceneData {
  ScenePlane plane;
  const SupportSeen* support_seen = nullptr;  // shared by the clusters of one locate() call
  const LightSweep* light = nullptr;          // the scan's sheet (null: camera visibility only)
  /// every cluster's points (shared by the clusters of one locate() call; null: this cluster's):
  /// the fitness test, so that a part that clustering split is not short of its own points
  const PointGrid* whole = nullptr;
  /// parts already found, each its model and T_model_scene: the unseen test's rays and beams stop
  /// at them too (a found part's side the scan did not measure still casts its shadow); null: none
  const std::vector<std::pair<const ModelMatcher::ModelIndex*, Eigen::Isometry3f>>* found = nullptr;
  std::vector<Vec3> all;       // finite input points
  ScanCloud coarse;            // voxelised, normals toward the viewpoint
  std::vector<Fpfh> fpfh;
  std::vector<int> fpfh_valid;
  pcl::KdTreeFLANN<pcl::FPFHSignature33> fpfh_tree;
  Eigen::MatrixXf learned;     // descriptor: learned, a row per coarse point
  ScanCloud ppf;               // coarse thinned to ppf_sampling
  std::vector<Vec3> icp_points;
  PointGrid grid;                        // over `all` (scene_search: grid)
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;  // over `all` (scene_search: kdtree)
  float diameter = 0;  // lower bound of the largest point distance
};

struct Correspondence {
  int scene, model;
};

struct Hypothesis {
  Eigen::Isometry3f T = Eigen::Isometry3f::Identity();  // model → scene
  int score = 0;
};

/// One scene point in the ICP's exact polish (model frame).
struct PolishRow {
  Eigen::Vector3d q, n;  // the point; the face normal, or (outside) the direction from its closest point
  double r;              // signed distance along n
  int tri = -1;          // its closest mesh triangle (-1: not from the mesh)
  bool outside = false;  // beyond an edge or corner: closest to it
};

struct Refined {
  Eigen::Isometry3f T = Eigen::Isometry3f::Identity();
  double rmse = 0;
  std::vector<PolishRow> polished;  // the exact polish's last rows, at T (mesh models)
  bool polished_fresh = false;      // their distances hold at T (the last step was below 1 µm)
};

// ---- scene_preparation.cpp
pcl::PointCloud<pcl::PointXYZ>::Ptr toXyz(const std::vector<Vec3>& pts);
pcl::PointCloud<pcl::FPFHSignature33>::Ptr toPclFpfh(const std::vector<Fpfh>& f);
bool validFpfh(const Fpfh& f);
/// Thins a cloud with normals to one point per cell (the first one met).
ScanCloud thinned(const ScanCloud& c, double cell);
std::unique_ptr<SceneData> prepareScene(const std::vector<Vec3>& finite, const MatchingConfig& cfg);
/// The cluster's plane when >= 60 % of its coarse points lie within inlier_distance / 2 of it.
ScenePlane scenePlane(const ScanCloud& coarse, const MatchingConfig& cfg);
/// At most `cap` points: a voxel grid of `leaf` (cell centroids), then every k-th point.
std::vector<Vec3> capPoints(const std::vector<Vec3>& pts, double leaf, size_t cap);

// ---- hypothesis_scoring.cpp
/// Counts scene points explained by the model under T (model → scene), with early exit when
/// the first `probe` points already promise less than `floor`.
int scoreHypothesis(const SceneData& s, const std::vector<int>& order, const ModelMatcher::ModelIndex& m,
                    const Eigen::Isometry3f& T, float inlier2, float cos_normal, int probe, double floor_share);
/// Whether two poses differ by more than dt (m) or 0.2 rad.
bool distinct(const Eigen::Isometry3f& a, const Eigen::Isometry3f& b, float dt);

// ---- ppf.cpp
/// Poses that lay a model's flat faces onto the cluster's plane (ScenePlane), centroid on
/// centroid, turned about the normal in steps of 30° from the major axes: the hypotheses for a
/// part seen by one flat face only, whose point pairs all share one feature that PPF leaves out.
std::vector<Hypothesis> planarHypotheses(const SceneData& s, const ModelMatcher::ModelIndex& m, size_t max_faces);
/// The point pair feature table of a model cloud with normals (features shared by more than
/// max_bucket pairs left out).
PpfTable buildPpf(const ScanCloud& c, float dist_step, int bins, size_t max_bucket);
/// The model's stable rests (rest_poses.hpp) and, per rest, where its upward faces lie.
void addRests(ModelMatcher::ModelIndex& m);
/// PPF candidates → best `refine_candidates` distinct poses by their distance-field score; with
/// a support plane and rest_candidates, the best distinct poses of the model resting on it too.
std::vector<Hypothesis> ppfHypotheses(const SceneData& s, const ModelMatcher::ModelIndex& m, const MatchingConfig& cfg,
                                      const Eigen::Vector4f* support, int* iterations);

// ---- fpfh_ransac.cpp
/// FPFH matches scene → model (mutual when at least min_correspondences survive the filter).
/// descriptor: learned — mutual nearest neighbours against the model's descriptors at turn `turn`
std::vector<Correspondence> learnedCorrespondences(const SceneData& s, const ModelMatcher::ModelIndex& m, size_t turn,
                                                   const MatchingConfig& cfg);
std::vector<Correspondence> correspondences(const SceneData& s, const ModelMatcher::ModelIndex& m,
                                            const MatchingConfig& cfg);
/// RANSAC over 3-point hypotheses: the best refine_candidates distinct poses.
std::vector<Hypothesis> ransac(const SceneData& s, const ModelMatcher::ModelIndex& m,
                               const std::vector<Correspondence>& corr, const MatchingConfig& cfg, uint64_t seed,
                               int* iterations);

// ---- icp.cpp
/// The mesh's closest point to q (model frame) within max_d: the candidate grid, else Embree.
ClosestPoint meshClosest(const ModelMatcher::ModelIndex& m, const Eigen::Vector3f& q, float max_d);
/// The directions a pose step may take (orthonormal columns in the steps' scaled coordinates:
/// turn × half the diameter, then translation): all six, or with `up` (model frame) the turn
/// about it and the three translations.
Eigen::Matrix<double, 6, Eigen::Dynamic> stepBasis(const Eigen::Vector3d* up);
/// Robust point-to-plane ICP of the scene points onto the model (Huber weights, shrinking
/// correspondence distance); distance-field correspondences, then exact ones.
/// `max_points`: the scene points used (evenly thinned); `polish`: finish with exact neighbours.
/// `up` (scene frame, unit): the pose's tilt is held, its steps turn about `up` only.
Refined icp(const SceneData& s, const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T0,
            const MatchingConfig& cfg, size_t max_points, bool polish, const Eigen::Vector3d* up = nullptr);

// ---- slack_centring.cpp
/// Centres a polished pose in the slack its scanned faces leave (see slack_centring.cpp).
/// Rotates the rows with the pose; returns the change (model frame, applied after X).
/// `up` (model frame, unit): only turns about it and translations are followed (tilt held).
Eigen::Isometry3d centreInSlack(const ModelMatcher::ModelIndex& m, std::vector<PolishRow>& rows, bool fresh,
                                const MatchingConfig& cfg, const Eigen::Vector3d* up = nullptr);

// ---- validation.cpp
/// Share of the coarse scene points within r of the model under T.
double coverage(const SceneData& s, const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T, double r);
/// Share of the model's points visible from the viewpoint (facing it, not hidden by the part
/// itself) that have a scene point within r_F.
/// see_through (optional): share of those visible points whose view ray runs on to seen support.
/// unseen (optional; 0 without a light sweep or a scene grid): share of those visible points the
/// scan should have measured and did not (MatchingConfig::max_unseen).
/// overhang (optional; 0 without support points): share of those visible points whose view ray
/// runs on to a measured support point, with no scan point near them (MatchingConfig::max_overhang).
/// With cfg.fitness_incidence_mid > 0 the share weighs each visible point by the scanner's
/// response at its camera incidence (see_through and unseen count them alike).
double visibleFitness(const SceneData& s, const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T,
                      const MatchingConfig& cfg, double* see_through = nullptr, double* unseen = nullptr,
                      double* overhang = nullptr);
/// Cluster points (s.coarse) carrying on a face of the model under T past its edge, per cluster
/// point the model explains (MatchingConfig::max_continuation); support: points within
/// continuation_reach of it are left out.
double continuation(const SceneData& s, const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T,
                    const MatchingConfig& cfg, const Eigen::Vector4f* support);
/// How far the model under T reaches below the support plane (m; <= 0: not at all).
float belowSupport(const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T, const Eigen::Vector4f& plane);
/// The pose is not physical for a part resting on the support: sunk deeper than
/// max_support_penetration, or (max_support_gap > 0) its lowest point higher than that above
/// it; `slack` widens both (coarse poses are a few millimetres off).
bool offSupport(const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T, const Eigen::Vector4f& plane,
                const MatchingConfig& cfg, float slack = 0.f);
/// The detection passes min_fitness, min_coverage, max_rmse, max_see_through, max_unseen and
/// max_continuation (1: off).
bool accepted(const PartDetection& d, const MatchingConfig& cfg);
/// ... with this fitness floor instead of min_fitness.
bool accepted(const PartDetection& d, const MatchingConfig& cfg, double min_fitness);

// ---- pair_matching.cpp
/// The unseen share and continuation of d under T, traced only for a pose that passes every
/// other test (the fitness at half its floor) with a sweep; 0 otherwise.
void traceSurfaceTests(const SceneData& s, const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T,
                       const MatchingConfig& cfg, const Eigen::Vector4f* support, PartDetection* d);
/// One (cluster, model) pair from the coarse stage to its best screened and polished pose.
PartDetection matchPair(const SceneData& s, const ModelMatcher::ModelIndex& m, const MatchingConfig& cfg,
                        const Eigen::Vector4f* support, uint64_t seed);
/// The found pose, or one turned about the support's normal that fits about as closely and
/// scores higher (MatchingConfig::turned_poses); *turned: whether it was turned.
PartDetection turnedPose(const SceneData& s, const ModelMatcher::ModelIndex& m, const MatchingConfig& cfg,
                         const Eigen::Vector4f* support, const PartDetection& found, bool* turned);
/// `d` polished and centred from T0 on `points` (a scene of their own, with the whole-scan grid,
/// support and sweep where given) into *r; false when the ICP diverged or left the support.
bool polishOn(std::vector<Vec3> points, const ModelMatcher::ModelIndex& m, const MatchingConfig& cfg,
              const Eigen::Vector4f* support_plane, const PartDetection& d, const Eigen::Isometry3f& T0,
              const PointGrid* whole, const SupportSeen* seen, const LightSweep* light, PartDetection* r);

// ---- found_parts.cpp
/// A scan point's distance to a model (Ti: the inverse of its pose); infinite beyond `radius`.
float modelDistance(const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& Ti, const Vec3& p, float radius);

/// Found parts at their poses, for handing scan points to them: a point belongs to the part
/// whose model lies nearest it, within `radius`.
struct FoundParts {
  std::vector<const ModelMatcher::ModelIndex*> model;  // per part
  std::vector<Eigen::Isometry3f> Tinv;
  std::vector<Vec3> centre;
  std::vector<float> reach;  // no point of part i lies farther from its centre (its centroid lies inside)
  float radius = 0;
  FoundParts(const std::vector<PartDetection>& parts, std::vector<const ModelMatcher::ModelIndex*> models, float r);
  /// p's distance to part i's model at its pose (infinite beyond the radius)
  float distance(size_t i, const Vec3& p) const;
  /// the part p belongs to (-1: none within the radius)
  int owner(const Vec3& p) const;
  /// another part than i lies nearer p than d
  bool nearerOther(size_t i, const Vec3& p, float d) const;
};

/// How far a model point moves from pose a to pose b, the part's symmetry taken out (m).
double modelMove(const ModelMatcher::ModelIndex& m, const Eigen::Isometry3d& a, const Eigen::Isometry3d& b);
/// A detection whose pose moved from `before` to d->pose: its ambiguous turns moved with it.
void carryTurns(const ModelMatcher::ModelIndex& m, const Eigen::Isometry3d& before, PartDetection* d);
/// The index of model `id` among the call's `models` (idx[i] indexes models[i]; id is one of them).
const ModelMatcher::ModelIndex& indexOf(const std::vector<std::shared_ptr<const ModelMatcher::ModelIndex>>& idx,
                                        const std::vector<std::string>& models, const std::string& id);
/// Found parts that clustering split polished again on every scan point near their model that
/// lies nearer them than any other part (MatchingConfig::polish_split_parts).
void polishSplitParts(std::vector<PartDetection>& parts, const std::vector<std::shared_ptr<const ModelMatcher::ModelIndex>>& idx,
                      const std::vector<std::string>& models, const std::vector<Vec3>& scan,
                      const std::vector<int>& scan_cluster, const PointGrid& whole, const SupportSeen& seen,
                      const LightSweep* light, const Eigen::Vector4f* support_plane, const MatchingConfig& cfg,
                      MatchStats& st);
/// The share of space two detections would hold together (the larger interpenetration share).
double sharedSpace(const PartDetection& a, const ModelMatcher::ModelIndex& ma, const PartDetection& b,
                   const ModelMatcher::ModelIndex& mb, float depth);
/// Drops every detection that shares space with a better explained one (max_interpenetration).
void dropInterpenetrating(std::vector<PartDetection>& kept, const std::vector<std::shared_ptr<const ModelMatcher::ModelIndex>>& idx,
                          const std::vector<std::string>& models, const MatchingConfig& cfg, MatchStats& st);
/// Refused poses tested again with the found parts as occluders, accepted if they pass then
/// (MatchingConfig::unseen_second_look).
void unseenSecondLook(std::vector<PartDetection>& kept, const std::vector<std::shared_ptr<const ModelMatcher::ModelIndex>>& idx,
                      const std::vector<std::string>& models, const std::vector<ScanCloud>& clusters, const PointGrid& whole,
                      const SupportSeen& seen, const LightSweep* light, const MatchingConfig& cfg, MatchStats& st);
/// Refused pieces of split parts polished on the scan points near their model that no found part
/// lies nearer, accepted if they pass then (MatchingConfig::split_second_look).
void splitSecondLook(std::vector<PartDetection>& kept, const std::vector<std::shared_ptr<const ModelMatcher::ModelIndex>>& idx,
                     const std::vector<std::string>& models, const std::vector<ScanCloud>& clusters,
                     const std::vector<Vec3>& scan, const std::vector<int>& scan_cluster, const PointGrid& whole,
                     const SupportSeen& seen, const LightSweep* light, const Eigen::Vector4f* support_plane,
                     const MatchingConfig& cfg, MatchStats& st);

}  // namespace matching_detail
}  // namespace cellsight
