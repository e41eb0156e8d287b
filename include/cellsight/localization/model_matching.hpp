// Model matching: a coarse pose per model and cluster — point pair feature voting (default), or
// the thesis's FPFH correspondences + RANSAC (Algorithm 5.1), or Open3D's FGR — hypotheses scored
// against a precomputed distance field of the model, robust point-to-plane ICP with an exact mesh
// polish, centring in the pose's slack, and validation by fitness over the model's *visible*
// surface (single-view scans see a part from one side), scene coverage and RMSE. Symmetric parts
// are reported in a canonical pose. One stage per file: docs/localization.md.
// PCL and Embree stay inside the stage files of src/localization/matching/.
#pragma once
#include <Eigen/Geometry>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "cellsight/localization/learned_descriptor.hpp"
#include "cellsight/localization/light_sweep.hpp"
#include "cellsight/localization/model_library.hpp"
#include "cellsight/common/scan_cloud.hpp"

namespace cellsight {

struct MatchingConfig {
  double voxel = 0.002;            ///< m, coarse resolution of scene and model for descriptors
  double normal_radius = 0.005;    ///< m, scene normals
  double feature_radius = 0.010;   ///< m, FPFH support
  /// Neighbour search over the cluster's points for its normals and the fitness test: "grid"
  /// (a uniform grid, PointGrid; default) or "kdtree" (PCL NormalEstimation and a FLANN k-d
  /// tree, the library path kept for comparison). Same normals; the grid took 0.6 ms where
  /// PCL took 6 ms on a 2 300-point part (docs/localization.md).
  std::string scene_search = "grid";
  bool mutual_filter = true;       ///< keep descriptor matches that are nearest both ways
  int min_correspondences = 12;    ///< below this the mutual filter is relaxed to one-way
  /// Coarse alignment: "ppf" (point pair feature voting, default), "ransac" (FPFH
  /// correspondences + RANSAC, the thesis's method) or "fgr" (FPFH + fast global registration).
  std::string coarse = "ppf";
  /// The per-point descriptor of the ransac and fgr paths: "fpfh" (PCL, feature_radius) or
  /// "learned" (the PointNet++ of learned_descriptor.hpp from learned_model, on the same coarse
  /// points and normals; docs/learned_descriptors.md).
  std::string descriptor = "fpfh";
  /// Model file of the learned descriptor; a relative path is taken from the folder of the
  /// settings file that names it (loadMatchingConfig resolves it).
  std::string learned_model = "descriptors/learned_k16.pt";
  int learned_dims = 16;         ///< K the file must have
  /// the model's descriptors at this many turns (the first: none), RANSAC / FGR on each, the
  /// best kept (the thesis's multi-rotation, for models trained by augmentation; 1: off)
  int learned_rotations = 1;
  double learned_scale = 1.0;    ///< coordinates × this before the network (parts far from 5-12 cm)
  /// a model file that cannot be used: FPFH with a warning (false: the matcher refuses to start)
  bool learned_fallback = true;
  double ppf_sampling = 0.0035;      ///< m, points of model and scene paired
  double ppf_distance_step = 0.003;  ///< m, pair distance quantisation
  int ppf_angle_bins = 30;           ///< angle quantisation (12°) and rotation bins
  int ppf_ref_step = 4;              ///< every n-th scene point is a reference
  /// model pairs one feature may hold; a feature shared by more (two points of one large flat
  /// face differ only in their distance) says little about the pose and is left out of the table
  int ppf_max_bucket = 64;
  /// best-voted poses scored on the distance field, on a quarter of the scene points (at least
  /// 300) in a fixed random order; a pose whose first 64 explain less than half the best pose's
  /// share stops there
  int ppf_candidates = 100;
  /// How RANSAC draws its 3-point hypotheses: "uniform" (three of the mutual descriptor matches,
  /// independently; the thesis's) or "guided" (every scene point's `ransac_neighbours` nearest
  /// model descriptors, one way, mutual_filter and min_correspondences unused; one match drawn,
  /// the other two among the matches whose distances and normal angles agree with it: a
  /// descriptor whose right match is seldom the nearest both ways still yields right poses;
  /// docs/learned_descriptors.md)
  std::string ransac_sampling = "uniform";
  int ransac_neighbours = 1;       ///< guided: nearest model descriptors per scene point (1-64)
  int max_iterations = 100000;     ///< RANSAC hypotheses at most
  double confidence = 0.999;       ///< adaptive RANSAC termination
  double edge_similarity = 0.9;    ///< pre-rejection: edge length ratio scene/model
  double normal_tolerance = 0.5;   ///< rad, pre-rejection normal consistency
  double inlier_distance = 0.003;  ///< m, coarse inlier threshold (≈ 1.5 voxel)
  int refine_candidates = 6;       ///< distinct coarse hypotheses refined by ICP per model
  /// PPF: distinct poses beyond refine_candidates are refined too while their coarse score is
  /// at least this share of the best, up to twice refine_candidates (a part seen mostly by one
  /// flat face: many poses explain nearly every point, and the cut would fall among them). 0: off.
  double refine_candidates_near = 0.95;
  /// PPF with a support plane: this many distinct poses of the model lying on the support in one
  /// of its stable rests (rest_poses.hpp) are refined besides the PPF candidates (a part lying on
  /// a side whose point pairs never vote for its pose). Each rest is turned about the support's
  /// normal in rest_yaw_step steps, centred on the cluster, brought in by a short ICP and scored
  /// on the distance field like a PPF vote. 0: off.
  int rest_candidates = 0;
  double rest_yaw_step = 0.2617993877991494;  ///< rad (15°)
  /// Rest poses are also laid with their upward faces' ends on the cluster's ends along its
  /// major axis, where the cluster reaches farther along it than rest_end_ratio times those
  /// faces (parts touching in one cluster: its centre lies between them). 0: off.
  double rest_end_ratio = 1.2;
  /// With a support plane: a polished pose tilted no more than this from one of the model's
  /// stable rests (and no less than rest_snap_min_angle) is also laid into that rest and polished
  /// again with its tilt held (turns about the support's normal and translations only); the
  /// rested pose is kept where it is accepted and fits within rest_snap_rmse_ratio of the free
  /// pose's RMSE (a part seen only by a narrow top face leaves its tilt to a few points).
  /// 0: off (rad).
  double rest_snap_angle = 0;
  double rest_snap_min_angle = 0.0087;  ///< rad (0.5°): a smaller tilt is the scan's own say
  double rest_snap_rmse_ratio = 1.25;
  double icp_spacing = 0.0005;     ///< m, model sampling for the fine alignment
  int icp_iterations = 40;
  double icp_max_points = 4000;    ///< scene points used by the final ICP (thinned evenly above this)
  double icp_screen_points = 1000; ///< scene points used to refine and rank the coarse candidates
  /// Final exact iterations after the distance field converged (the mesh's closest point, see
  /// icp_mesh_polish; k-d tree neighbours for cloud models).
  int icp_exact_iterations = 6;
  double icp_huber_floor = 0.0005;  ///< m; smallest Huber scale of the ICP residuals
  /// The exact polish measures to the closest point of the model's mesh (Embree point query):
  /// scan points beyond a face's edge are pulled back over it. false: to the nearest fine
  /// sample's tangent plane, which runs on past the edge. Cloud models always use the samples.
  bool icp_mesh_polish = true;
  /// After the polish, move an accepted pose to the middle of its slack: the directions the
  /// scanned faces constrain weakly (eigenvalues of their point-to-plane normal matrix below
  /// icp_slack_eigen_ratio of the largest: a flat top's two shifts and turn) are followed up to
  /// icp_slack_range each way to where scan points leave the mesh by icp_slack_tolerance, and
  /// the pose goes halfway (mesh models only).
  bool icp_centre_slack = true;
  double icp_slack_range = 0.005;       ///< m (turns: the same arc at half the part's diameter)
  double icp_slack_tolerance = 0.0001;  ///< m
  double icp_slack_eigen_ratio = 0.01;
  int icp_slack_steps = 8;              ///< bisection steps in the bracket
  int icp_slack_points = 8;             ///< the k-th scan point leaving ends the slack: k = max(this, points / 500)
  /// Mixed points at an edge: where a scanner's line runs off an edge it reads a little below
  /// the face, and those points are closer to the wall under the edge than to the face they lie
  /// on. Slack centring leaves out the points of a flat face (PlanarFaces group) that has fewer
  /// than icp_edge_support of them beyond icp_edge_band of its creases: a wall the scanner never
  /// saw, which would otherwise end the slack wherever the polish stopped. 0 band: off.
  double icp_edge_band = 0.001;  ///< m
  int icp_edge_support = 3;
  /// refine() on a second scan: a part takes the scan's points within refine_radius of its model
  /// (and nearer it than any other part's); with fewer than refine_min_points, or when the
  /// refined pose moves a model point more than refine_max_shift, it keeps its pose.
  double refine_radius = 0.003;     ///< m
  int refine_min_points = 200;
  double refine_max_shift = 0.002;  ///< m
  /// The polish's closest points from a grid of candidate triangles per cell (ClosestPointGrid,
  /// exact; meshes up to 5 000 faces) instead of Embree's BVH point query for every point
  /// (false: the library path, kept for comparison). Same answers, measured faster on the part
  /// meshes (docs/localization.md).
  bool closest_point_grid = true;
  double fitness_radius = 0.002;   ///< m, r_F
  double min_fitness = 0.30;       ///< share of the model's visible points matched (laser shadows hide some)
  double min_coverage = 0.6;       ///< share of the cluster explained (0: whole-scene search)
  double max_rmse = 0.0015;        ///< m, point-to-plane RMS of the inliers
  bool check_visibility = true;    ///< fitness over points the viewpoint can see
  /// With a LightSweep given to locate(), "visible" asks also that the light sheet
  /// reached the point: facing the emitter within max_view_angle, not shadowed by the part
  /// itself. A part lying on its side shadows most of what the camera sees of it.
  bool check_illumination = true;
  /// Fitness counts scan points of every cluster of the locate() call and its fragments (false:
  /// only the matched cluster's): a part that clustering split is not short of its own points.
  bool fitness_whole_scan = true;
  /// A part found in one cluster whose model, at its pose, lies near points of other clusters or
  /// fragments (clustering split it) is polished again on the scan points near its model, with
  /// refine_radius (docs/localization.md, "Split parts"); false: polished on its cluster only.
  /// Needs fitness_whole_scan (the new pose must explain more of the whole scan).
  bool polish_split_parts = true;
  /// A part seen from one side can fit the scan turned about the support's normal: a holder
  /// lying on an arm shows a 30 x 32 mm face either way. The found pose is also turned by a
  /// quarter, a half and three quarters about the vertical through its scanned points and
  /// polished; among the accepted poses, those whose RMSE is at most the lowest one divided by
  /// turned_rmse_ratio compete on score (docs/localization.md, "Turned poses"). Needs the
  /// support plane (locate() given one); false: the found pose stands.
  bool turned_poses = true;
  double turned_rmse_ratio = 0.7;  ///< (0, 1]; 1: the closest fit wins outright
  /// A found pose is reported ambiguous (PartDetection::ambiguous_poses) when one of its turns that
  /// fits about as closely (turned_rmse_ratio) scores at least this share of its score: the scan
  /// cannot tell the two apart (a holder lying on an arm turned by a half shows the camera the
  /// same face). Reported only; the pose stands. [0, 1]; needs turned_poses.
  double ambiguous_score_ratio = 0.85;
  /// Parts rest on a support (the table the clustering removed): a pose that puts the model more
  /// than this below the support plane is not physical and is discarded before validation
  /// (a thin flat part seen from above fits upside down as well). Used when locate() is given
  /// the plane; metres.
  double max_support_penetration = 0.003;
  /// Parts rest on the support too: a pose whose lowest point is more than this above the
  /// support plane floats and is discarded the same way (a shaft standing on its end seen as
  /// upright with its flange in mid-air, a part fitted onto the top of a box). 0: off (parts
  /// stacked on other parts, bins). Metres.
  double max_support_gap = 0;
  /// At most this share of the model's visible points may lie where the camera saw the support
  /// behind them (locate() given the support's points): a part fitted onto a smaller object
  /// overhangs it, and the table was seen under the overhang. 1: off.
  double max_see_through = 1.0;
  /// At most this share of the model's visible points (PartDetection::overhang) may lie where the
  /// camera's ray past the point ends within overhang_table_radius of a support point the
  /// clustering kept, with no scan point within overhang_clearance of the point itself: the camera
  /// measured the table where the part would hide it. The see-through test's map is eroded by a
  /// cell and the unseen test leaves unseen_radius to a scanner's lost edges; this test reads the
  /// support's points themselves and asks the clearance instead, so it sees a part fitted onto a
  /// smaller object that overhangs it by a few millimetres. Needs the support's points; 1: off.
  double max_overhang = 1.0;
  double overhang_clearance = 0.002;     ///< m
  double overhang_table_radius = 0.001;  ///< m
  /// At most this share of the model's visible points may be surface the scan should have
  /// measured and did not (PartDetection::unseen): seen by the camera and lit by the sheet, both
  /// within unseen_view_angle of the normal, farther than unseen_radius from every scan point and
  /// above the support by more, with no scan point on the camera's ray or the beam to it (nothing
  /// hid it). A part fitted onto a smaller object claims such surface; a true part's misses lie at
  /// its edges, at grazing angles or in another part's shadow. Needs the LightSweep; 1: off.
  double max_unseen = 1.0;
  double unseen_radius = 0.003;      ///< m
  double unseen_view_angle = 1.05;   ///< rad
  /// At most this many cluster points per explained one may carry on a model face's plane past
  /// its edge: farther than fitness_radius from the model and within continuation_reach (which
  /// must exceed it while the test is on), within continuation_tolerance of the plane of a face within that reach whose
  /// normal the scan's there follows (|cos| >= 0.9), above the support by more than
  /// continuation_reach. A part fitted onto a larger object that shares a
  /// face with it (a bracket's plate on a cylinder's top) leaves such points; a true part's
  /// faces end where the scan's do. Taken where unseen is (PartDetection::continuation); 1: off.
  double max_continuation = 1.0;
  double continuation_reach = 0.004;       ///< m
  double continuation_tolerance = 0.00025; ///< m
  /// Two solid parts cannot share space: where more than this share of one detection's model
  /// surface lies deeper than interpenetration_depth inside another's mesh (either way), the
  /// better explained (higher fitness) stays, with a warning naming both (a piece of a part that
  /// clustering split, matched elsewhere on the part's own points). 1: off (config/matching.yaml:
  /// 0.02).
  double max_interpenetration = 1.0;
  double interpenetration_depth = 0.001;  ///< m
  /// Once every part is found, each cluster's best pose refused for unseen surface or fitness alone
  /// (the fitness at half min_fitness at least), clear of the parts found, is tested again with
  /// their models stopping rays and beams too (a part whose side towards it was not measured still
  /// shades it; what a found part hides or shades leaves the fitness), and accepted if it passes then.
  bool unseen_second_look = true;
  /// Once every part is found, each cluster's best refused pose that explains its cluster
  /// (min_coverage) and half of min_fitness, clear of them, whose model lies near points of other
  /// clusters or fragments (a part that clustering split, its small piece matched millimetres
  /// off), is polished on the scan points near its model and accepted if it passes every test
  /// then (docs/localization.md, "Refused pieces of split parts"). Needs fitness_whole_scan.
  bool split_second_look = true;
  Eigen::Vector3f viewpoint = Eigen::Vector3f::Zero();  ///< scene frame (the scanner camera)
  double max_view_angle = 1.40;    ///< rad between normal and view ray for "visible"
  /// The fitness (PartDetection::fitness, and so the ranking) weighs each visible point by the share of
  /// such surface the scanner measures at its camera incidence θ (the angle between its normal
  /// and the ray to the camera): w = 1 / (1 + exp((θ - fitness_incidence_mid) /
  /// fitness_incidence_width)). A part showing the camera mostly steep faces is not refused for
  /// surface the scanner barely measures, and a wrong pose claiming such faces still pays a little
  /// for each. 0: off, every visible point weighs 1.
  double fitness_incidence_mid = 0;      ///< rad
  double fitness_incidence_width = 0.07; ///< rad
  int max_instances = 3;           ///< detections per cluster (touching parts)
  int min_instance_points = 60;    ///< leftover cluster points worth another search
  /// Larger clusters (a whole scene of millions of points sent to the service) are thinned to a
  /// voxel grid of icp_spacing, then evenly, to at most this many points, with a warning: time
  /// and memory stay bounded.
  double max_cluster_points = 300000;
  int threads = 0;                 ///< 0: hardware concurrency
  uint64_t seed = 42;
  /// Folder of prepared models (sampled clouds, descriptors, PPF table, distance field, closest-
  /// point grid), one file per model keyed by its geometry and the settings that shape it; a
  /// model found there is loaded instead of prepared. Empty: no cache.
  std::string model_cache_dir;
};

struct PartDetection {
  std::string model;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  ///< T_scene_model (canonical)
  /// share of visible model points within r_F of the scene (weighted by the scanner's response
  /// with MatchingConfig::fitness_incidence_mid)
  double fitness = 0;
  double coverage = 0;   ///< share of the cluster's points explained by the model
  double rmse = 0;       ///< m
  /// share of the model's visible points through which the camera saw the support behind
  /// (free-space violation; 0 when locate() had no support points)
  double see_through = 0;
  /// share of the model's visible points the camera saw past to a measured support point, with no
  /// scan point near them (MatchingConfig::max_overhang; 0 when locate() had no support points)
  double overhang = 0;
  /// share of the model's visible points the scan should have measured and did not (see
  /// MatchingConfig::max_unseen; computed for poses that pass every other test, the fitness test at
  /// half of min_fitness, with a light sweep; 0 otherwise)
  double unseen = 0;
  /// cluster points carrying on a model face's plane past its edge, per cluster point the model
  /// explains (MatchingConfig::max_continuation; computed where unseen is)
  double continuation = 0;
  double score = 0;      ///< fitness × coverage (ranking)
  /// Other poses of this part, turned about the support's normal, that fit the scan about as
  /// closely (MatchingConfig::turned_poses, turned_rmse_ratio) and score at least
  /// MatchingConfig::ambiguous_score_ratio x score, best first: the scan cannot tell this pose
  /// from them (a grasp may suit them all; a placement does not). Empty: not ambiguous, or not
  /// assessed (a pose accepted at a second look, MatchingConfig::unseen_second_look and
  /// split_second_look, is not turned). A pose polished again later (split parts, refine()) carries
  /// them along, canonical like the pose.
  std::vector<Eigen::Isometry3d> ambiguous_poses;
  /// the best score of a turned pose that fits about as closely, as a share of score when the
  /// turned poses were scored (0: none); what ambiguous_score_ratio is held against
  double alternative_score_share = 0;
  int cluster = -1;      ///< index of the input cluster
  int iterations = 0;    ///< RANSAC hypotheses drawn
  std::string matcher;   ///< the coarse stage: "ppf", "ransac" or "fgr"
  bool refined = false;  ///< refine() moved it to its pose on a second scan
  /// the scan it was found on: 0 the first (locate()), 1 a second pass that mergePasses() added
  int pass = 0;
  double coarse_seconds = 0, refine_seconds = 0;  ///< CPU time of the stages for this pair
  /// A pose in MatchStats::rejected: the acceptance tests it failed, with its figure and the
  /// limit, as refusalReasons() words them (empty for a pose that was accepted).
  std::string refused_by;
};

/// The acceptance tests `d` fails under `c`'s thresholds, e.g. "rmse 0.169 mm > max_rmse
/// 0.160 mm; fitness 0.21 < min_fitness 0.30", in the order fitness, coverage, rmse,
/// see-through, unseen, continuation; "no pose fitted" when the pair reached no scored pose.
/// Empty when every test passes.
std::string refusalReasons(const PartDetection& d, const MatchingConfig& c);

struct MatchStats {
  double seconds = 0;
  /// CPU seconds per stage, summed over clusters and (cluster, model) pairs (threads overlap):
  /// scene preparation (voxels, normals), coarse (PPF/RANSAC/FGR), refinement (ICP, validation)
  double scene_seconds = 0, coarse_seconds = 0, refine_seconds = 0;
  /// of which the learned descriptor (scene clusters; the models' at preparation are not counted)
  double descriptor_seconds = 0;
  size_t pairs = 0, pairs_skipped_by_size = 0;
  /// parts polished again on points of other clusters (polish_split_parts), and how far that
  /// moved them in all (m, a model point's move)
  size_t split_parts_polished = 0;
  double split_polish_moved = 0;
  /// parts whose pose turned about the support's normal fitted the scan about as closely and
  /// scored higher (turned_poses; counted before the pieces of split parts are merged)
  size_t turned_poses = 0;
  /// parts refused for unseen surface alone and accepted at a second look, the parts found
  /// casting their shadows (unseen_second_look)
  size_t unseen_second_look = 0;
  /// refused poses of split parts polished on the points near them and accepted (split_second_look)
  size_t split_second_look = 0;
  /// detections dropped because a better explained one's model holds them (max_interpenetration)
  size_t interpenetrating = 0;
  /// mergePasses(): second-pass detections added (their place free in the first pass), and those
  /// left out because a detection already kept holds their place
  size_t second_pass_added = 0, second_pass_taken = 0;
  std::vector<PartDetection> rejected;  ///< best pose per (cluster, model) that failed validation
  std::vector<std::string> warnings;
};

/// One line per cluster of a locate() call that no detection in `found` came from and whose
/// best refused pose (highest score in `stats.rejected`) had a model fitted: "cluster 3: no part
/// accepted; the best refused, holder (fitness 0.210, coverage 0.800): fitness 0.210 <
/// min_fitness 0.300". Clusters whose every pair fitted nothing are left out.
std::vector<std::string> refusedClusters(const std::vector<PartDetection>& found, const MatchStats& stats);

/// Symmetry-aware pose error about the model centroid: translation of the centroid (m) and
/// rotation (rad; none: full, discrete: best of the n equivalent rotations, axial: angle between
/// the axes, spherical: 0).
struct PoseError {
  double translation = 0, rotation = 0;
};
PoseError poseError(const ModelInfo& info, const Eigen::Vector3d& centroid, const Eigen::Isometry3d& estimate,
                    const Eigen::Isometry3d& truth);

/// The canonical representative of a symmetric pose: axial and discrete symmetries turn about
/// the model's axis (through its origin) so that the model x axis points as close to the scene
/// +x as the symmetry allows; spherical ones keep the centre and take the identity rotation.
Eigen::Isometry3d canonicalPose(const ModelInfo& info, const Eigen::Vector3d& centroid, const Eigen::Isometry3d& pose);

/// The acceptance thresholds of the validation stage: the settings that may change while a
/// matcher runs (model_matching's dynamic_reconfigure), without rebuilding any model data.
/// (The defaults live in MatchingConfig: take them with acceptanceOf({}).)
struct AcceptanceThresholds {
  double min_fitness = 0, min_coverage = 0;
  double max_rmse = 0;  ///< m
  int max_instances = 0;
};
/// Copies the thresholds into anything with fields of the same names (MatchingConfig, the node's
/// dynamic_reconfigure config).
template <typename Config>
void copyAcceptance(const AcceptanceThresholds& t, Config* c) {
  c->min_fitness = t.min_fitness;
  c->min_coverage = t.min_coverage;
  c->max_rmse = t.max_rmse;
  c->max_instances = t.max_instances;
}
AcceptanceThresholds acceptanceOf(const MatchingConfig& c);
/// The rules loadMatchingConfig applies to these keys: {"", ""} when valid, else {key, why}.
std::pair<std::string, std::string> checkAcceptance(const AcceptanceThresholds& t);

class ModelMatcher {
 public:
  ModelMatcher(std::shared_ptr<const ModelLibrary> library, const MatchingConfig& config);
  ~ModelMatcher();

