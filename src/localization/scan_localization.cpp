#include "cellsight/localization/scan_localization.hpp"

#include <stdexcept>

namespace cellsight {

const char* passRoleName(PassRole role) {
  switch (role) {
    case PassRole::kDetect:
      return "detect";
    case PassRole::kAddDetections:
      return "add_detections";
    case PassRole::kRefine:
      return "refine";
  }
  return "unknown";
}

PassRole passRoleFromName(const std::string& name) {
  for (PassRole r : {PassRole::kDetect, PassRole::kAddDetections, PassRole::kRefine})
    if (name == passRoleName(r)) return r;
  throw std::invalid_argument("unknown pass role '" + name + "' (detect, add_detections or refine)");
}

ScanPass scanPass(PassRole role, const ClusteringResult& clustered, const std::optional<Eigen::Vector3f>& viewpoint,
                  std::optional<LightSweep> light) {
  ScanPass p;
  p.role = role;
  for (const auto& c : clustered.clusters) p.clusters.push_back(c.cloud);
  p.evidence.viewpoint = viewpoint;
  if (clustered.plane_found)
    p.evidence.support_plane = Eigen::Vector4f(static_cast<float>(clustered.support.n.x()), static_cast<float>(clustered.support.n.y()),
                                               static_cast<float>(clustered.support.n.z()), static_cast<float>(clustered.support.d));
  p.evidence.support_points = clustered.support_points;
  p.evidence.light = std::move(light);
  p.evidence.fragments = clustered.fragments;
  return p;
}

namespace {

template <typename T>
const T* ptr(const std::optional<T>& o) {
  return o ? &*o : nullptr;
}

PassResult locatePass(const ModelMatcher& matcher, const ScanPass& pass, const std::vector<Eigen::Vector3f>& support_points,
                      const std::vector<std::string>& models) {
  PassResult r;
  const ScanEvidence& e = pass.evidence;
  r.found = matcher.locate(pass.clusters, models, &r.stats, ptr(e.viewpoint), ptr(e.support_plane), &support_points,
                           ptr(e.light), &e.fragments);
  return r;
}

void checkPasses(const std::vector<ScanPass>& passes) {
  if (passes.empty()) throw std::invalid_argument("locateScan: no pass to locate on");
  if (passes.front().role != PassRole::kDetect)
    throw std::invalid_argument(std::string("locateScan: the first pass must detect, not ") + passRoleName(passes.front().role));
  for (size_t k = 1; k < passes.size(); ++k)
    if (passes[k].role == PassRole::kDetect)
      throw std::invalid_argument("locateScan: pass " + std::to_string(k) + " detects again: only the first pass detects");
}

}  // namespace

void addPass(const ModelMatcher& matcher, const std::vector<ScanPass>& passes, LocatedScan* so_far,
             const std::vector<std::string>& models) {
  const size_t k = so_far->passes.size();
  if (k >= passes.size())
    throw std::invalid_argument("addPass: all " + std::to_string(passes.size()) + " passes are located already");
  checkPasses({passes.begin(), passes.begin() + static_cast<std::ptrdiff_t>(k + 1)});
  LocatedScan& out = *so_far;
  const ScanPass& pass = passes[k];
  if (k == 0) {
    out.passes.push_back(locatePass(matcher, pass, pass.evidence.support_points, models));
    out.stats = out.passes.front().stats;
    out.parts = out.passes.front().found;
  } else if (pass.role == PassRole::kAddDetections) {
    // the cell stands still between passes: where any pass saw the table, no part is
    std::vector<Eigen::Vector3f> seen = pass.evidence.support_points;
    for (size_t j = 0; j < k; ++j)
      seen.insert(seen.end(), passes[j].evidence.support_points.begin(), passes[j].evidence.support_points.end());
    PassResult r = locatePass(matcher, pass, seen, models);
    out.parts = matcher.mergePasses(out.parts, r.found, &out.stats);
    for (auto rejected : r.stats.rejected) {
      rejected.pass = 1;
      out.stats.rejected.push_back(std::move(rejected));
    }
    out.stats.seconds += r.stats.seconds;
    out.passes.push_back(std::move(r));
  } else {
    // this pass's points above the support with every earlier pass's: each pins what the
    // others leave loose (one runs along the edges another crosses)
    const ScanEvidence& first = passes.front().evidence;
    ScanCloud above;
    for (size_t j = k + 1; j-- > 0;)
      for (const auto& c : passes[j].clusters) above.points.insert(above.points.end(), c.points.begin(), c.points.end());
    PassResult r;
    r.found = matcher.refine(above, out.parts, &r.stats, ptr(first.viewpoint), ptr(first.support_plane));
    out.parts = r.found;
    out.stats.warnings.insert(out.stats.warnings.end(), r.stats.warnings.begin(), r.stats.warnings.end());
    out.stats.seconds += r.stats.seconds;
    out.passes.push_back(std::move(r));
  }
}

LocatedScan locateScan(const ModelMatcher& matcher, const std::vector<ScanPass>& passes, const std::vector<std::string>& models) {
  checkPasses(passes);
  LocatedScan out;
  for (size_t k = 0; k < passes.size(); ++k) addPass(matcher, passes, &out, models);
  return out;
}

}  // namespace cellsight
