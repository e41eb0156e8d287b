// Strict loader of config/matching.yaml into a MatchingConfig.
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "cellsight/common/errors.hpp"
#include "cellsight/common/yaml_reader.hpp"
#include "cellsight/localization/model_matching.hpp"

namespace cellsight {

AcceptanceThresholds acceptanceOf(const MatchingConfig& c) {
  return {c.min_fitness, c.min_coverage, c.max_rmse, c.max_instances};
}

std::pair<std::string, std::string> checkAcceptance(const AcceptanceThresholds& t) {
  if (!(t.min_fitness >= 0 && t.min_fitness <= 1)) return {"min_fitness", "must be in [0, 1]"};
  if (!(t.min_coverage >= 0 && t.min_coverage <= 1)) return {"min_coverage", "must be in [0, 1]"};
  if (!(t.max_rmse > 0)) return {"max_rmse", "must be > 0"};
  if (t.max_instances < 1) return {"max_instances", "must be >= 1"};
  return {"", ""};
}

void ModelMatcher::setAcceptance(const AcceptanceThresholds& t) {
  if (const auto bad = checkAcceptance(t); !bad.first.empty()) throw ConfigError(bad.first + " " + bad.second);
  copyAcceptance(t, &config_);
}

MatchingConfig scaledMatchingConfig(const MatchingConfig& base, double model_diagonal, const ScanCloud& scene,
                                    ScanFigures* figures) {
  if (!(model_diagonal > 0) || !std::isfinite(model_diagonal)) throw std::invalid_argument("model diagonal must be > 0");
  const double scene_spacing = medianPointSpacing(scene);
  const double voxel = std::max(model_diagonal / 50.0, std::isfinite(scene_spacing) ? 2.0 * scene_spacing : 0.0);
  const double r = voxel / base.voxel;
  MatchingConfig c = base;
  for (double* v : {&c.voxel, &c.normal_radius, &c.feature_radius, &c.ppf_sampling, &c.ppf_distance_step,
                    &c.inlier_distance, &c.icp_spacing, &c.icp_huber_floor, &c.icp_slack_range, &c.icp_slack_tolerance,
                    &c.fitness_radius, &c.max_support_penetration, &c.max_support_gap,
                    &c.continuation_reach, &c.continuation_tolerance, &c.interpenetration_depth})
    *v *= r;
  const double noise = medianPlaneResidual(scene, c.voxel);
  c.max_rmse = std::clamp(2.0 * noise, 0.1 * c.voxel, 0.5 * c.voxel);
  if (figures) *figures = {scene_spacing, noise};
  return c;
}

MatchingConfig loadMatchingConfig(const std::string& path) {
  YamlMap m(loadYamlFile(path), path);
  MatchingConfig c;
  auto positive = [&](const char* key, double& v) {
    v = m.getDouble(key, v);
    if (!(v > 0)) m.fail(key, "must be > 0");
  };
  auto atLeast = [&](const char* key, int& v, int lowest) {
    v = m.getInt(key, v);
    if (v < lowest) m.fail(key, "must be >= " + std::to_string(lowest));
  };
  auto share = [&](const char* key, double& v) {
    v = m.getDouble(key, v);
    if (!(v >= 0 && v <= 1)) m.fail(key, "must be in [0, 1]");
  };
  positive("voxel", c.voxel);
  c.scene_search = m.getString("scene_search", c.scene_search);
  if (c.scene_search != "grid" && c.scene_search != "kdtree") m.fail("scene_search", "must be grid or kdtree");
  positive("normal_radius", c.normal_radius);
  positive("feature_radius", c.feature_radius);
  c.mutual_filter = m.getBool("mutual_filter", c.mutual_filter);
  c.min_correspondences = m.getInt("min_correspondences", c.min_correspondences);
  c.coarse = m.getString("coarse", c.coarse);
  if (c.coarse != "ppf" && c.coarse != "ransac" && c.coarse != "fgr") m.fail("coarse", "must be ppf, ransac or fgr");
  c.descriptor = m.getString("descriptor", c.descriptor);
  if (c.descriptor != "fpfh" && c.descriptor != "learned") m.fail("descriptor", "must be fpfh or learned");
  if (c.descriptor == "learned" && c.coarse == "ppf") m.fail("descriptor", "learned needs coarse: ransac or fgr (ppf uses no descriptor)");
  c.learned_model = m.getString("learned_model", c.learned_model);
  if (c.learned_model.empty()) m.fail("learned_model", "must name a model file");
  if (c.learned_model[0] != '/') {
    const auto slash = path.find_last_of('/');
    c.learned_model = (slash == std::string::npos ? std::string(".") : path.substr(0, slash)) + "/" + c.learned_model;
  }
  c.learned_dims = m.getInt("learned_dims", c.learned_dims);
  if (c.learned_dims != 16 && c.learned_dims != 32) m.fail("learned_dims", "must be 16 or 32");
  atLeast("learned_rotations", c.learned_rotations, 1);
  positive("learned_scale", c.learned_scale);
  c.learned_fallback = m.getBool("learned_fallback", c.learned_fallback);
  positive("ppf_sampling", c.ppf_sampling);
  positive("ppf_distance_step", c.ppf_distance_step);
  c.ppf_angle_bins = m.getInt("ppf_angle_bins", c.ppf_angle_bins);
  if (c.ppf_angle_bins < 4 || c.ppf_angle_bins > 255) m.fail("ppf_angle_bins", "must be in [4, 255]");
  c.ppf_ref_step = m.getInt("ppf_ref_step", c.ppf_ref_step);
  if (c.ppf_ref_step < 1) m.fail("ppf_ref_step", "must be >= 1");
  atLeast("ppf_max_bucket", c.ppf_max_bucket, 1);
  atLeast("ppf_candidates", c.ppf_candidates, 1);
  c.ransac_sampling = m.getString("ransac_sampling", c.ransac_sampling);
  if (c.ransac_sampling != "uniform" && c.ransac_sampling != "guided") m.fail("ransac_sampling", "must be uniform or guided");
  c.ransac_neighbours = m.getInt("ransac_neighbours", c.ransac_neighbours);
  if (c.ransac_neighbours < 1 || c.ransac_neighbours > 64) m.fail("ransac_neighbours", "must be in [1, 64]");
  atLeast("max_iterations", c.max_iterations, 1);
  c.confidence = m.getDouble("confidence", c.confidence);
  if (!(c.confidence > 0 && c.confidence < 1)) m.fail("confidence", "must be in (0, 1)");
  share("edge_similarity", c.edge_similarity);
  positive("normal_tolerance", c.normal_tolerance);
  positive("inlier_distance", c.inlier_distance);
  atLeast("refine_candidates", c.refine_candidates, 1);
  share("refine_candidates_near", c.refine_candidates_near);
  c.rest_candidates = m.getInt("rest_candidates", c.rest_candidates);
  if (c.rest_candidates < 0 || c.rest_candidates > 64) m.fail("rest_candidates", "must be in [0, 64] (0: off)");
  c.rest_yaw_step = m.getDouble("rest_yaw_step", c.rest_yaw_step);
  if (!(c.rest_yaw_step >= 0.01 && c.rest_yaw_step <= M_PI)) m.fail("rest_yaw_step", "must be in [0.01, pi] rad");
  c.rest_end_ratio = m.getDouble("rest_end_ratio", c.rest_end_ratio);
  if (!(c.rest_end_ratio == 0 || c.rest_end_ratio >= 1)) m.fail("rest_end_ratio", "must be 0 (off) or >= 1");
  c.rest_snap_angle = m.getDouble("rest_snap_angle", c.rest_snap_angle);
  if (!(c.rest_snap_angle >= 0 && c.rest_snap_angle <= 0.35)) m.fail("rest_snap_angle", "must be in [0, 0.35] rad (0: off)");
  c.rest_snap_min_angle = m.getDouble("rest_snap_min_angle", c.rest_snap_min_angle);
  if (!(c.rest_snap_min_angle >= 0 && c.rest_snap_min_angle <= c.rest_snap_angle + 1e-12) && c.rest_snap_angle > 0)
    m.fail("rest_snap_min_angle", "must be in [0, rest_snap_angle] rad");
  c.rest_snap_rmse_ratio = m.getDouble("rest_snap_rmse_ratio", c.rest_snap_rmse_ratio);
  if (!(c.rest_snap_rmse_ratio >= 1)) m.fail("rest_snap_rmse_ratio", "must be >= 1");
  positive("icp_spacing", c.icp_spacing);
  c.icp_iterations = m.getInt("icp_iterations", c.icp_iterations);
  positive("icp_max_points", c.icp_max_points);
  positive("icp_screen_points", c.icp_screen_points);
  positive("max_cluster_points", c.max_cluster_points);
  atLeast("icp_exact_iterations", c.icp_exact_iterations, 0);
  c.icp_mesh_polish = m.getBool("icp_mesh_polish", c.icp_mesh_polish);
  c.icp_edge_band = m.getDouble("icp_edge_band", c.icp_edge_band);
  if (!(c.icp_edge_band >= 0)) m.fail("icp_edge_band", "must be >= 0 (0: off)");
  atLeast("icp_edge_support", c.icp_edge_support, 1);
  positive("refine_radius", c.refine_radius);
  atLeast("refine_min_points", c.refine_min_points, 20);
  positive("refine_max_shift", c.refine_max_shift);
  c.icp_centre_slack = m.getBool("icp_centre_slack", c.icp_centre_slack);
  c.fitness_whole_scan = m.getBool("fitness_whole_scan", c.fitness_whole_scan);
  c.polish_split_parts = m.getBool("polish_split_parts", c.polish_split_parts);
  c.turned_poses = m.getBool("turned_poses", c.turned_poses);
  c.unseen_second_look = m.getBool("unseen_second_look", c.unseen_second_look);
  c.split_second_look = m.getBool("split_second_look", c.split_second_look);
  c.turned_rmse_ratio = m.getDouble("turned_rmse_ratio", c.turned_rmse_ratio);
  if (!(c.turned_rmse_ratio > 0 && c.turned_rmse_ratio <= 1)) m.fail("turned_rmse_ratio", "must be in (0, 1]");
  share("ambiguous_score_ratio", c.ambiguous_score_ratio);
  positive("icp_slack_range", c.icp_slack_range);
  positive("icp_slack_tolerance", c.icp_slack_tolerance);
  share("icp_slack_eigen_ratio", c.icp_slack_eigen_ratio);
  atLeast("icp_slack_steps", c.icp_slack_steps, 1);
  atLeast("icp_slack_points", c.icp_slack_points, 1);
  c.closest_point_grid = m.getBool("closest_point_grid", c.closest_point_grid);
  c.icp_huber_floor = m.getDouble("icp_huber_floor", c.icp_huber_floor);
  if (!(c.icp_huber_floor >= 0)) m.fail("icp_huber_floor", "must be >= 0");
  positive("fitness_radius", c.fitness_radius);
  share("min_fitness", c.min_fitness);
  share("min_coverage", c.min_coverage);
  positive("max_rmse", c.max_rmse);
  c.check_visibility = m.getBool("check_visibility", c.check_visibility);
  c.check_illumination = m.getBool("check_illumination", c.check_illumination);
  if (m.has("viewpoint")) c.viewpoint = m.getVector3("viewpoint").cast<float>();
  positive("max_view_angle", c.max_view_angle);
  c.fitness_incidence_mid = m.getDouble("fitness_incidence_mid", c.fitness_incidence_mid);
  if (!(c.fitness_incidence_mid >= 0 && c.fitness_incidence_mid <= c.max_view_angle))
    m.fail("fitness_incidence_mid", "must be in [0, max_view_angle] (rad; 0: off)");
  positive("fitness_incidence_width", c.fitness_incidence_width);
  positive("max_support_penetration", c.max_support_penetration);
  c.max_support_gap = m.getDouble("max_support_gap", c.max_support_gap);
  if (!(c.max_support_gap >= 0)) m.fail("max_support_gap", "must be >= 0 (0: off)");
  share("max_see_through", c.max_see_through);
  share("max_overhang", c.max_overhang);
  positive("overhang_clearance", c.overhang_clearance);
  positive("overhang_table_radius", c.overhang_table_radius);
  share("max_unseen", c.max_unseen);
  share("max_continuation", c.max_continuation);
  positive("continuation_reach", c.continuation_reach);
  positive("continuation_tolerance", c.continuation_tolerance);
  if (c.max_continuation < 1 && !(c.continuation_reach > c.fitness_radius))
    m.fail("continuation_reach", "must exceed fitness_radius (m) while max_continuation is on");
  share("max_interpenetration", c.max_interpenetration);
  positive("interpenetration_depth", c.interpenetration_depth);
  positive("unseen_radius", c.unseen_radius);
  positive("unseen_view_angle", c.unseen_view_angle);
  if (c.unseen_view_angle > c.max_view_angle) m.fail("unseen_view_angle", "must be <= max_view_angle");
  c.max_instances = m.getInt("max_instances", c.max_instances);
  if (const auto bad = checkAcceptance(acceptanceOf(c)); !bad.first.empty()) m.fail(bad.first, bad.second);
  c.min_instance_points = m.getInt("min_instance_points", c.min_instance_points);
  c.threads = m.getInt("threads", c.threads);
  c.seed = static_cast<uint64_t>(m.getInt("seed", static_cast<int>(c.seed)));
  m.finish();
  return c;
}

}  // namespace cellsight