  const MatchingConfig& config() const { return config_; }
  /// Replaces the acceptance thresholds for later locate() calls (not while one runs); throws
  /// ConfigError naming the key when checkAcceptance() refuses them.
  void setAcceptance(const AcceptanceThresholds& t);

  /// Finds instances of `models` (empty: all) in each cluster; clusters × models run in
  /// parallel. Throws std::out_of_range for an unknown model id (before any work). Empty or
  /// all-NaN clusters give a warning and no detection.
  /// `viewpoint` (scene frame) overrides config().viewpoint for this call. `support_plane`
  /// (a, b, c, d of a·x + b·y + c·z + d = 0, unit normal pointing up, scene frame), when given,
  /// discards poses that sink the model into the support or float above it (see
  /// max_support_penetration, max_support_gap). `support_points` (scene frame), the points of
  /// the support the scan saw, with the plane, turn on the free-space test (max_see_through).
  /// `light` (scene frame), the scan's light sheet frame by frame, turns on the illumination
  /// test of the fitness (check_illumination). `fragments` (scene frame), points the scan
  /// measured above the support that are in no cluster (ClusteringResult::fragments), are never
  /// searched but count, with fitness_whole_scan, in the fitness and unseen tests of every pose.
  std::vector<PartDetection> locate(const std::vector<ScanCloud>& clusters, const std::vector<std::string>& models,
                                MatchStats* stats = nullptr, const Eigen::Vector3f* viewpoint = nullptr,
                                const Eigen::Vector4f* support_plane = nullptr,
                                const std::vector<Eigen::Vector3f>* support_points = nullptr,
                                const LightSweep* light = nullptr,
                                const std::vector<Eigen::Vector3f>* fragments = nullptr) const;

