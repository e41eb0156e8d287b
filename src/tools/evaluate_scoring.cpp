// The scoring of cellsight_evaluate_localization: detections against the scene's truth, and
// what the scan measured of each part.
#include <algorithm>
#include <cmath>
#include <limits>

#include "cellsight/common/mesh.hpp"
#include "cellsight/eval/evaluation.hpp"
#include "cellsight/localization/model_library.hpp"
#include "evaluate_localization.hpp"
#include "json_pose.hpp"

using namespace cellsight;
using json = nlohmann::json;

namespace cellsight_tools {
namespace {

const double kDeg = M_PI / 180;

/// The matcher's word on a detection's turns (PartDetection::ambiguous_poses), for the JSON:
/// whether it is ambiguous, the best turn's score share, and each reported pose's turn from it.
void addAmbiguity(const ScoredDetection& d, const ModelInfo& info, const Eigen::Vector3d& centroid, json* j) {
  (*j)["ambiguous"] = !d.ambiguous_poses.empty();
  (*j)["alternative_score_share"] = d.alternative_score_share;
  if (d.ambiguous_poses.empty()) return;
  (*j)["ambiguous_turns_deg"] = json::array();
  for (const auto& a : d.ambiguous_poses) (*j)["ambiguous_turns_deg"].push_back(poseError(info, centroid, a, d.pose).rotation / kDeg);
}

}  // namespace

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

/// What the scan measured of each part (evaluation only: from the truth). Each part gets
/// `scan_points`, the scan points on its true surface (`on_object`: per point, the scene object
/// it lies on within kOnSurface, SurfaceDistance::stats). A false detection of a part's model
/// whose nearest object is that part, missed, gets `part_points_on_it`: the share of the part's
/// scan points that lie within kOnSurface of the detected pose's surface too (1: the points
/// cannot tell the two poses apart; only where nothing was measured can).
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

}  // namespace cellsight_tools
