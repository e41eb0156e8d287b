// cellsight_evaluate_localization: localisation figures against ground truth.
// Usage: cellsight_evaluate_localization SUBCOMMAND [OPTIONS]   (--help on the tool and each subcommand)
//   demo       detections of the demo scan vs the simulator's truth → detections.json
//              --detections detections_raw.json [--scene S.yaml] [--models F] [--root R]
//              [--max-t-mm 5] [--max-r-deg 5] [--json out.json]; exit 3 unless every part is found
//   occlusion  the thesis's random-walk occlusion test on single-view clouds of our parts
//              [--parts blade,housing,holder] [--trials 100] [--from 0.25] [--to 0.75] [--step 0.05]
//              [--ks 20] [--min-fitness F] + the sweep options below
//   outliers   uniform outliers with random normals in the workspace box, 0…200 % of the points
//              [--parts blade,housing,holder,bracket] [--trials 50] [--ratios 0,0.25,0.5,1,1.5,2]
//              + the sweep options below
//   cells      random cells (scene generator) scanned in-process, clustered, located: P/R/F1
//              --seeds N... | --seeds-file config/heldout_seeds.yaml [--out DIR] [--json out.json]
//   descriptors  FPFH vs the learned descriptor in the same RANSAC pipeline: held-out laser views of
//              our parts and the real UWA / PCL scenes [--views 12] [--json F] [--png F]
//              [--limit-beats-fpfh MARGIN] (exit 4 unless learned beats FPFH)
//   (a part in a real scan from files: cellsight_locate)
//   sweep options (occlusion, outliers): [--search all|self] [--root repo] [--scene S.yaml]
//              [--models folder] [--matching matching.yaml] [--max-t-mm 2] [--max-r-deg 2]
//              [--json out.json] [--png curves.png]
//   --png of a sweep: success-rate curves drawn by /usr/bin/gnuplot; the data and the script stay
//   beside it (curves.png.dat, curves.png.gp: re-plot with `cd <folder> && gnuplot curves.png.gp`).
//   No gnuplot, or a failing one: a warning, the JSON is still written (it is the result).
// Bad or unknown options are reported by CLI11 (non-zero exit); failures at run time print
// "error: ..." and exit 1.

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iomanip>
#include <iostream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>

#include "cellsight/common/file_io.hpp"
#include "cellsight/common/yaml_reader.hpp"
#include "cellsight/common/trajectory.hpp"
#include "cellsight/scanner/scanner_config.hpp"
#include "cellsight/localization/clustering.hpp"
#include "cellsight/eval/evaluation.hpp"
#include "cellsight/eval/sim_scan.hpp"
#include "cellsight/eval/scene_generator.hpp"
#include "cellsight/localization/localization_eval.hpp"
#include "cellsight/common/mesh.hpp"
#include "cellsight/common/scan_cloud.hpp"
#include "cellsight/localization/model_matching.hpp"
#include "cellsight/sim/scene.hpp"
#include "cli_args.hpp"
#include "gnuplot.hpp"
#include "descriptor_eval.hpp"
#include "json_pose.hpp"

using namespace cellsight;
using json = nlohmann::json;