  /// Refines located parts (poses as locate() gives them) on another scan of the same cell, its
  /// points above the support (e.g. the clusters of clusterScene, joined): a second pass, e.g.
  /// at right angles to the first, whose lines cross the edges the first ran along. Each part
  /// takes the scan's points within refine_radius of its model and nearer it than any other
  /// part's, and is polished and centred in its slack from its pose as locate() finishes a
  /// detection. A part with fewer than refine_min_points there, whose refined pose is not
  /// accepted, or that would move a model point more than refine_max_shift (its symmetry taken
  /// out) keeps its pose, and a warning in `stats` says why. Returns `parts` in order (`refined`
  /// set where moved).
  /// `viewpoint`, `support_plane`: as for locate(). Unknown model ids throw std::out_of_range.
  /// The fitness here counts every camera-visible point: the points of two passes, lit by two
  /// sweeps, are refined together.
  std::vector<PartDetection> refine(const ScanCloud& scan, const std::vector<PartDetection>& parts,
                                    MatchStats* stats = nullptr, const Eigen::Vector3f* viewpoint = nullptr,
                                    const Eigen::Vector4f* support_plane = nullptr) const;

  /// Joins the detections of two scans of one cell (locate() on each, e.g. a second pass with the
  /// sheet leaning the other way, which lights what the first pass's sheet shaded). Every
  /// detection of `first` stands; one of `second` is added (`pass` = 1) when no detection kept so
  /// far holds its place: none of its model whose centroid lies within a quarter of the two
  /// diameters of its own (the same part, however turned), and none it would share space with
  /// (max_interpenetration at interpenetration_depth, as locate() drops such pairs; off at 1).
  /// Counts in `stats` (second_pass_added, second_pass_taken). Unknown model ids throw
  /// std::out_of_range.
  std::vector<PartDetection> mergePasses(const std::vector<PartDetection>& first, const std::vector<PartDetection>& second,
                                         MatchStats* stats = nullptr) const;

