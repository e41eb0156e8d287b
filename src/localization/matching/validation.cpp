// Validation of a refined pose (coverage, visible fitness, support, acceptance) and the
// symmetry-aware pose error and canonical pose.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <string>

#include "matching_internal.hpp"

namespace cellsight {
namespace matching_detail {

/// Share of the coarse scene points within r of the model under T.
double coverage(const SceneData& s, const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T, double r) {
  if (s.coarse.size() == 0) return 0;
  const Eigen::Isometry3f Ti = T.inverse();
  const float r2 = static_cast<float>(r * r);
  size_t n = 0;
  for (const auto& p : s.coarse.points) {
    const Vec3 q = Ti * p;
    const int j = m.field.lookup(q);
    if (j >= 0 && (q - m.fine->points[j]).squaredNorm() <= r2) ++n;
  }
  return static_cast<double>(n) / s.coarse.size();
}

SupportSeen buildSupportSeen(const std::vector<Vec3>& points, const Eigen::Vector4f& plane, float cell) {
  SupportSeen g;
  const Vec3 n = plane.head<3>();
  if (points.empty() || !(cell > 0) || !plane.allFinite() || std::abs(n.norm() - 1.f) > 1e-3f) return g;
  g.n = n;
  g.d = plane.w();
  g.u = n.unitOrthogonal();
  g.v = n.cross(g.u);
  g.cell = cell;
  Eigen::Vector2f lo = Eigen::Vector2f::Constant(std::numeric_limits<float>::max()), hi = -lo;
  std::vector<Eigen::Vector2f> uv;
  uv.reserve(points.size());
  for (const auto& p : points) {
    if (!p.allFinite()) continue;
    uv.emplace_back(g.u.dot(p), g.v.dot(p));
    lo = lo.cwiseMin(uv.back());
    hi = hi.cwiseMax(uv.back());
  }
  if (uv.empty()) return g;
  // at most 16 M cells: a huge support is mapped coarser
  const Eigen::Vector2f size = hi - lo;
  g.cell = std::max(cell, std::sqrt(size.x() * size.y() / 16e6f));
  g.lo = lo;
  g.nu = static_cast<int>(size.x() / g.cell) + 1;
  g.nv = static_cast<int>(size.y() / g.cell) + 1;
  std::vector<uint8_t> hit(static_cast<size_t>(g.nu) * g.nv, 0);
  for (const auto& q : uv) {
    const int i = std::min(g.nu - 1, static_cast<int>((q.x() - lo.x()) / g.cell));
    const int j = std::min(g.nv - 1, static_cast<int>((q.y() - lo.y()) / g.cell));
    hit[static_cast<size_t>(j) * g.nu + i] = 1;
  }
  // eroded: a cell counts as seen when it and its 8 neighbours are (a missing cell between
  // sparse support points erodes its neighbours too: the test then checks less, never more)
  g.seen.assign(hit.size(), 0);
  for (int j = 1; j + 1 < g.nv; ++j) {
    for (int i = 1; i + 1 < g.nu; ++i) {
      bool all = true;
      for (int dj = -1; dj <= 1 && all; ++dj)
        for (int di = -1; di <= 1 && all; ++di) all = hit[static_cast<size_t>(j + dj) * g.nu + i + di] != 0;
      g.seen[static_cast<size_t>(j) * g.nu + i] = all;
    }
  }
  g.points = PointGrid(points, cell);
  return g;
}

bool SupportSeen::behind(const Vec3& eye, const Vec3& p, float min_height, Vec3* q) const {
  const float hp = n.dot(p) + d, he = n.dot(eye) + d;
  if (hp <= min_height || he <= hp) return false;  // low, or the eye is not above the point
  *q = p + (p - eye) * (hp / (he - hp));
  return true;
}

bool SupportSeen::measuredBehind(const Vec3& eye, const Vec3& p, float min_height, float r) const {
  Vec3 q;
  return points.size() > 0 && behind(eye, p, min_height, &q) && points.anyWithin(q, r);
}

bool SupportSeen::seenBehind(const Vec3& eye, const Vec3& p, float min_height) const {
  Vec3 q;
  if (!behind(eye, p, min_height, &q)) return false;
  const int i = static_cast<int>(std::floor((u.dot(q) - lo.x()) / cell));
  const int j = static_cast<int>(std::floor((v.dot(q) - lo.y()) / cell));
  return i >= 0 && j >= 0 && i < nu && j < nv && seen[static_cast<size_t>(j) * nu + i] != 0;
}

/// How far along the camera's ray and the beam the unseen test looks for what hid a point (m):
/// beyond the tallest part a cell holds.
constexpr float kUnseenReach = 0.25f;
/// Model points whose normals agree this well (cos) lie on one face for the unseen test's rim.
constexpr float kSameFace = 0.7f;

/// Share of the model's points visible from the viewpoint (facing it, not hidden by the part
/// itself) and, with s.light, lit by the sheet (facing its emitter, not shadowed by the part
/// itself) that have a scene point within r_F (of every cluster of the call when s.whole is set).
double visibleFitness(const SceneData& s, const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T,
                      const MatchingConfig& cfg, double* see_through, double* unseen, double* overhang) {
  const Eigen::Isometry3f Ti = T.inverse();
  const Vec3 eye = Ti * cfg.viewpoint;
  const float cos_max = std::cos(static_cast<float>(cfg.max_view_angle));
  const float r2 = static_cast<float>(cfg.fitness_radius * cfg.fitness_radius);
  std::vector<int> idx(1);
  std::vector<float> d2(1);
  size_t visible = 0, matched = 0, through = 0, over = 0;
  // the scanner's response at the point's camera incidence (1: every visible point alike)
  const bool weigh = cfg.fitness_incidence_mid > 0;
  const float mid = static_cast<float>(cfg.fitness_incidence_mid);
  const float width = static_cast<float>(cfg.fitness_incidence_width);
  double weight_visible = 0, weight_matched = 0;
  const SupportSeen* seen = see_through && s.support_seen && !s.support_seen->empty() ? s.support_seen : nullptr;
  // the scan points (every cluster's): the overhang test's clearance; the unseen test searches
  // them along the camera's ray and the beam too
  const PointGrid* all_scan = s.whole ? s.whole : cfg.scene_search == "grid" ? &s.grid : nullptr;
  const PointGrid* scan = all_scan;
  if (unseen) *unseen = 0;
  const bool test_over = overhang && s.support_seen && s.support_seen->points.size() > 0 && all_scan;
  const float r_clear = static_cast<float>(cfg.overhang_clearance), r_table = static_cast<float>(cfg.overhang_table_radius);
  if (!s.light || !cfg.check_visibility) scan = nullptr;
  const bool test_unseen = unseen && scan;
  const float cos_unseen = std::cos(static_cast<float>(cfg.unseen_view_angle));
  const float r_unseen = static_cast<float>(cfg.unseen_radius);
  const float step = static_cast<float>(std::max(0.0005, 0.5 * cfg.voxel));
  const bool has_support = s.support_seen && !s.support_seen->empty();
  // a found part's mesh (the second look: s.found) lies on the path from p along dir between
  // near and far, where the path enters it (a path that first leaves a mesh starts inside that
  // part: overlap, which must not pass for shade)
  auto foundOnPath = [&](const Vec3& p, const Vec3& dir, float near, float far) {
    if (!s.found) return false;
    for (const auto& [part, Tp] : *s.found) {
      if (!part->has_mesh) continue;
      const Vec3 d = Tp.linear() * dir;
      const RayHit hit = part->caster.intersect(Tp * p, d, near, far);
      if (hit.hit && hit.normal.dot(d) < 0) return true;
    }
    return false;
  };
  // nothing the scan measured lies within a step of the segment p → to, leaving p's own surface,
  // and no found part's mesh stops it
  auto clearPath = [&](const Vec3& p, const Vec3& to) {
    const Vec3 ray = to - p;
    const float len = std::min(ray.norm(), kUnseenReach);
    const Vec3 dir = ray.normalized();
    for (float t = r_unseen; t < len; t += step)
      if (scan->anyWithin(p + t * dir, step)) return false;
    return !foundOnPath(p, dir, r_unseen, len);
  };
  // the unseen test's model points: 1 visible and lit, 2 also a candidate miss
  std::vector<uint8_t> state(test_unseen ? m.coarse->points.size() : 0, 0);
  const float min_height = static_cast<float>(cfg.voxel);  // the lowest band: the part's own footprint
  const auto& mp = m.coarse->points;
  const auto& mn = m.coarse->normals;
  // model point i faces `from` (model frame) within max_view_angle and the part does not hide it
  const float margin = static_cast<float>(std::max(0.0005, 0.5 * cfg.voxel));
  auto reaches = [&](const Vec3& from, size_t i) {
    const Vec3 ray = mp[i] - from;
    const float dist = ray.norm();
    if (dist <= 0) return false;
    const Vec3 dir = ray / dist;
    if (-mn[i].dot(dir) < cos_max) return false;
    return !(m.has_mesh && m.caster.occluded(from, dir, 0.f, dist - margin));
  };
  // a found part's mesh stands between p and `to` (scene frame)
  auto shaded = [&](const Vec3& p, const Vec3& to) {
    const float len = (to - p).norm();
    return len > margin && foundOnPath(p, (to - p) / len, margin, len);
  };
  for (size_t i = 0; i < mp.size(); ++i) {
    Vec3 emitter = Vec3::Zero();
    float fan_margin = 0;
    if (cfg.check_visibility) {
      if (!reaches(eye, i)) continue;  // the camera does not see it
      // no sheet of the sweep passed it, or the sheet did not reach it
      if (s.light && (!s.light->emitterFor(T * mp[i], &emitter, &fan_margin) || !reaches(Ti * emitter, i))) continue;
      // a found part hides it from the camera or shades it from the sheet
      if (s.found && (shaded(T * mp[i], cfg.viewpoint) || (s.light && shaded(T * mp[i], emitter)))) continue;
    }
    ++visible;
    float w = 1.f;
    if (weigh && (mp[i] - eye).squaredNorm() > 0) {
      const float incidence = std::acos(std::clamp(-mn[i].dot((mp[i] - eye).normalized()), -1.f, 1.f));
      w = 1.f / (1.f + std::exp((incidence - mid) / width));
    }
    weight_visible += w;
    if (test_unseen) state[i] = 1;
    const Vec3 p = T * mp[i];
    if (seen && seen->seenBehind(cfg.viewpoint, p, min_height)) ++through;
    // (a point the camera sees squarely: near a steep face's foot the table is measured within
    // overhang_table_radius of where a grazing ray through the face would meet it)
    if (test_over && -mn[i].dot((mp[i] - eye).normalized()) >= cos_unseen && !all_scan->anyWithin(p, r_clear) &&
        s.support_seen->measuredBehind(cfg.viewpoint, p, min_height, r_table))
      ++over;
    bool hit = false;
    if (s.whole) {
      hit = s.whole->anyWithin(p, static_cast<float>(cfg.fitness_radius));
    } else if (cfg.scene_search == "grid") {
      hit = s.grid.anyWithin(p, static_cast<float>(cfg.fitness_radius));
    } else {
      hit = s.tree.nearestKSearch(pcl::PointXYZ(p.x(), p.y(), p.z()), 1, idx, d2) == 1 && d2[0] <= r2;
    }
    matched += hit;
    if (hit) weight_matched += w;
    // measured well had it been there: it faces camera and emitter squarely, well inside the
    // fan, clear of the support's band and of every scan point, and nothing the scan saw is on
    // the ray or the beam
    if (!hit && test_unseen && fan_margin >= kFanEdgeMargin && -mn[i].dot((mp[i] - eye).normalized()) >= cos_unseen &&
        -mn[i].dot((mp[i] - Ti * emitter).normalized()) >= cos_unseen &&
        !(has_support && s.support_seen->n.dot(p) + s.support_seen->d <= r_unseen) && !scan->anyWithin(p, r_unseen) &&
        clearPath(p, cfg.viewpoint) && clearPath(p, emitter))
      state[i] = 2;
  }
  // ... and inside what camera and sheet reach, not at its rim: every point of its own face
  // within unseen_radius is visible and lit too (a sliver lit beside a shadow's edge gives the
  // line extraction segments too short to keep)
  size_t missed = 0;
  const float r_face2 = r_unseen * r_unseen;
  for (size_t i = 0; i < state.size(); ++i) {
    if (state[i] != 2) continue;
    bool inside = true;
    for (size_t j = 0; j < mp.size() && inside; ++j)
      inside = state[j] != 0 || (mp[j] - mp[i]).squaredNorm() > r_face2 || mn[j].dot(mn[i]) < kSameFace;
    missed += inside;
  }
  if (see_through) *see_through = visible ? static_cast<double>(through) / visible : 0.0;
  if (overhang) *overhang = visible ? static_cast<double>(over) / visible : 0.0;
  if (unseen) *unseen = visible ? static_cast<double>(missed) / visible : 0.0;
  if (weigh) return weight_visible > 0 ? weight_matched / weight_visible : 0.0;
  return visible ? static_cast<double>(matched) / visible : 0.0;
}

double continuation(const SceneData& s, const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T,
                    const MatchingConfig& cfg, const Eigen::Vector4f* support) {
  const Eigen::Isometry3f Ti = T.inverse();
  const float r = static_cast<float>(cfg.fitness_radius), reach = static_cast<float>(cfg.continuation_reach);
  const float tol = static_cast<float>(cfg.continuation_tolerance);
  const auto& fp = m.fine->points;
  const auto& fn = m.fine->normals;
  if (fn.size() != fp.size()) return 0;
  std::vector<int> idx(1);
  std::vector<float> d2(1), near_d2;
  std::vector<int> near;
  size_t explained = 0, beyond = 0;
  for (size_t i = 0; i < s.coarse.size(); ++i) {
    const Vec3& p = s.coarse.points[i];
    const Vec3 q = Ti * p;
    if (m.fine_tree.nearestKSearch(pcl::PointXYZ(q.x(), q.y(), q.z()), 1, idx, d2) != 1) continue;
    if (d2[0] <= r * r) {
      ++explained;
      continue;
    }
    if (d2[0] > reach * reach) continue;
    if (support && support->head<3>().dot(p) + support->w() <= reach) continue;  // the table carries on the bottom
    if (i >= s.coarse.normals.size()) continue;
    const Vec3 sn = Ti.linear() * s.coarse.normals[i];
    // a face near it whose plane it lies in, facing as the scan's surface does there
    bool carries = false;
    m.fine_tree.radiusSearch(pcl::PointXYZ(q.x(), q.y(), q.z()), reach, near, near_d2);
    for (size_t k = 0; k < near.size() && !carries; ++k) {
      const size_t j = static_cast<size_t>(near[k]);
      carries = std::abs(sn.dot(fn[j])) >= 0.9f && std::abs(fn[j].dot(q - fp[j])) <= tol;
    }
    if (!carries) continue;
    ++beyond;
  }
  return explained ? static_cast<double>(beyond) / static_cast<double>(explained) : 0.0;
}

/// How far the model under T reaches below the support plane (m; <= 0: not at all).
float belowSupport(const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T, const Eigen::Vector4f& plane) {
  float lowest = std::numeric_limits<float>::infinity();
  for (const auto& v : m.extremes) lowest = std::min(lowest, plane.head<3>().dot(T * v) + plane.w());
  return m.extremes.empty() ? 0.f : -lowest;
}

bool offSupport(const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T, const Eigen::Vector4f& plane,
                const MatchingConfig& cfg, float slack) {
  const float below = belowSupport(m, T, plane);
  if (below > static_cast<float>(cfg.max_support_penetration) + slack) return true;
  return cfg.max_support_gap > 0 && -below > static_cast<float>(cfg.max_support_gap) + slack;
}

namespace {
/// The acceptance tests after the score's, in order: `fail(wording, figure, limit)` for each that
/// `d` fails (a NaN figure fails). accepted() and refusalReasons() both read this one list.
template <class Fail>
void failedTests(const PartDetection& d, const MatchingConfig& cfg, double min_fitness, Fail&& fail) {
  if (!(d.fitness >= min_fitness)) fail("fitness %.3f < min_fitness %.3f", d.fitness, min_fitness);
  if (!(d.coverage >= cfg.min_coverage)) fail("coverage %.3f < min_coverage %.3f", d.coverage, cfg.min_coverage);
  if (!(d.rmse <= cfg.max_rmse)) fail("rmse %.3f mm > max_rmse %.3f mm", d.rmse * 1e3, cfg.max_rmse * 1e3);
  if (!(d.see_through <= cfg.max_see_through))
    fail("see-through %.3f > max_see_through %.3f", d.see_through, cfg.max_see_through);
  if (!(d.overhang <= cfg.max_overhang)) fail("overhang %.3f > max_overhang %.3f", d.overhang, cfg.max_overhang);
  if (!(d.unseen <= cfg.max_unseen)) fail("unseen %.3f > max_unseen %.3f", d.unseen, cfg.max_unseen);
  if (!(cfg.max_continuation >= 1 || d.continuation <= cfg.max_continuation))
    fail("continuation %.4f > max_continuation %.4f", d.continuation, cfg.max_continuation);
}
}  // namespace

bool accepted(const PartDetection& d, const MatchingConfig& cfg) { return accepted(d, cfg, cfg.min_fitness); }

bool accepted(const PartDetection& d, const MatchingConfig& cfg, double min_fitness) {
  if (!(d.score > 0)) return false;
  bool ok = true;
  failedTests(d, cfg, min_fitness, [&](const char*, double, double) { ok = false; });
  return ok;
}

}  // namespace matching_detail

namespace {

Eigen::Matrix3d rotationAbout(const Eigen::Vector3d& axis, double angle) {
  return Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
}

double rotationAngle(const Eigen::Matrix3d& R) { return Eigen::AngleAxisd(R).angle(); }

}  // namespace

PoseError poseError(const ModelInfo& info, const Eigen::Vector3d& centroid, const Eigen::Isometry3d& est,
                    const Eigen::Isometry3d& truth) {
  PoseError e;
  e.translation = (est * centroid - truth * centroid).norm();
  const Eigen::Vector3d a = info.symmetry.axis.normalized();
  switch (info.symmetry.type) {
    case Symmetry::Type::kNone:
      e.rotation = rotationAngle(est.linear().transpose() * truth.linear());
      break;
    case Symmetry::Type::kDiscrete: {
      e.rotation = M_PI;
      for (int k = 0; k < info.symmetry.order; ++k) {
        const Eigen::Matrix3d Rk = est.linear() * rotationAbout(a, 2 * M_PI * k / info.symmetry.order);
        e.rotation = std::min(e.rotation, rotationAngle(Rk.transpose() * truth.linear()));
      }
      break;
    }
    case Symmetry::Type::kAxial:
      e.rotation = std::acos(std::clamp((est.linear() * a).dot(truth.linear() * a), -1.0, 1.0));
      break;
    case Symmetry::Type::kSpherical:
      e.rotation = 0;
      break;
  }
  return e;
}

Eigen::Isometry3d canonicalPose(const ModelInfo& info, const Eigen::Vector3d& centroid, const Eigen::Isometry3d& pose) {
  Eigen::Isometry3d out = pose;
  const Eigen::Vector3d a = info.symmetry.axis.normalized();
  // how far the model's x axis, turned about the axis, is from the scene's +x
  auto xCost = [&](const Eigen::Matrix3d& R) { return -(R * Eigen::Vector3d::UnitX()).x(); };
  switch (info.symmetry.type) {
    case Symmetry::Type::kNone:
      break;
    case Symmetry::Type::kDiscrete: {
      double best = 1e9;
      for (int k = 0; k < info.symmetry.order; ++k) {
        const Eigen::Matrix3d R = pose.linear() * rotationAbout(a, 2 * M_PI * k / info.symmetry.order);
        if (xCost(R) < best - 1e-9) {
          best = xCost(R);
          out.linear() = R;
        }
      }
      break;
    }
    case Symmetry::Type::kAxial: {
      // maximise (R Rot(a,θ) x)·X = cosθ·u + sinθ·v with u = (R x)·X, v = (R (a × x))·X
      Eigen::Vector3d x = Eigen::Vector3d::UnitX();
      if (std::abs(a.dot(x)) > 0.9) x = Eigen::Vector3d::UnitY();
      x = (x - a * a.dot(x)).normalized();
      const Eigen::Vector3d y = a.cross(x);
      const double u = (pose.linear() * x).x(), v = (pose.linear() * y).x();
      const double theta = std::atan2(v, u);
      out.linear() = pose.linear() * rotationAbout(a, theta);
      break;
    }
    case Symmetry::Type::kSpherical:
      out.linear().setIdentity();
      out.translation() = pose * centroid - centroid;
      break;
  }
  return out;
}

std::string refusalReasons(const PartDetection& d, const MatchingConfig& c) {
  if (d.score <= 0 && d.fitness <= 0 && d.coverage <= 0) return "no pose fitted";
  std::string out;
  char buf[128];
  matching_detail::failedTests(d, c, c.min_fitness, [&](const char* fmt, double figure, double limit) {
    std::snprintf(buf, sizeof(buf), fmt, figure, limit);
    out += (out.empty() ? "" : "; ") + std::string(buf);
  });
  if (out.empty() && !(d.score > 0)) out = "score 0 (fitness x coverage)";
  return out;
}

std::vector<std::string> refusedClusters(const std::vector<PartDetection>& found, const MatchStats& stats) {
  std::map<int, const PartDetection*> best;
  for (const auto& r : stats.rejected) {
    if (r.cluster < 0 || r.score <= 0 || r.refused_by.empty()) continue;
    if (std::any_of(found.begin(), found.end(), [&](const PartDetection& d) { return d.cluster == r.cluster; })) continue;
    const PartDetection*& b = best[r.cluster];
    if (!b || r.score > b->score) b = &r;
  }
  std::vector<std::string> out;
  char buf[160];
  for (const auto& [cluster, r] : best) {
    std::snprintf(buf, sizeof(buf), "cluster %d: no part accepted; the best refused, %s (fitness %.3f, coverage %.3f): ", cluster,
                  r->model.c_str(), r->fitness, r->coverage);
    out.push_back(buf + r->refused_by);
  }
  return out;
}

}  // namespace cellsight
