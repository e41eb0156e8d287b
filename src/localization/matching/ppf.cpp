// Coarse stage "ppf": the model's point pair feature table (Drost et al. 2010), voting over
// the scene's point pairs, and the best-voted poses scored on the distance field.
#include <algorithm>
#include <array>
#include <limits>
#include <numeric>
#include <random>

#include "cellsight/common/polygon.hpp"
#include "matching_internal.hpp"

namespace cellsight::matching_detail {
namespace {

/// Cluster points of the short ICP that brings a laid face in before it is scored.
constexpr size_t kPlanarIcpPoints = 200;
/// Iterations of the short ICP that brings a rest hypothesis in before it is scored.
constexpr int kRestIcpIterations = 10;
/// A cluster narrower than this share of a rest's upward faces along an axis is a partial view of them.
constexpr float kPartialView = 0.7f;
/// How far beyond a cluster's end the sheet is asked whether it reached (m).
constexpr float kBeyondEnd = 0.003f;

/// atan2 to within 2e-6 rad of std::atan2 (measured over 300 000 angles; a minimax polynomial on
/// [0, 1] and octant folding): PPF angles are binned in 12° steps, so libm's exactness only
/// costs time in the voting loop.
float fastAtan2(float y, float x) {
  const float ax = std::abs(x), ay = std::abs(y);
  const float mx = std::max(ax, ay), mn = std::min(ax, ay);
  if (mx == 0.f) return 0.f;
  const float a = mn / mx, s = a * a;
  float r = a * (0.99997726f + s * (-0.33262347f + s * (0.19354346f + s * (-0.11643287f + s * (0.05265332f + s * -0.0117212f)))));
  if (ay > ax) r = static_cast<float>(M_PI_2) - r;
  if (x < 0.f) r = static_cast<float>(M_PI) - r;
  return y < 0.f ? -r : r;
}

/// Transform taking p to the origin and n onto +x.
Eigen::Isometry3f toLocalFrame(const Vec3& p, const Vec3& n) {
  Eigen::Isometry3f T = Eigen::Isometry3f::Identity();
  T.linear() = Eigen::Quaternionf::FromTwoVectors(n, Vec3::UnitX()).toRotationMatrix();
  T.translation() = -(T.linear() * p);
  return T;
}

float pairAlpha(const Eigen::Isometry3f& local, const Vec3& p2) {
  const Vec3 q = local * p2;
  return fastAtan2(-q.z(), q.y());
}

bool ppfKey(const Vec3& p1, const Vec3& n1, const Vec3& p2, const Vec3& n2, float dist_step, const AngleBins& q,
            uint64_t* key) {
  const Vec3 d = p2 - p1;
  const float len = d.norm();
  if (len < 1e-6f) return false;
  const Vec3 du = d / len;
  const uint64_t bins = static_cast<uint64_t>(q.bins());
  const uint64_t f1 = static_cast<uint64_t>(len / dist_step);
  *key = (((f1 * bins + q(n1.dot(du))) * bins + q(n2.dot(du))) * bins) + q(n1.dot(n2));
  return true;
}

/// Drost-style voting: every `ref_step`-th scene point pairs with all scene points within the
/// model's diameter; each pair's feature looks up model pairs; votes go to (model reference,
/// rotation about the normal). One pose per scene reference, with its votes.
std::vector<Hypothesis> ppfVoting(const ScanCloud& scene, const ModelMatcher::ModelIndex& m, int ref_step) {
  const PpfTable& t = m.ppf;
  const int bins = t.angle_bins;
  const size_t M = m.ppf_cloud.size();
  std::vector<Hypothesis> out;
  if (M == 0 || scene.size() < 2) return out;
  std::vector<int> acc(M * bins);
  std::vector<uint32_t> touched;  // cells voted for by the current reference (reset after it)
  const float max_d2 = m.diameter * m.diameter;
  const float to_bin = bins / static_cast<float>(2 * M_PI);
  for (size_t r = 0; r < scene.size(); r += static_cast<size_t>(std::max(1, ref_step))) {
    for (uint32_t k : touched) acc[k] = 0;
    touched.clear();
    const Vec3 &pr = scene.points[r], &nr = scene.normals[r];
    const Eigen::Isometry3f Ls = toLocalFrame(pr, nr);
    // the running maximum (lowest cell on ties, as a scan would find it) instead of a scan
    // of the M × bins accumulator per reference
    int best = 0;
    size_t best_k = 0;
    for (size_t i = 0; i < scene.size(); ++i) {
      if (i == r || (scene.points[i] - pr).squaredNorm() > max_d2) continue;
      uint64_t key;
      if (!ppfKey(pr, nr, scene.points[i], scene.normals[i], t.dist_step, t.angles, &key)) continue;
      const auto [lo, hi] = t.range(key);
      if (lo == hi) continue;
      // rotation bin of α_m − α_s, wrapped into [0, bins): entries carry α_m in bins already
      const float as = pairAlpha(Ls, scene.points[i]) * to_bin - static_cast<float>(bins);
      for (size_t e = lo; e < hi; ++e) {
        int b = static_cast<int>(t.entries[e].alpha - as);  // in [bins/2, 5 bins/2)
        if (b >= bins) b -= bins;
        if (b >= bins) b -= bins;
        const size_t k = static_cast<size_t>(t.entries[e].cell) + static_cast<size_t>(b);
        const int v = ++acc[k];
        if (v == 1) touched.push_back(static_cast<uint32_t>(k));
        if (v > best || (v == best && k < best_k)) {
          best = v;
          best_k = k;
        }
      }
    }
    if (best < 3) continue;
    const size_t k = best_k;
    const int mr = static_cast<int>(k / bins);
    const float alpha = (static_cast<float>(k % bins) + 0.5f) / to_bin - static_cast<float>(M_PI);
    const Eigen::Isometry3f Lm = toLocalFrame(m.ppf_cloud.points[mr], m.ppf_cloud.normals[mr]);
    Hypothesis h;
    h.T = Ls.inverse() * Eigen::AngleAxisf(alpha, Vec3::UnitX()) * Lm;
    h.score = best;
    out.push_back(h);
  }

  return out;
}

}  // namespace

PpfTable buildPpf(const ScanCloud& c, float dist_step, int bins, size_t max_bucket) {
  PpfTable t;
  t.dist_step = dist_step;
  t.angle_bins = bins;
  t.angles = AngleBins(bins);
  std::vector<std::pair<uint64_t, PpfTable::Entry>> all;
  all.reserve(c.size() * (c.size() - 1));
  for (size_t i = 0; i < c.size(); ++i) {
    const Eigen::Isometry3f L = toLocalFrame(c.points[i], c.normals[i]);
    for (size_t j = 0; j < c.size(); ++j) {
      uint64_t key;
      if (i == j || !ppfKey(c.points[i], c.normals[i], c.points[j], c.normals[j], dist_step, t.angles, &key)) continue;
      const float alpha_bins = (pairAlpha(L, c.points[j]) + static_cast<float>(M_PI)) * bins / static_cast<float>(2 * M_PI);
      all.push_back({key, {static_cast<int32_t>(i) * bins, std::min(alpha_bins, std::nextafter(static_cast<float>(bins), 0.f))}});
    }
  }
  // by key, then by accumulator cell: a key's votes then walk the accumulator forwards
  std::sort(all.begin(), all.end(), [](const auto& a, const auto& b) {
    return a.first < b.first || (a.first == b.first && a.second.cell < b.second.cell);
  });
  // Features shared by very many pairs (two points on one large flat face differ only in their
  // distance) say little about the pose and cost most of the voting: leave them out.
  t.entries.reserve(all.size());
  const bool dense = all.empty() || all.back().first + 2 <= PpfTable::kMaxDenseKeys;
  if (dense) t.offset.assign(all.empty() ? 1 : all.back().first + 2, 0);
  for (size_t a = 0; a < all.size();) {
    size_t b = a;
    while (b < all.size() && all[b].first == all[a].first) ++b;
    if (b - a <= max_bucket) {
      for (size_t k = a; k < b; ++k) {
        t.entries.push_back(all[k].second);
        if (!dense) t.keys.push_back(all[k].first);
      }
    }
    if (dense) t.offset[all[a].first + 1] = static_cast<uint32_t>(t.entries.size());  // end of this key
    a = b;
  }
  // keys without entries end where the previous key ended
  for (size_t k = 1; k < t.offset.size(); ++k) t.offset[k] = std::max(t.offset[k], t.offset[k - 1]);
  return t;
}

std::vector<FacePatch> facePatches(const TriangleMesh& mesh, const PlanarFaces& faces, float min_area) {
  struct Sum {
    double area = 0;
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    Eigen::Matrix3d cc = Eigen::Matrix3d::Zero();
  };
  std::vector<Sum> sum(faces.groups.size());
  for (size_t f = 0; f < mesh.faces.size() && f < faces.group.size(); ++f) {
    const int g = faces.group[f];
    if (g < 0) continue;
    const auto& t = mesh.faces[f];
    const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>(), b = mesh.vertices[t[1]].cast<double>(),
                          c = mesh.vertices[t[2]].cast<double>();
    const double area = 0.5 * (b - a).cross(c - a).norm();
    Sum& S = sum[static_cast<size_t>(g)];
    S.area += area;
    // the triangle's second moment (exact: vertices and centroid with weights 1/12 and 9/12)
    const Eigen::Vector3d m = (a + b + c) / 3;
    S.c += area * m;
    S.cc += area * (0.75 * m * m.transpose() + (a * a.transpose() + b * b.transpose() + c * c.transpose()) / 12.0);
  }
  std::vector<FacePatch> out;
  for (size_t g = 0; g < sum.size(); ++g) {
    const Sum& S = sum[g];
    if (S.area < min_area) continue;
    FacePatch p;
    const Eigen::Vector3d c = S.c / S.area;
    const Eigen::Matrix3d cov = S.cc / S.area - c * c.transpose();
    p.n = faces.groups[g].normal.cast<float>().normalized();
    p.c = c.cast<float>();
    p.area = static_cast<float>(S.area);
    // major axis in the face's plane
    const Eigen::Vector3d n = faces.groups[g].normal.normalized();
    const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - n * n.transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(P * cov * P);
    p.axis = es.eigenvectors().col(2).cast<float>().normalized();
    out.push_back(p);
  }
  return out;
}

std::vector<Hypothesis> planarHypotheses(const SceneData& s, const ModelMatcher::ModelIndex& m, size_t max_faces) {
  std::vector<Hypothesis> out;
  if (!s.plane.found || m.patches.empty()) return out;
  // faces that can hold what was seen, the closest in area first
  std::vector<const FacePatch*> faces;
  for (const auto& f : m.patches)
    if (f.area >= 0.6f * s.plane.area) faces.push_back(&f);
  std::sort(faces.begin(), faces.end(), [&](const FacePatch* a, const FacePatch* b) {
    return std::abs(a->area - s.plane.area) < std::abs(b->area - s.plane.area);
  });
  if (faces.size() > max_faces) faces.resize(max_faces);
  for (const FacePatch* f : faces) {
    // the face's normal onto the scene's, then its major axis onto the scene's
    const Eigen::Quaternionf q0 = Eigen::Quaternionf::FromTwoVectors(f->n, s.plane.n);
    const Vec3 a = q0 * f->axis;
    const Vec3 a_in = (a - a.dot(s.plane.n) * s.plane.n).normalized();
    const float ang0 = std::atan2(a_in.cross(s.plane.axis).dot(s.plane.n), a_in.dot(s.plane.axis));
    for (int k = 0; k < 12; ++k) {
      const Eigen::Matrix3f R = Eigen::AngleAxisf(ang0 + static_cast<float>(k) * static_cast<float>(M_PI) / 6, s.plane.n) *
                                q0.toRotationMatrix();
      Hypothesis h;
      h.T.linear() = R;
      h.T.translation() = s.plane.c - R * f->c;
      out.push_back(h);
    }
  }
  return out;
}

void addRests(ModelMatcher::ModelIndex& m) {
  m.rests.clear();
  m.rest_top.clear();
  m.rest_top_hull.clear();
  // a sphere rests every way (its centre is found directly)
  if (m.info.symmetry.type == Symmetry::Type::kSpherical || !m.fine) return;
  std::vector<Eigen::Vector3d> v;
  v.reserve(m.extremes.size());
  for (const auto& p : m.extremes) v.push_back(p.cast<double>());
  m.rests = stableRests(v, m.centroid);
  for (const RestPose& r : m.rests) {
    // what a camera above the table sees of it: the faces turned up
    const Eigen::Matrix3f R = r.R.cast<float>();
    Eigen::Vector2f c = Eigen::Vector2f::Zero();
    std::vector<Eigen::Vector2d> top;
    for (size_t i = 0; i < m.fine->size(); ++i) {
      if ((R * m.fine->normals[i]).z() < 0.5f) continue;
      top.push_back((R * m.fine->points[i]).head<2>().cast<double>());
      c += top.back().cast<float>();
    }
    m.rest_top.push_back(!top.empty() ? Eigen::Vector2f(c / static_cast<float>(top.size())) : Eigen::Vector2f::Zero());
    std::vector<Eigen::Vector2f> hull;
    for (const auto& v : convexHull2d(std::move(top))) hull.push_back(v.cast<float>());
    m.rest_top_hull.push_back(std::move(hull));
  }
}

namespace {

/// Poses of the model lying in each of its stable rests on the support (normal: up), turned about
/// the normal in rest_yaw_step steps, the centroid of its upward faces on the cluster's, each brought
/// in by a short ICP. Where the cluster ends along one of its principal axes at the edge of what
/// the sheet reached (the fan's edge, the sweep's end: a tall part's top near the workspace's
/// end) and spans less than kPartialView of those faces' width along it, the faces are also laid
/// with their other end on the cluster's other end: centred, a partly lit face is centimetres
/// off, and a short ICP on a flat face does not slide it back. Where the cluster reaches farther
/// along its major axis than rest_end_ratio times those faces (parts touching in one cluster,
/// whose centre lies between them), the faces are also laid with each end on the cluster's end.
std::vector<Hypothesis> restHypotheses(const SceneData& s, const ModelMatcher::ModelIndex& m, const MatchingConfig& cfg,
                                       const Eigen::Vector4f& support) {
  std::vector<Hypothesis> out;
  const Vec3 n = support.head<3>().normalized();
  if (m.rests.empty() || !n.allFinite() || s.coarse.points.empty()) return out;
  Vec3 centre = Vec3::Zero();
  size_t k = 0;
  for (const auto& p : s.coarse.points) {
    if (!p.allFinite()) continue;
    centre += p;
    ++k;
  }
  if (k == 0) return out;
  centre /= static_cast<float>(k);
  // the table's frame: x, y in its plane, z its normal; origin: the cluster's centre on the plane
  Eigen::Matrix3f Q;
  Q.col(2) = n;
  Q.col(0) = (std::abs(n.x()) < 0.9f ? Vec3::UnitX() : Vec3::UnitY()).cross(n).normalized();
  Q.col(1) = n.cross(Q.col(0));
  const Vec3 origin = centre - (n.dot(centre) + support.w() / support.head<3>().norm()) * n;
  // the cluster in the table's frame: its principal axes, how far it reaches each way along
  // them, its mean height
  std::vector<Eigen::Vector2f> flat;
  Eigen::Matrix2f cov = Eigen::Matrix2f::Zero();
  float height = 0;
  for (const auto& p : s.coarse.points) {
    if (!p.allFinite()) continue;
    const Vec3 local = Q.transpose() * (p - origin);
    flat.push_back(local.head<2>());
    cov += flat.back() * flat.back().transpose();
    height += local.z() / static_cast<float>(k);
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2f> es(cov);
  std::array<Eigen::Vector2f, 2> axes{es.eigenvectors().col(0), es.eigenvectors().col(1)};
  auto reach = [](const std::vector<Eigen::Vector2f>& pts, const Eigen::Vector2f& u) {
    float hi = -std::numeric_limits<float>::infinity();
    for (const auto& p : pts) hi = std::max(hi, u.dot(p));
    return hi;
  };
  std::array<float, 2> c_hi{}, c_lo{};
  // whether the sheet reached a little beyond the cluster's end at u·p = end (table frame)
  auto litBeyond = [&](const Eigen::Vector2f& u, float end) {
    const Eigen::Vector2f q = (end + kBeyondEnd) * u;
    Vec3 emitter;
    float margin = 0;
    return s.light->emitterFor(origin + Q * Vec3(q.x(), q.y(), height), &emitter, &margin) && margin >= kFanEdgeMargin;
  };
  std::array<bool, 2> cut_hi{}, cut_lo{};
  for (size_t a = 0; a < 2; ++a) {
    c_hi[a] = reach(flat, axes[a]);
    c_lo[a] = -reach(flat, -axes[a]);
    if (s.light && !s.light->empty()) {
      cut_hi[a] = !litBeyond(axes[a], c_hi[a]);
      cut_lo[a] = !litBeyond(-axes[a], -c_lo[a]);
    }
  }
  const int steps = std::max(1, static_cast<int>(std::lround(2 * M_PI / cfg.rest_yaw_step)));
  MatchingConfig short_icp = cfg;  // a turn half a step off comes in within a few iterations
  short_icp.icp_iterations = std::min(cfg.icp_iterations, kRestIcpIterations);
  for (size_t r = 0; r < m.rests.size(); ++r) {
    const Eigen::Matrix3f Rr = m.rests[r].R.cast<float>();
    // a part turned about its own axis of revolution, standing upright, is the same pose: one
    // turn (else the quota fills with copies of one place)
    const bool revolves = m.info.symmetry.type == Symmetry::Type::kAxial &&
                          std::abs((Rr * m.info.symmetry.axis.cast<float>().normalized()).z()) > 0.999f;
    for (int i = 0; i < (revolves ? 1 : steps); ++i) {
      const Eigen::Matrix3f Rz = Eigen::AngleAxisf(static_cast<float>(2 * M_PI * i / steps), Vec3::UnitZ()).toRotationMatrix();
      const Eigen::Matrix2f Rz2 = Rz.topLeftCorner<2, 2>();
      const Eigen::Vector2f top = Rz2 * m.rest_top[r];
      // the upward faces' outline as placed (top centroid on the cluster's centre)
      std::vector<Eigen::Vector2f> outline;
      if (r < m.rest_top_hull.size())
        for (const auto& v : m.rest_top_hull[r]) outline.push_back(Rz2 * v - top);
      std::vector<Eigen::Vector2f> shifts{Eigen::Vector2f::Zero()};
      for (size_t a = 0; a < 2 && !outline.empty(); ++a) {
        const float m_hi = reach(outline, axes[a]), m_lo = -reach(outline, -axes[a]);
        // the faces' low or high end along the axis on the cluster's
        auto endOn = [&](bool low) { return Eigen::Vector2f((low ? c_lo[a] - m_lo : c_hi[a] - m_hi) * axes[a]); };
        // axes[1]: the major axis (the solver's eigenvalues ascend); a cluster longer than the
        // part along it may hold it at either end (touching parts)
        if (a == 1 && cfg.rest_end_ratio > 0 && c_hi[a] - c_lo[a] > cfg.rest_end_ratio * (m_hi - m_lo)) {
          shifts.push_back(endOn(true));
          shifts.push_back(endOn(false));
          continue;
        }
        if (cut_hi[a] == cut_lo[a] || c_hi[a] - c_lo[a] >= kPartialView * (m_hi - m_lo)) continue;
        // the end the sheet did reach past is the part's own
        shifts.push_back(endOn(cut_hi[a]));
      }
      for (const Eigen::Vector2f& d : shifts) {
        Hypothesis h;
        h.T.linear() = Q * Rz * Rr;
        h.T.translation() = origin + Q * Vec3(d.x() - top.x(), d.y() - top.y(), static_cast<float>(m.rests[r].height));
        const Refined f = icp(s, m, h.T, short_icp, kPlanarIcpPoints, false);
        if (!f.T.matrix().allFinite()) continue;
        h.T = f.T;
        out.push_back(h);
      }
    }
  }
  return out;
}

}  // namespace

/// PPF candidates → best `refine_candidates` distinct poses by their distance-field score.
std::vector<Hypothesis> ppfHypotheses(const SceneData& s, const ModelMatcher::ModelIndex& m, const MatchingConfig& cfg,
                                      const Eigen::Vector4f* support, int* iterations) {
  std::vector<Hypothesis> votes = ppfVoting(s.ppf, m, cfg.ppf_ref_step);
  *iterations = static_cast<int>(votes.size());
  std::sort(votes.begin(), votes.end(), [](const Hypothesis& a, const Hypothesis& b) { return a.score > b.score; });
  if (votes.size() > static_cast<size_t>(cfg.ppf_candidates)) votes.resize(cfg.ppf_candidates);
  // a cluster that is mostly one flat patch: its pairs' features were left out of the table (flat-face
  // buckets); its faces are laid onto the patch instead, ranked with the votes
  for (Hypothesis h : planarHypotheses(s, m, 6)) {
    // laid centroid on centroid, a face is a few millimetres off when the view holds only part
    // of it, and then explains far fewer points than a wrong face that happens to be centred (a
    // bracket on its side: 5 mm strips); a short ICP on a few points brings it in first
    const Refined r = icp(s, m, h.T, cfg, kPlanarIcpPoints, false);
    if (r.T.matrix().allFinite()) h.T = r.T;
    votes.push_back(h);
  }
  // scene points in a random (fixed) order: a pose whose first `probe` points explain less
  // than half the best pose's share so far stops there (its score extrapolated)
  std::vector<int> order(s.coarse.size());
  std::iota(order.begin(), order.end(), 0);
  std::mt19937_64 rng(cfg.seed);
  std::shuffle(order.begin(), order.end(), rng);
  // the ranking needs the share of points explained, not every point: a quarter of them, at
  // least 300 (±3 % of the share; the screening ICP then ranks the few kept on all points)
  order.resize(std::min(order.size(), std::max<size_t>(300, order.size() / 4)));
  const int probe = std::min<int>(64, static_cast<int>(order.size()));
  int best_score = 0;
  const float inl2 = static_cast<float>(cfg.inlier_distance * cfg.inlier_distance);
  std::vector<Hypothesis> top;
  const size_t keep = static_cast<size_t>(std::max(1, cfg.refine_candidates));
  // a coarse pose may be a few millimetres off: only clearly sunken or floating ones are dropped here
  const float slack = static_cast<float>(2 * cfg.inlier_distance);
  // scored on the distance field; false for a pose clearly off the support
  auto score = [&](Hypothesis& v) {
    if (support && offSupport(m, v.T, *support, cfg, slack)) return false;
    v.score = scoreHypothesis(s, order, m, v.T, inl2, std::cos(0.8f), probe, 0.5 * best_score / static_cast<double>(order.size()));
    best_score = std::max(best_score, v.score);
    return true;
  };
  const float dt = static_cast<float>(2 * cfg.inlier_distance);
  // a pose near one already listed replaces it if it scores higher; a distinct one is added
  auto merge = [&](std::vector<Hypothesis>& list, const Hypothesis& v) {
    auto same = std::find_if(list.begin(), list.end(), [&](const Hypothesis& h) { return !distinct(h.T, v.T, dt); });
    if (same == list.end()) {
      list.push_back(v);
    } else if (v.score > same->score) {
      *same = v;
    }
  };
  for (auto& v : votes)
    if (score(v)) merge(top, v);
  std::sort(top.begin(), top.end(), [](const Hypothesis& a, const Hypothesis& b) { return a.score > b.score; });
  // near-ties past the cut are kept too (a flat face explains nearly every point in many poses)
  size_t n = std::min(keep, top.size());
  while (cfg.refine_candidates_near > 0 && n < top.size() && n < 2 * keep &&
         top[n].score >= cfg.refine_candidates_near * top[0].score)
    ++n;
  top.resize(n);
  if (support && cfg.rest_candidates > 0) {
    // the part lying on the support: a separate quota, so that no PPF candidate gives way
    std::vector<Hypothesis> rest;
    for (auto& v : restHypotheses(s, m, cfg, *support)) {
      if (!score(v)) continue;
      // PPF refines that pose already
      if (std::any_of(top.begin(), top.end(), [&](const Hypothesis& h) { return !distinct(h.T, v.T, dt); })) continue;
      merge(rest, v);
    }
    std::sort(rest.begin(), rest.end(), [](const Hypothesis& a, const Hypothesis& b) { return a.score > b.score; });
    if (rest.size() > static_cast<size_t>(cfg.rest_candidates)) rest.resize(cfg.rest_candidates);
    top.insert(top.end(), rest.begin(), rest.end());
  }
  return top;
}

}  // namespace cellsight::matching_detail