namespace {

const double kDeg = M_PI / 180;

/// The options of one subcommand (each has its own instance and defaults).
struct Options {
  std::string root = ".", scene, models, matching, json, png;
  std::string search = "all";
  double max_t_mm = 2, max_r_deg = 2;
  int trials = 100, ks = 20;
  double from = 0.25, to = 0.75, step = 0.05;
  double min_fitness = 0;
  bool min_fitness_given = false;
  std::vector<std::string> parts;
  std::vector<double> ratios;
  std::string detections, cloud, calibration;
  std::string trajectory = "demo_sweep";  ///< cells: the scan's trajectory (config/trajectories.yaml)
  /// cells: a second scan's trajectory (empty: none), located on its own and merged
  /// (ModelMatcher::mergePasses)
  std::string second_pass;
  double limit_rms_mm = 0, limit_t_mm = 0, limit_r_deg = 0, limit_recall = 0;  ///< cells: 0 = no limit
  std::string dump_clusters;  ///< cells, cloud: write each scene's clusters as PLY here
  /// `value`, or `<root>/<relative>` when not given
  std::string orRoot(const std::string& value, const std::string& relative) const {
    return value.empty() ? root + "/" + relative : value;
  }
};

/// Drops empty names ("a,,b" -> a, b), as the comma-separated lists always did.
std::vector<std::string> nonEmpty(const std::vector<std::string>& v) {
  std::vector<std::string> out;
  for (const auto& s : v)
    if (!s.empty()) out.push_back(s);
  return out;
}

using cellsight_tools::median;
using cellsight_tools::writeJson;

struct Setup {
  std::shared_ptr<const ModelLibrary> lib;
  MatchingConfig cfg;
  Eigen::Vector3f eye;
  Eigen::AlignedBox3f workspace;
};

Setup setup(const Options& o) {
  Setup s;
  const Scene scene = loadScene(o.orRoot(o.scene, "config/scenes/demo.yaml"));
  s.lib = std::make_shared<const ModelLibrary>(o.orRoot(o.models, "config/models"));
  s.cfg = loadMatchingConfig(o.orRoot(o.matching, "config/matching.yaml"));
  s.eye = scene.scanner_camera.T_base_camera.translation().cast<float>();
  s.cfg.viewpoint = s.eye;
  s.workspace = Eigen::AlignedBox3f(scene.workspace.min().cast<float>(), scene.workspace.max().cast<float>());
  return s;
}

/// A random pose resting on the table inside the workspace (x, y, yaw).
Eigen::Isometry3d randomTablePose(const Eigen::AlignedBox3f& ws, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> U(0, 1);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(ws.min().x() + (0.25 + 0.5 * U(rng)) * ws.sizes().x(),
                                    ws.min().y() + (0.25 + 0.5 * U(rng)) * ws.sizes().y(), 0);
  T.linear() = Eigen::AngleAxisd(2 * M_PI * U(rng), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return T;
}

struct Trial {
  bool success = false;        // within the strict thresholds (--max-t-mm, --max-r-deg)
  bool success_thesis = false;  // within the thesis's criterion (Δt ≤ 20 mm, ΔR ≤ 7.5°)
  double seconds = 0;
  double stage[3] = {0, 0, 0};  // scene preparation, coarse, refinement (CPU s)
};

/// The success criterion of the thesis's UWA test (digest §4): Δt ≤ 20 mm, ΔR ≤ 7.5°.
constexpr double kThesisMaxT = 0.020, kThesisMaxR = 7.5 * M_PI / 180;

Trial runTrial(const ModelMatcher& m, const ModelLibrary& lib, const std::string& id, const ScanCloud& cloud,
               const Eigen::Isometry3d& truth, double max_t, double max_r, bool all_models) {
  Trial t;
  MatchStats st;
  const Eigen::Vector4f table(0, 0, 1, 0);  // the parts rest on the table, z = 0 in the base frame
  const auto dets = m.locate({cloud}, all_models ? std::vector<std::string>{} : std::vector<std::string>{id}, &st, nullptr, &table);
  t.seconds = st.seconds;
  t.stage[0] = st.scene_seconds;
  t.stage[1] = st.coarse_seconds;
  t.stage[2] = st.refine_seconds;
  for (const auto& d : dets) {
    if (d.model != id) continue;
    const PoseError e = poseError(lib.model(id).info, m.centroid(id), d.pose, truth);
    if (e.translation <= max_t && e.rotation <= max_r) t.success = true;
    if (e.translation <= kThesisMaxT && e.rotation <= kThesisMaxR) t.success_thesis = true;
  }
  if (!t.success && std::getenv("CELLSIGHT_EVAL_VERBOSE")) {
    for (const auto& d : dets) {
      const PoseError e = poseError(lib.model(d.model).info, m.centroid(d.model), d.pose, truth);
      const Eigen::Vector3d dt = (truth.inverse() * d.pose).translation() * 1e3;
      std::fprintf(stderr, "  miss %s: found %s at %.1f mm %.1f deg (model-frame offset %.1f %.1f %.1f mm; fitness %.2f coverage %.2f)\n",
                   id.c_str(), d.model.c_str(), e.translation * 1e3, e.rotation / kDeg, dt.x(), dt.y(), dt.z(), d.fitness, d.coverage);
    }
    for (const auto& d : st.rejected) {
      const PoseError e = d.model == id ? poseError(lib.model(id).info, m.centroid(id), d.pose, truth) : PoseError{-1, -1};
      std::fprintf(stderr, "  rejected %s: %.1f mm %.1f deg fitness %.2f coverage %.2f rmse %.3f mm (%s)\n", d.model.c_str(),
                   e.translation * 1e3, e.rotation / kDeg, d.fitness, d.coverage, d.rmse * 1e3, d.refused_by.c_str());
    }
  }
  return t;
}

/// Degrades a single view by `x` (an occlusion share, an outlier ratio).
using Degrade = std::function<ScanCloud(const ScanCloud& view, double x, std::mt19937_64& rng)>;

/// For each part and each x: `--trials` single views at random table poses, degraded, located;
/// success rates and median times into `j`, then the JSON and the plot.
int sweep(const Options& o, const Setup& s, const MatchingConfig& cfg, const std::vector<std::string>& parts, int trials,
          const std::string& what, const std::vector<double>& xs, uint64_t seed, const Degrade& degrade, json& j,
          const std::string& title, const std::string& xlabel) {
  const double max_t = o.max_t_mm * 1e-3, max_r = o.max_r_deg * kDeg;
  const bool all_models = o.search == "all";
  ModelMatcher m(s.lib, cfg);
  m.prepare({});
  j["models_searched"] = all_models ? "all (identify and locate)" : "the part's own model (locate only)";
  j["success"] = {{"max_t_mm", max_t * 1e3}, {"max_r_deg", max_r / kDeg}};
  j["success_thesis_criterion"] = {{"max_t_mm", kThesisMaxT * 1e3}, {"max_r_deg", kThesisMaxR / kDeg}};
  j["min_fitness"] = cfg.min_fitness;
  std::vector<std::pair<std::string, std::vector<double>>> series;
  for (const auto& id : parts) {
    std::vector<double> rates, rates_thesis, times;
    for (size_t xi = 0; xi < xs.size(); ++xi) {
      std::mt19937_64 rng(seed + 1000 * xi + std::hash<std::string>()(id) % 1000);
      int ok = 0, ok_thesis = 0;
      std::vector<double> secs, stage[3];
      for (int t = 0; t < trials; ++t) {
        const Eigen::Isometry3d truth = randomTablePose(s.workspace, rng);
        const ScanCloud view = singleViewCloud(s.lib->model(id).mesh, truth, s.eye, 0.001, 2e-5, rng());
        const Trial r = runTrial(m, *s.lib, id, degrade(view, xs[xi], rng), truth, max_t, max_r, all_models);
        ok += r.success;
        ok_thesis += r.success_thesis;
        secs.push_back(r.seconds);
        for (int k = 0; k < 3; ++k) stage[k].push_back(r.stage[k]);
      }
      rates.push_back(100.0 * ok / trials);
      rates_thesis.push_back(100.0 * ok_thesis / trials);
      times.push_back(median(secs));
      std::printf("%-8s %s %3.0f %%: success %5.1f %% (thesis criterion %5.1f %%; median %.3f s: scene %.3f coarse %.3f refine %.3f)\n",
                  id.c_str(), what.c_str(), xs[xi] * 100, rates.back(), rates_thesis.back(), times.back(), median(stage[0]),
                  median(stage[1]), median(stage[2]));
      std::fflush(stdout);
    }
    j["parts"][id] = {{"success_percent", rates}, {"success_percent_thesis_criterion", rates_thesis}, {"median_seconds", times}};
    series.push_back({id, rates});
  }
  writeJson(o.json, j);
  std::vector<double> percent;
  for (double x : xs) percent.push_back(x * 100);
  cellsight_tools::plotLines(o.png, title, xlabel, {"success [%]", true, false}, percent, series);
  return 0;
}

int runOcclusion(const Options& o) {
  const Setup s = setup(o);
  const int trials = o.trials;
  const int k_s = o.ks;
  std::vector<double> levels;
  for (double l = o.from; l <= o.to + 1e-9; l += o.step) levels.push_back(l);
  json j;
  j["test"] = "random-walk occlusion (thesis ch. 5): single-view clouds of each part at random table poses";
  j["trials_per_level"] = trials;
  j["k_s"] = k_s;
  j["levels"] = levels;
  // The validation threshold is a detection policy: F counts the visible model surface seen, so
  // with a share x deleted F <= 1 - x and the default 0.35 rejects every pose beyond ~65 %.
  // `--min-fitness` lowers it to measure pose recovery alone (the thesis's test).
  MatchingConfig cfg = s.cfg;
  if (o.min_fitness_given) cfg.min_fitness = o.min_fitness;
  return sweep(o, s, cfg, nonEmpty(o.parts), trials, "occlusion", levels, 0,
               [k_s](const ScanCloud& v, double x, std::mt19937_64& rng) { return randomWalkOcclusion(v, x, k_s, rng); }, j,
               "occlusion: success rate per part", "occlusion %");
}

int runOutliers(const Options& o) {
  const Setup s = setup(o);
  const int trials = o.trials;
  const std::vector<double>& ratios = o.ratios;
  MatchingConfig cfg = s.cfg;
  cfg.min_coverage = 0;  // the outliers are part of the cloud: nothing can explain them
  json j;
  j["test"] = "uniform outliers with random normals in the scanner's workspace box, ratio of the part's points";
  j["ratios"] = ratios;
  j["trials_per_ratio"] = trials;
  const Eigen::AlignedBox3f box = s.workspace;
  return sweep(o, s, cfg, nonEmpty(o.parts), trials, "outliers", ratios, 77,
               [box](const ScanCloud& v, double x, std::mt19937_64& rng) { return addUniformOutliers(v, box, x, rng); }, j,
               "outliers: success rate per part", "outliers, % of the part's points");
}

struct ScoredDetection {
  std::string model;
  Eigen::Isometry3d pose;
  double fitness = 0, coverage = 0, rmse = 0, see_through = 0, unseen = 0, continuation = 0, overhang = 0;
  double alternative_score_share = 0;             ///< PartDetection's (0: none fits as closely, or turns not scored)
  std::vector<Eigen::Isometry3d> ambiguous_poses{};  ///< PartDetection's (empty: not ambiguous)
  int pass = 0;                                   ///< PartDetection's: the scan it was found on
};

/// The matcher's word on a detection's turns (PartDetection::ambiguous_poses), for the JSON:
/// whether it is ambiguous, the best turn's score share, and each reported pose's turn from it.
void addAmbiguity(const ScoredDetection& d, const ModelInfo& info, const Eigen::Vector3d& centroid, json* j) {
  (*j)["ambiguous"] = !d.ambiguous_poses.empty();
  (*j)["alternative_score_share"] = d.alternative_score_share;
  if (d.ambiguous_poses.empty()) return;
  (*j)["ambiguous_turns_deg"] = json::array();
  for (const auto& a : d.ambiguous_poses) (*j)["ambiguous_turns_deg"].push_back(poseError(info, centroid, a, d.pose).rotation / kDeg);
}

/// Detections against a scene's truth: each object takes the nearest unused detection of its
/// model, found when within max_t / max_r; detections left over are false. Per part and totals.
json scoreDetections(const Scene& scene, const ModelLibrary& lib, const ModelMatcher& centroids,
                     const std::vector<ScoredDetection>& dets, double max_t, double max_r, DetectionCounts* counts,
                     std::vector<double>* terr, std::vector<double>* rerr) {
  json out;
  out["success"] = {{"max_t_mm", max_t * 1e3}, {"max_r_deg", max_r / kDeg}};
  out["parts"] = json::array();
  std::vector<bool> used(dets.size(), false);
  for (const auto& o : scene.objects) {
    json p = {{"name", o.name}, {"model", o.model}, {"found", false}};
    if (!lib.has(o.model)) {  // a distractor: nothing to find, only false detections to avoid
      p["distractor"] = true;
      out["parts"].push_back(p);
      continue;
    }
    double best = 1e9;
    int bi = -1;
    PoseError be;
    const Eigen::Vector3d c = centroids.centroid(o.model);
    for (size_t i = 0; i < dets.size(); ++i) {
      if (used[i] || dets[i].model != o.model) continue;
      const PoseError e = poseError(lib.model(o.model).info, c, dets[i].pose, o.T_base_object);
      if (e.translation < best) {
        best = e.translation;
        bi = static_cast<int>(i);
        be = e;
      }
    }
    if (bi >= 0 && be.translation <= max_t && be.rotation <= max_r) {
      used[bi] = true;
      p["found"] = true;
      p["t_err_mm"] = be.translation * 1e3;
      p["r_err_deg"] = be.rotation / kDeg;
      p["fitness"] = dets[bi].fitness;
      p["coverage"] = dets[bi].coverage;
      p["rmse_mm"] = dets[bi].rmse * 1e3;
      p["see_through"] = dets[bi].see_through;
      p["overhang"] = dets[bi].overhang;
      p["unseen"] = dets[bi].unseen;
      p["continuation"] = dets[bi].continuation;
      p["pose"] = cellsight_tools::poseToJson(dets[bi].pose);
      p["pass"] = dets[bi].pass;
      addAmbiguity(dets[bi], lib.model(o.model).info, c, &p);
      counts->ambiguous_tp += !dets[bi].ambiguous_poses.empty();
      terr->push_back(be.translation * 1e3);
      rerr->push_back(be.rotation / kDeg);
      ++counts->tp;
    } else {
      ++counts->fn;
      if (bi >= 0) {
        p["nearest_t_err_mm"] = be.translation * 1e3;
        p["nearest_r_err_deg"] = be.rotation / kDeg;
      }
    }
    out["parts"].push_back(p);
  }
  // what each false detection is: a wrong pose of a part, a part taken for another, or a
  // distractor taken for a part (the nearest object's centre to the detection's)
  out["false_detections"] = json::array();
  std::vector<bool> claimed(scene.objects.size(), false);  // a missed part one ambiguous false detection offered already
  for (size_t i = 0; i < dets.size(); ++i) {
    if (used[i]) continue;
    ++counts->fp;
    const Eigen::Vector3d at = dets[i].pose * centroids.centroid(dets[i].model);
    json f = {{"model", dets[i].model},       {"fitness", dets[i].fitness}, {"coverage", dets[i].coverage},
              {"rmse_mm", dets[i].rmse * 1e3}, {"see_through", dets[i].see_through}, {"overhang", dets[i].overhang}, {"unseen", dets[i].unseen},
              {"continuation", dets[i].continuation}, {"at", {at.x(), at.y(), at.z()}},  {"pose", cellsight_tools::poseToJson(dets[i].pose)},
              {"detection", i}, {"pass", dets[i].pass}};
    addAmbiguity(dets[i], lib.model(dets[i].model).info, centroids.centroid(dets[i].model), &f);
    if (!dets[i].ambiguous_poses.empty()) {
      ++counts->ambiguous_fp;
      // the poses the matcher offered beside it: is one of them the part's?
      bool right = false;
      for (size_t k = 0; k < scene.objects.size(); ++k) {
        const auto& o = scene.objects[k];
        if (right || claimed[k] || o.model != dets[i].model || out["parts"][k]["found"].get<bool>()) continue;
        for (const auto& a : dets[i].ambiguous_poses) {
          const PoseError e = poseError(lib.model(o.model).info, centroids.centroid(o.model), a, o.T_base_object);
          right = right || (e.translation <= max_t && e.rotation <= max_r);
        }
        claimed[k] = right;
      }
      f["alternative_right"] = right;
      counts->ambiguous_fp_alternative_right += right;
    }
    double nearest = 1e9;
    for (const auto& o : scene.objects) {
      const Eigen::Vector3d c = lib.has(o.model) ? Eigen::Vector3d(o.T_base_object * centroids.centroid(o.model))
                                                 : o.T_base_object.translation();
      const double d = (c - at).norm();
      if (d < nearest) {
        nearest = d;
        f["nearest_object"] = o.name;
        f["nearest_is_distractor"] = !lib.has(o.model);
        f["nearest_object_mm"] = d * 1e3;
      }
    }
    out["false_detections"].push_back(f);
  }
  out["tp"] = counts->tp;
  out["fp"] = counts->fp;
  out["fn"] = counts->fn;
  out["precision"] = counts->precision();
  out["recall"] = counts->recall();
  out["f1"] = counts->f1();
  out["median_t_err_mm"] = median(*terr);
  out["median_r_err_deg"] = median(*rerr);
  return out;
}

int runDemo(const Options& o) {
  const Scene scene = loadScene(o.orRoot(o.scene, "config/scenes/demo.yaml"));
  auto lib = std::make_shared<const ModelLibrary>(o.orRoot(o.models, "config/models"));
  ModelMatcher centroids(lib, MatchingConfig());
  std::ifstream f(o.detections);
  if (!f) throw std::runtime_error("cannot read --detections '" + o.detections + "'");
  json raw;
  try {
    f >> raw;
  } catch (const std::exception& e) {
    throw std::runtime_error(o.detections + ": not valid JSON: " + e.what());
  }
  std::vector<ScoredDetection> dets;
  for (const json& d : raw["detections"]) {
    dets.push_back({d.at("model"), cellsight_tools::poseFromJson(d), d.at("fitness"), d.at("coverage"), d.at("rmse").get<double>()});
    for (const auto& a : d.value("ambiguous_poses", json::array())) dets.back().ambiguous_poses.push_back(cellsight_tools::poseFromJson(a));
    dets.back().alternative_score_share = d.value("alternative_score_share", 0.0);
  }
  // "found": the right model within 5 mm / 5° (a gross-error test); the errors are reported as measured
  DetectionCounts counts;
  std::vector<double> terr, rerr;
  json out = scoreDetections(scene, *lib, centroids, dets, o.max_t_mm * 1e-3, o.max_r_deg * kDeg, &counts, &terr, &rerr);
  out["locate_seconds"] = raw.value("locate_seconds", 0.0);
  for (auto& p : out["parts"])
    if (p["found"].get<bool>()) p["locate_seconds"] = out["locate_seconds"];
  writeJson(o.json, out);
  std::printf("demo: %d/%zu parts found, %d false, median %.3f mm %.3f deg, locate %.3f s\n", counts.tp, scene.objects.size(),
              counts.fp, median(terr), median(rerr), out["locate_seconds"].get<double>());
  return counts.fn == 0 && counts.fp == 0 ? 0 : 3;
}

/// What the scan measured of each part (evaluation only: from the truth). Each part gets
/// `scan_points`, the scan points on its true surface (`on_object`: per point, the scene object
/// it lies on within kOnSurface, SurfaceDistance::stats). A false detection of a part's model
/// whose nearest object is that part, missed, gets `part_points_on_it`: the share of the part's
/// scan points that lie within kOnSurface of the detected pose's surface too (1: the points
/// cannot tell the two poses apart; only where nothing was measured can).
constexpr double kOnSurface = 0.001;  // m
constexpr double kFitsBoth = 0.99;    // part_points_on_it from which the scan cannot tell the poses apart
void describeScanPoints(const Scene& scene, const ModelLibrary& lib, const ScanCloud& cloud, const std::vector<int>& on_object,
                        const std::vector<ScoredDetection>& dets, json* sj) {
  std::vector<std::vector<Eigen::Vector3d>> on(scene.objects.size());
  for (size_t i = 0; i < cloud.size() && i < on_object.size(); ++i)
    if (on_object[i] >= 0 && static_cast<size_t>(on_object[i]) < on.size())
      on[static_cast<size_t>(on_object[i])].push_back(cloud.points[i].cast<double>());
  auto& parts = (*sj)["parts"];
  for (size_t k = 0; k < scene.objects.size() && k < parts.size(); ++k) parts[k]["scan_points"] = on[k].size();
  for (auto& f : (*sj)["false_detections"]) {
    const std::string near = f.value("nearest_object", std::string());
    for (size_t k = 0; k < scene.objects.size() && k < parts.size(); ++k) {
      const SceneObject& o = scene.objects[k];
      if (o.name != near || o.model != f["model"].get<std::string>() || parts[k]["found"].get<bool>() || on[k].empty()) continue;
      const ScoredDetection& d = dets.at(f["detection"].get<size_t>());
      const TriangleMesh& mesh = lib.model(o.model).mesh;
      size_t both = 0;
      for (const auto& p : on[k]) {
        const Eigen::Vector3d q = d.pose.inverse() * p;
        double best = std::numeric_limits<double>::infinity();
        for (const auto& t : mesh.faces)
          best = std::min(best, pointTriangleDistance(q, mesh.vertices[t[0]].cast<double>(), mesh.vertices[t[1]].cast<double>(),
                                                      mesh.vertices[t[2]].cast<double>()));
        both += best <= kOnSurface;
      }
      f["part_points_on_it"] = static_cast<double>(both) / static_cast<double>(on[k].size());
    }
  }
}

/// One finished scan of a cell (cropped and filtered as the nodes do), the sweep that lit it as
/// the scanner knows it and, for scoring only, the object each of its points lies on and the
/// scan's surface error (SurfaceDistance::stats).
struct CellScan {
  ScanCloud cloud;
  LightSweep light;
  std::vector<int> on_object;
  double surface_rms = 0;  ///< m
};

/// A scan clustered and located as the nodes do.
struct PassResult {
  std::vector<PartDetection> found;
  MatchStats stats;
  std::vector<size_t> cluster_sizes;
  std::vector<Eigen::Vector3f> support_points;  ///< the table points the scan measured (ClusteringResult's)
};

/// `other_support`: table points another scan of the cell measured, added to this scan's for the
/// free-space tests (the cell stands still between passes: where either scan saw the table, no
/// part is).
PassResult locatePass(const Scene& scene, const ScanCloud& cloud, const LightSweep* light, ModelMatcher& matcher,
                      const ClusteringConfig& ccfg, const Options& o, const std::string& suffix,
                      const std::vector<Eigen::Vector3f>* other_support = nullptr) {
  ClusteringResult cr = clusterScene(cloud, ccfg);
  PassResult r;
  r.support_points = cr.support_points;
  if (other_support) cr.support_points.insert(cr.support_points.end(), other_support->begin(), other_support->end());
  std::vector<ScanCloud> clusters;
  for (const auto& c : cr.clusters) clusters.push_back(c.cloud);
  if (!o.dump_clusters.empty()) {  // what the matcher was given, for a look in a viewer
    makeDirs(o.dump_clusters);
    const std::string stem = o.dump_clusters + "/" + scene.name + suffix;
    for (size_t i = 0; i < clusters.size(); ++i) saveCloud(stem + "_cluster_" + std::to_string(i) + ".ply", clusters[i]);
    ScanCloud support;  // the table points the free-space test (max_see_through) reads
    for (const auto& p : cr.support_points) support.append(p, 0.f);
    saveCloud(stem + "_support.ply", support);
    ScanCloud fragments;  // unclustered points: evidence for the fitness and unseen tests only
    for (const auto& p : cr.fragments) fragments.append(p, 0.f);
    if (fragments.size() > 0) saveCloud(stem + "_fragments.ply", fragments);
    // the sweep the illumination and unseen tests read
    if (light) saveSweep(stem + "_sweep.txt", *light);
  }
  const Eigen::Vector3f eye = scene.scanner_camera.T_base_camera.translation().cast<float>();
  const Eigen::Vector4f support(static_cast<float>(cr.support.n.x()), static_cast<float>(cr.support.n.y()),
                                static_cast<float>(cr.support.n.z()), static_cast<float>(cr.support.d));
  r.found = matcher.locate(clusters, {}, &r.stats, &eye, cr.plane_found ? &support : nullptr, &cr.support_points, light,
                           &cr.fragments);
  for (const auto& c : clusters) r.cluster_sizes.push_back(c.size());
  return r;
}

/// A finished scan clustered and located as the nodes do, scored against the scene's truth; with
/// `second`, a second scan of the cell located alike and merged (ModelMatcher::mergePasses).
json locateAndScore(const Scene& scene, const ScanCloud& cloud, const ModelLibrary& lib, ModelMatcher& matcher,
                    const ClusteringConfig& ccfg, const Options& o, DetectionCounts* counts, std::vector<double>* terr,
                    std::vector<double>* rerr, const LightSweep* light = nullptr, const std::vector<int>* on_object = nullptr,
                    const CellScan* second = nullptr) {
  PassResult first = locatePass(scene, cloud, light, matcher, ccfg, o, "");
  MatchStats& st = first.stats;
  std::vector<PartDetection> found = first.found;
  PassResult other;
  if (second) {
    other = locatePass(scene, second->cloud, &second->light, matcher, ccfg, o, "_pass2", &first.support_points);
    found = matcher.mergePasses(first.found, other.found, &st);
    for (auto r : other.stats.rejected) {
      r.pass = 1;
      st.rejected.push_back(std::move(r));
    }
    st.seconds += other.stats.seconds;
  }
  std::vector<ScoredDetection> dets;
  for (const auto& d : found)
    dets.push_back({d.model, d.pose, d.fitness, d.coverage, d.rmse, d.see_through, d.unseen, d.continuation,
                    d.overhang, d.alternative_score_share, d.ambiguous_poses, d.pass});
  json sj = scoreDetections(scene, lib, matcher, dets, o.max_t_mm * 1e-3, o.max_r_deg * kDeg, counts, terr, rerr);
  // a missed part: the pose of its model nearest the truth that validation refused, with the
  // figures it failed on
  for (auto& p : sj["parts"]) {
    if (p["found"].get<bool>() || p.value("distractor", false)) continue;
    for (const auto& o : scene.objects) {
      if (o.name != p["name"].get<std::string>()) continue;
      double nearest = 1e9;
      for (const auto& r : st.rejected) {
        if (r.model != o.model) continue;
        const PoseError e = poseError(lib.model(o.model).info, matcher.centroid(o.model), r.pose, o.T_base_object);
        if (e.translation >= nearest) continue;
        nearest = e.translation;
        p["nearest_rejected"] = {{"fitness", r.fitness},       {"coverage", r.coverage},
                                 {"rmse_mm", r.rmse * 1e3},    {"see_through", r.see_through}, {"overhang", r.overhang}, {"unseen", r.unseen},
                                 {"continuation", r.continuation}, {"cluster", r.cluster},       {"pass", r.pass},
                                 {"t_err_mm", e.translation * 1e3},
                                 {"r_err_deg", e.rotation / kDeg},
                                 {"refused_by", r.refused_by},
                                 {"pose", cellsight_tools::poseToJson(r.pose)}};
      }
    }
  }
  // every pose validation refused (the best per cluster and model), and whether it was right:
  // the figures right and wrong poses reach, for choosing acceptance thresholds on tuning cells
  sj["rejected"] = json::array();
  std::vector<const PartDetection*> listed;  // a cluster searched again (half the coverage) refuses the same pose twice
  for (const auto& r : st.rejected) {
    if (std::any_of(listed.begin(), listed.end(), [&](const PartDetection* l) {
          return l->model == r.model && l->cluster == r.cluster && l->pass == r.pass && l->pose.isApprox(r.pose, 1e-9);
        }))
      continue;
    listed.push_back(&r);
    double t_err = 1e9, r_err = 1e9;
    for (const auto& o : scene.objects) {
      if (o.model != r.model) continue;
      const PoseError e = poseError(lib.model(o.model).info, matcher.centroid(o.model), r.pose, o.T_base_object);
      if (e.translation < t_err) t_err = e.translation, r_err = e.rotation;
    }
    sj["rejected"].push_back({{"model", r.model},
                              {"cluster", r.cluster},
                              {"pass", r.pass},
                              {"fitness", r.fitness},
                              {"coverage", r.coverage},
                              {"rmse_mm", r.rmse * 1e3},
                              {"see_through", r.see_through},
                              {"overhang", r.overhang},
                              {"unseen", r.unseen},
                              {"continuation", r.continuation},
                              {"refused_by", r.refused_by},
                              {"right", t_err <= o.max_t_mm * 1e-3 && r_err <= o.max_r_deg * kDeg}});
  }
  if (on_object && second) {  // what either scan measured of each part
    ScanCloud both = cloud;
    std::vector<int> on = *on_object;
    on.resize(cloud.size(), -1);
    for (const auto& p : second->cloud.points) both.append(p, 0.f);
    on.insert(on.end(), second->on_object.begin(), second->on_object.end());
    describeScanPoints(scene, lib, both, on, dets, &sj);
  } else if (on_object) {
    describeScanPoints(scene, lib, cloud, *on_object, dets, &sj);
  }
  sj["cluster_sizes"] = first.cluster_sizes;
  sj["points"] = cloud.size();
  sj["clusters"] = first.cluster_sizes.size();
  if (second) {
    sj["second_pass"] = {{"points", second->cloud.size()},
                         {"cluster_sizes", other.cluster_sizes},
                         {"found", other.found.size()},
                         {"added", st.second_pass_added},
                         {"taken", st.second_pass_taken},
                         {"locate_seconds", other.stats.seconds}};
  }
  sj["locate_seconds"] = st.seconds;
  sj["split_parts_polished"] = st.split_parts_polished;
  sj["turned_poses"] = st.turned_poses;
  sj["interpenetrating"] = st.interpenetrating;
  return sj;
}

/// A finished scan file located in-process (clustering + matching with the repository's
/// settings) and scored: the localisation figures of a scan made another way (e.g. the demo's
/// frames triangulated again with another calibration). Exit 3 unless every part is found.
int runCloud(const Options& o) {
  const Scene scene = loadScene(o.orRoot(o.scene, "config/scenes/demo.yaml"));
  auto lib = std::make_shared<const ModelLibrary>(o.orRoot(o.models, "config/models"));
  const MatchingConfig cfg = loadMatchingConfig(o.orRoot(o.matching, "config/matching.yaml"));
  const ClusteringConfig ccfg = loadClusteringConfig(o.root + "/config/clustering.yaml");
  ModelMatcher matcher(lib, cfg);
  matcher.prepare({});
  const ScanCloud cloud = loadCloud(o.cloud);
  if (cloud.size() == 0) throw std::runtime_error(o.cloud + ": the cloud is empty");
  DetectionCounts counts;
  std::vector<double> terr, rerr;
  json out = locateAndScore(scene, cloud, *lib, matcher, ccfg, o, &counts, &terr, &rerr);
  out["cloud"] = o.cloud;
  writeJson(o.json, out);
  std::printf("cloud: %d/%zu parts found, %d false, median %.3f mm %.3f deg\n", counts.tp, scene.objects.size(), counts.fp,
              median(terr), median(rerr));
  return counts.fn == 0 && counts.fp == 0 ? 0 : 3;
}

/// The second pass's image-noise seed is the cell's plus this (another scan, other noise).
constexpr uint64_t kSecondPassNoise = 1000003;

/// A generated cell scanned in-process along `sweep` with `cal` (frames rendered where the robot
/// as built takes the flange; image noise from `noise_seed`), with the nodes' crop and outlier
/// filter; the light sheet frame by frame as the scanner knows it (the poses the robot reported,
/// the calibrated flange → laser transform); each point's object from the truth.
CellScan scanCell(const Scene& scene, const ScannerRenderer& renderer, const Trajectory& sweep, const ScannerCalibration& cal,
                  const ScannerSettings& settings, const RobotErrorModel& robot, uint64_t noise_seed) {
  CellScan s;
  s.cloud = simulateScan(renderer, sweep.poses, cal, settings.line, settings.triangulation, noise_seed, nullptr, &robot);
  if (settings.has_workspace) s.cloud = cropBox(s.cloud, settings.workspace);
  s.cloud = statisticalOutlierRemoval(s.cloud, settings.outlier_k, settings.outlier_std);
  s.light = LightSweep::fromFlangePoses(sweep.poses, cal.T_flange_laser, settings.laser_fan_angle / 2);
  std::vector<Eigen::Vector3d> pts;
  for (const auto& p : s.cloud.points) pts.push_back(p.cast<double>());
  s.surface_rms = SurfaceDistance(scene).stats(pts, &s.on_object, kOnSurface).rms;
  return s;
}

/// Random cells (eval/scene_generator) scanned in-process (the demo sweep unless told) and the nodes' crop
/// and outlier filter, clustered and located: detection P/R/F1 and errors over the seeds.
int runCells(const Options& o, const std::vector<uint64_t>& seeds, const std::string& out_dir) {
  const std::string models = o.orRoot(o.models, "config/models"), base = o.orRoot(o.scene, "config/scenes/demo.yaml");
  auto lib = std::make_shared<const ModelLibrary>(models);
  const MatchingConfig cfg = loadMatchingConfig(o.orRoot(o.matching, "config/matching.yaml"));
  const ClusteringConfig ccfg = loadClusteringConfig(o.root + "/config/clustering.yaml");
  const ScannerSettings settings = loadScannerSettings(o.root + "/config/scanner.yaml");
  const Trajectory sweep = loadTrajectory(o.root + "/config/trajectories.yaml", o.trajectory);
  const bool two_passes = !o.second_pass.empty();
  const Trajectory sweep2 = two_passes ? loadTrajectory(o.root + "/config/trajectories.yaml", o.second_pass) : Trajectory();
  ModelMatcher matcher(lib, cfg);
  matcher.prepare({});
  DetectionCounts total;
  std::vector<double> terr, rerr, rms;
  const bool own_calibration = !o.calibration.empty();
  json out = {{"calibration", own_calibration ? o.calibration : "the simulator's true calibration"},
              {"trajectory", o.trajectory},
              {"second_pass", two_passes ? json(o.second_pass) : json(nullptr)},
              {"success", {{"max_t_mm", o.max_t_mm}, {"max_r_deg", o.max_r_deg}}},
              {"seeds", json::array()}};
  int unmeasured = 0, fits_both = 0;  // misses with no scan point on the part; whose points a false pose fits
  size_t second_added = 0;            // detections the second pass added
  for (const uint64_t seed : seeds) {
    const GeneratedScene g = generateScene(base, models, seed, {}, out_dir);
    const ScannerRenderer renderer(std::make_shared<CellGeometry>(g.scene));
    // the cell as built (the base scene's as_built section): its robot errs, the scan uses the
    // given calibration or the truth
    const RobotErrorModel robot(g.scene.as_built.robot);
    const ScannerCalibration cal =
        own_calibration ? ScannerCalibration::fromFolder(o.calibration) : ScannerCalibration::fromScene(g.scene);
    const CellScan scan = scanCell(g.scene, renderer, sweep, cal, settings, robot, seed);
    // the second pass: another scan of the same cell (its own image noise), located on its own
    CellScan second;
    if (two_passes) second = scanCell(g.scene, renderer, sweep2, cal, settings, robot, seed + kSecondPassNoise);
    DetectionCounts counts;
    std::vector<double> t1, r1;
    json sj = locateAndScore(g.scene, scan.cloud, *lib, matcher, ccfg, o, &counts, &t1, &r1, &scan.light, &scan.on_object,
                             two_passes ? &second : nullptr);
    sj["seed"] = seed;
    sj["scene"] = g.file;
    sj["surface_error_rms_mm"] = scan.surface_rms * 1e3;
    rms.push_back(scan.surface_rms * 1e3);
    if (two_passes) second_added += sj["second_pass"]["added"].get<size_t>();
    out["seeds"].push_back(sj);
    total.tp += counts.tp;
    total.fp += counts.fp;
    total.fn += counts.fn;
    total.ambiguous_tp += counts.ambiguous_tp;
    total.ambiguous_fp += counts.ambiguous_fp;
    total.ambiguous_fp_alternative_right += counts.ambiguous_fp_alternative_right;
    for (const auto& p : sj["parts"]) {
      if (p["found"].get<bool>() || p.value("distractor", false)) continue;
      if (p.value("scan_points", 0) == 0) ++unmeasured;
      for (const auto& f : sj["false_detections"])
        if (f.value("nearest_object", std::string()) == p["name"].get<std::string>() && f.value("part_points_on_it", 0.0) >= kFitsBoth) {
          ++fits_both;
          break;
        }
    }
    terr.insert(terr.end(), t1.begin(), t1.end());
    rerr.insert(rerr.end(), r1.begin(), r1.end());
    std::printf("seed %llu: %d found, %d missed, %d false (%zu objects, %zu distractors), median %.3f mm %.3f deg\n",
                static_cast<unsigned long long>(seed), counts.tp, counts.fn, counts.fp, g.scene.objects.size(),
                g.distractors.size(), median(t1), median(r1));
    std::fflush(stdout);
  }
  out["tp"] = total.tp;
  out["fp"] = total.fp;
  out["fn"] = total.fn;
  // the misses the scan's points cannot decide: parts it holds no point of, and parts whose points
  // a false detection of their model fits as well (describeScanPoints)
  out["fn_no_scan_point"] = unmeasured;
  out["fn_points_fit_a_false_pose"] = fits_both;
  if (two_passes) out["second_pass_added"] = second_added;
  // detections the matcher reported ambiguous (a turn fits about as well): right ones, false
  // ones, and false ones whose alternative pose is the part's
  out["ambiguous_found"] = total.ambiguous_tp;
  out["ambiguous_false"] = total.ambiguous_fp;
  out["ambiguous_false_alternative_right"] = total.ambiguous_fp_alternative_right;
  // the same counts with a reported ambiguity whose other pose is the part's taken as that part
  // found (the cell knows it must check the part's orientation): beside the strict figures, not
  // instead of them
  DetectionCounts lenient = total;
  lenient.tp += total.ambiguous_fp_alternative_right;
  lenient.fp -= total.ambiguous_fp_alternative_right;
  lenient.fn -= total.ambiguous_fp_alternative_right;
  out["ambiguity_counted_found"] = {{"tp", lenient.tp},
                                    {"fp", lenient.fp},
                                    {"fn", lenient.fn},
                                    {"precision", lenient.precision()},
                                    {"recall", lenient.recall()},
                                    {"f1", lenient.f1()}};
  out["precision"] = total.precision();
  out["recall"] = total.recall();
  out["f1"] = total.f1();
  out["median_t_err_mm"] = median(terr);
  out["median_r_err_deg"] = median(rerr);
  out["surface_error_rms_mm_median"] = median(rms);
  out["surface_error_rms_mm_max"] = rms.empty() ? 0.0 : *std::max_element(rms.begin(), rms.end());
  // the limits a test sets (issue: thresholds derived from the measured distribution)
  json failed = json::array();
  if (o.limit_rms_mm > 0 && out["surface_error_rms_mm_max"].get<double>() > o.limit_rms_mm)
    failed.push_back("surface RMS " + std::to_string(out["surface_error_rms_mm_max"].get<double>()) + " mm > " +
                     std::to_string(o.limit_rms_mm));
  if (o.limit_t_mm > 0 && median(terr) > o.limit_t_mm)
    failed.push_back("median translation error " + std::to_string(median(terr)) + " mm > " + std::to_string(o.limit_t_mm));
  if (o.limit_r_deg > 0 && median(rerr) > o.limit_r_deg)
    failed.push_back("median rotation error " + std::to_string(median(rerr)) + " deg > " + std::to_string(o.limit_r_deg));
  if (o.limit_recall > 0 && total.recall() < o.limit_recall)
    failed.push_back("recall " + std::to_string(total.recall()) + " < " + std::to_string(o.limit_recall));
  out["limits_failed"] = failed;
  writeJson(o.json, out);
  std::printf("cells: %d found, %d missed (%d with no scan point on the part, %d whose scan points a false pose of its model "
              "fits as well), %d false\n",
              total.tp, total.fn, unmeasured, fits_both, total.fp);
  std::printf("cells: reported ambiguous (a turn fits about as well): %d of the found, %d of the false (%d whose other pose "
              "is the part's)\n",
              total.ambiguous_tp, total.ambiguous_fp, total.ambiguous_fp_alternative_right);
  std::printf("cells: with those whose other pose is the part's counted as found: P %.3f R %.3f F1 %.3f\n", lenient.precision(),
              lenient.recall(), lenient.f1());
  std::printf("cells: %zu seeds, P %.3f R %.3f F1 %.3f, median %.3f mm %.3f deg, surface RMS median %.4f mm max %.4f mm\n",
              seeds.size(), total.precision(), total.recall(), total.f1(), median(terr), median(rerr), median(rms),
              out["surface_error_rms_mm_max"].get<double>());
  if (two_passes)
    std::printf("cells: the second pass (%s) added %zu detections where the first (%s) had none\n", o.second_pass.c_str(),
                second_added, o.trajectory.c_str());
  for (const auto& f : failed) std::printf("cells: LIMIT EXCEEDED: %s\n", f.get<std::string>().c_str());
  return failed.empty() ? 0 : 4;
}


/// --root, --scene, --models (demo and the sweeps).
void addSceneOptions(CLI::App* c, Options& o) {
  c->add_option("--root", o.root, "repository root: the defaults of --scene, --models, --matching lie under it")
      ->check(CLI::ExistingDirectory)
      ->capture_default_str();
  c->add_option("--scene", o.scene, "scene YAML [default: <root>/config/scenes/demo.yaml]")->check(CLI::ExistingFile);
  c->add_option("--models", o.models, "model library folder [default: <root>/config/models]")->check(CLI::ExistingDirectory);
}

void addSuccessOptions(CLI::App* c, Options& o) {
  using cellsight_tools::positive;
  c->add_option("--max-t-mm", o.max_t_mm, "success: translation error at most this [mm]")->check(positive())->capture_default_str();
  c->add_option("--max-r-deg", o.max_r_deg, "success: rotation error at most this [deg]")->check(positive())->capture_default_str();
}

/// The options shared by occlusion and outliers.
void addSweepOptions(CLI::App* c, Options& o) {
  addSceneOptions(c, o);
  c->add_option("--matching", o.matching, "matching settings YAML [default: <root>/config/matching.yaml]")
      ->check(CLI::ExistingFile);
  c->add_option("--search", o.search, "all: every model searched (identify and locate); self: the part's own model (locate)")
      ->check(CLI::IsMember({"all", "self"}))
      ->capture_default_str();
  c->add_option("--parts", o.parts, "model ids, comma-separated")->delimiter(',')->capture_default_str();
  c->add_option("--trials", o.trials, "random views per part and level")->check(cellsight_tools::positiveInt())->capture_default_str();
  addSuccessOptions(c, o);
  c->add_option("--json", o.json, "write the figures to this JSON file");
  c->add_option("--png", o.png, "draw the success-rate curves (gnuplot) to this PNG; <png>.dat and <png>.gp stay beside it");
}

}  // namespace

int main(int argc, char** argv) {
  using cellsight_tools::fraction;
  using cellsight_tools::positive;
  CLI::App app("Localisation figures against ground truth: the demo scan's detections, the occlusion and outlier "
               "sweeps on single-view clouds, random cells.",
               "cellsight_evaluate_localization");
  app.require_subcommand(1);

  Options demo;
  demo.max_t_mm = demo.max_r_deg = 5;  // "found": the right model within 5 mm / 5° (a gross-error test)
  CLI::App* c_demo =
      app.add_subcommand("demo", "detections of the demo scan vs the simulator's truth (exit 3 unless every part is found)");
  c_demo->add_option("--detections", demo.detections, "detections_raw.json of the demo")->required()->check(CLI::ExistingFile);
  addSceneOptions(c_demo, demo);
  addSuccessOptions(c_demo, demo);
  c_demo->add_option("--json", demo.json, "write the figures to this JSON file");

  Options cld;
  cld.max_t_mm = cld.max_r_deg = 5;  // as demo
  CLI::App* c_cld = app.add_subcommand(
      "cloud", "a finished scan file clustered and located in-process with the repository's settings, scored against "
               "the scene's truth (exit 3 unless every part is found)");
  c_cld->add_option("--cloud", cld.cloud, "the scan (PLY, PCD), cropped and filtered as the nodes finish it")
      ->required()
      ->check(CLI::ExistingFile);
  addSceneOptions(c_cld, cld);
  c_cld->add_option("--matching", cld.matching, "matching settings YAML [default: <root>/config/matching.yaml]")
      ->check(CLI::ExistingFile);
  addSuccessOptions(c_cld, cld);
  c_cld->add_option("--json", cld.json, "write the figures to this JSON file");

  Options occ;
  occ.trials = 100;
  occ.parts = {"blade", "housing", "holder"};
  CLI::App* c_occ = app.add_subcommand("occlusion", "the thesis's random-walk occlusion test on single-view clouds of the parts");
  addSweepOptions(c_occ, occ);
  c_occ->add_option("--from", occ.from, "first occlusion share")->check(fraction())->capture_default_str();
  c_occ->add_option("--to", occ.to, "last occlusion share")->check(fraction())->capture_default_str();
  c_occ->add_option("--step", occ.step, "occlusion share step")->check(positive())->capture_default_str();
  c_occ->add_option("--ks", occ.ks, "random-walk k_s")->check(cellsight_tools::positiveInt())->capture_default_str();
  CLI::Option* min_fitness =
      c_occ->add_option("--min-fitness", occ.min_fitness, "validation fitness threshold [default: the matching settings']")
          ->check(fraction());

  Options outl;
  outl.trials = 50;
  outl.parts = {"blade", "housing", "holder", "bracket"};
  outl.ratios = {0, 0.25, 0.5, 1, 1.5, 2};
  CLI::App* c_out =
      app.add_subcommand("outliers", "uniform outliers with random normals in the workspace box, a ratio of the part's points");
  addSweepOptions(c_out, outl);
  c_out->add_option("--ratios", outl.ratios, "outlier ratios, comma-separated (1 = as many outliers as part points)")
      ->delimiter(',')
      ->check(cellsight_tools::nonNegative())
      ->capture_default_str();


  Options cells;
  cells.max_t_mm = cells.max_r_deg = 5;  // found: the right model within 5 mm / 5° (as the demo)
  std::vector<uint64_t> cell_seeds;
  std::string seeds_file, cells_out = "/tmp/cellsight_cells";
  CLI::App* c_cells = app.add_subcommand("cells", "random cells (scene generator) scanned in-process, clustered and located: "
                                                  "detection P/R/F1 and errors over seeds");
  addSceneOptions(c_cells, cells);
  addSuccessOptions(c_cells, cells);
  c_cells->add_option("--matching", cells.matching, "matching settings YAML [default: <root>/config/matching.yaml]")
      ->check(CLI::ExistingFile);
  c_cells->add_option("--seeds", cell_seeds, "scene seeds");
  c_cells->add_option("--trajectory", cells.trajectory, "the scan's trajectory (config/trajectories.yaml)")
      ->capture_default_str();
  c_cells->add_option("--second-pass", cells.second_pass,
                      "scan each cell again along this trajectory (e.g. reverse_sweep: the sheet leaning the other way), "
                      "locate on it alike and add the parts found where the first pass found none");
  c_cells->add_option("--dump-clusters", cells.dump_clusters, "write every scene's clusters (and its support points) as PLY into this folder");
  c_cells->add_option("--seeds-file", seeds_file, "a seeds file, e.g. config/heldout_seeds.yaml")->check(CLI::ExistingFile);
  c_cells->add_option("--out", cells_out, "where the generated scenes go")->capture_default_str();
  c_cells->add_option("--json", cells.json, "write the figures to this JSON file");
  c_cells->add_option("--calibration", cells.calibration,
                      "scan with this calibration folder (a self-calibration) instead of the simulator's truth")
      ->check(CLI::ExistingDirectory);
  c_cells->add_option("--limit-rms-mm", cells.limit_rms_mm, "exit 4 if any scene's surface RMS exceeds this [mm]")
      ->check(positive());
  c_cells->add_option("--limit-t-mm", cells.limit_t_mm, "exit 4 if the median translation error exceeds this [mm]")
      ->check(positive());
  c_cells->add_option("--limit-r-deg", cells.limit_r_deg, "exit 4 if the median rotation error exceeds this [deg]")
      ->check(positive());
  c_cells->add_option("--limit-recall", cells.limit_recall, "exit 4 if the recall is below this")->check(fraction());

  cellsight_tools::DescriptorEvalOptions desc;
  CLI::App* c_desc = app.add_subcommand("descriptors", "FPFH against the learned descriptor in the same RANSAC pipeline: "
                                                       "held-out laser views of our parts, real UWA / PCL scenes");
  c_desc->add_option("--root", desc.root, "the package folder (config/)")->capture_default_str();
  c_desc->add_option("--data", desc.data, "real point-cloud data [default: <root>/../shared/data/pointclouds]");
  c_desc->add_option("--parts", desc.parts, "parts, comma-separated")->delimiter(',')->capture_default_str();
  c_desc->add_option("--views", desc.views, "held-out views per part")->check(cellsight_tools::positiveInt())->capture_default_str();
  c_desc->add_option("--learned", desc.learned, "model trained with local reference frames")->capture_default_str();
  c_desc->add_option("--augment", desc.augment, "model trained by rotation augmentation")->capture_default_str();
  c_desc->add_option("--rotations", desc.rotations, "turns of the multi-rotation method")
      ->check(cellsight_tools::positiveInt())->capture_default_str();
  c_desc->add_option("--max-iterations", desc.max_iterations, "RANSAC hypotheses at most (every method)")
      ->check(cellsight_tools::positiveInt())->capture_default_str();
  c_desc->add_option("--sampling", desc.sampling,
                     "RANSAC sampling for every method and case: guided (one match, then two that agree with it, "
                     "from each scene point's nearest model descriptors) or uniform (three mutual matches, the thesis's)")
      ->check(CLI::IsMember({"guided", "uniform"}))
      ->capture_default_str();
  bool no_real = false;
  c_desc->add_flag("--no-real", no_real, "leave out the real scenes");
  c_desc->add_option("--json", desc.json, "write the figures to this JSON file");
  c_desc->add_option("--png", desc.png, "write the success plot to this PNG");
  c_desc->add_option("--limit-beats-fpfh", desc.limit_recall_margin,
                     "exit 4 unless the learned (LRF) descriptor's recall exceeds FPFH's by this and its registration "
                     "success is higher")
      ->check(cellsight_tools::nonNegative());

  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  desc.real = !no_real;
  if (!seeds_file.empty()) {
    YamlMap m(loadYamlFile(seeds_file), seeds_file);
    for (const auto& s : m.raw("seeds")) cell_seeds.push_back(s.as<uint64_t>());
    m.getString("base");
    m.finish();
  }
  occ.min_fitness_given = min_fitness->count() > 0;
  return cellsight_tools::runTool([&] {
    if (c_demo->parsed()) return runDemo(demo);
    if (c_cld->parsed()) return runCloud(cld);
    if (c_occ->parsed()) return runOcclusion(occ);
    if (c_out->parsed()) return runOutliers(outl);
    if (c_desc->parsed()) return cellsight_tools::runDescriptorEvaluation(desc);
    if (c_cells->parsed()) {
      if (cell_seeds.empty()) throw std::invalid_argument("cells: give --seeds or --seeds-file");
      return runCells(cells, cell_seeds, cells_out);
    }
    return 2;  // not reached: a subcommand is required
  });
}