  /// Builds the per-model data (clouds, descriptors, distance field) now rather than on the
  /// first locate(); unknown ids throw std::out_of_range.
  void prepare(const std::vector<std::string>& models) const;

  /// Centroid of the model's surface (model frame), for errors and grasping.
  Eigen::Vector3d centroid(const std::string& model) const;

  struct ModelIndex;  // per-model data built once: clouds, descriptors, distance field, ray caster

 private:
  std::shared_ptr<const ModelIndex> index(const std::string& id) const;
  /// The model-preparation cache (config.model_cache_dir): file of a model, load (false when
  /// missing, stale or unreadable: then prepared and saved again), save (atomic).
  std::string cacheFile(const ModelEntry& e, const std::string& id) const;
  bool loadIndex(const std::string& file, const ModelEntry& e, ModelIndex& m) const;
  void saveIndex(const std::string& file, const ModelIndex& m) const;
  /// descriptor: learned — the model's descriptors at each of learned_rotations turns
  void addLearned(ModelIndex& m) const;

  std::shared_ptr<const ModelLibrary> library_;
  MatchingConfig config_;
  mutable std::mutex mutex_;
  mutable std::map<std::string, std::shared_ptr<const ModelIndex>> indices_;
  std::shared_ptr<const LearnedDescriptor> learned_;  ///< descriptor: learned
  std::string fallback_warning_;  ///< why descriptor: learned runs on FPFH
};

/// Strict loader of config/matching.yaml (ConfigError names file and key).
MatchingConfig loadMatchingConfig(const std::string& path);

/// What scaledMatchingConfig measured of the scan.
struct ScanFigures {
  double spacing = 0;  ///< m, medianPointSpacing
  double noise = 0;    ///< m, medianPlaneResidual within one scaled voxel
};

/// Settings for a part of any size in `scene`, from `base` (tuned on the demo parts: 2 mm voxel
/// for parts of 8-12 cm): the voxel becomes max(model diagonal / 50, 2 x the scan's median point
/// spacing) and every length setting (radii, steps, distances, tolerances) scales with it; shares
/// and counts stay. The RMSE a pose may leave is taken from the scan instead: 2 x its scatter off
/// the surface within one voxel (medianPlaneResidual), kept within [0.1, 0.5] x voxel. A true
/// pose leaves about the scan's noise; a wrong one, the spread of whatever lies inside the ICP's
/// correspondence distance (0.7-1.4 voxel on the real scans of docs/localization.md). Used by
/// cellsight_locate when no settings file is given.
MatchingConfig scaledMatchingConfig(const MatchingConfig& base, double model_diagonal, const ScanCloud& scene,
                                    ScanFigures* figures = nullptr);

}  // namespace cellsight
