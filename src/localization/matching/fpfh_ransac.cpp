// Coarse stage "ransac" (the thesis's method): FPFH (or learned) descriptor correspondences and
// RANSAC on 3-point hypotheses with cheap pre-rejection.
#include <numeric>
#include <random>

#include "matching_internal.hpp"

namespace cellsight::matching_detail {

std::vector<Correspondence> correspondences(const SceneData& s, const ModelMatcher::ModelIndex& m,
                                            const MatchingConfig& cfg) {
  std::vector<Correspondence> one_way, mutual;
  if (s.fpfh_valid.empty() || m.fpfh_valid.empty()) return one_way;
  pcl::FPFHSignature33 q;
  std::vector<int> idx(1);
  std::vector<float> d2(1);
  if (cfg.ransac_sampling == "guided") {
    // every scene point's nearest model descriptors, one way
    const int k = std::min<int>(cfg.ransac_neighbours, static_cast<int>(m.fpfh_valid.size()));
    for (int si : s.fpfh_valid) {
      std::copy(s.fpfh[si].begin(), s.fpfh[si].end(), q.histogram);
      const int found = m.fpfh_tree.nearestKSearch(q, k, idx, d2);
      for (int j = 0; j < found; ++j) one_way.push_back({si, m.fpfh_valid[idx[j]]});
    }
    return one_way;
  }
  for (int si : s.fpfh_valid) {
    std::copy(s.fpfh[si].begin(), s.fpfh[si].end(), q.histogram);
    if (m.fpfh_tree.nearestKSearch(q, 1, idx, d2) < 1) continue;
    const int mi = m.fpfh_valid[idx[0]];
    one_way.push_back({si, mi});
    if (!cfg.mutual_filter) continue;
    std::copy(m.fpfh[mi].begin(), m.fpfh[mi].end(), q.histogram);
    if (s.fpfh_tree.nearestKSearch(q, 1, idx, d2) == 1 && s.fpfh_valid[idx[0]] == si) mutual.push_back({si, mi});
  }
  if (cfg.mutual_filter && static_cast<int>(mutual.size()) >= cfg.min_correspondences) return mutual;
  return one_way;
}

std::vector<Correspondence> learnedCorrespondences(const SceneData& s, const ModelMatcher::ModelIndex& m, size_t turn,
                                                   const MatchingConfig& cfg) {
  std::vector<Correspondence> out;
  if (turn >= m.learned.size() || s.learned.rows() == 0) return out;
  const auto pairs = cfg.ransac_sampling == "guided"
                         ? nearestDescriptors(s.learned, m.learned[turn], cfg.ransac_neighbours)
                         : matchDescriptors(s.learned, m.learned[turn], cfg.mutual_filter, cfg.min_correspondences);
  for (const auto& [si, mi] : pairs) out.push_back({si, mi});
  return out;
}

namespace {

Eigen::Isometry3f kabsch(const Eigen::Matrix3f& model_pts, const Eigen::Matrix3f& scene_pts) {
  Eigen::Isometry3f T = Eigen::Isometry3f::Identity();
  T.matrix() = Eigen::umeyama(model_pts, scene_pts, false);
  return T;
}
}  // namespace

std::vector<Hypothesis> ransac(const SceneData& s, const ModelMatcher::ModelIndex& m,
                               const std::vector<Correspondence>& corr, const MatchingConfig& cfg, uint64_t seed,
                               int* iterations) {
  std::vector<Hypothesis> top;
  *iterations = 0;
  const int n = static_cast<int>(corr.size());
  if (n < 3) return top;
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> pick(0, n - 1);
  std::vector<int> order(s.coarse.size());
  std::iota(order.begin(), order.end(), 0);
  std::shuffle(order.begin(), order.end(), rng);
  const float inl2 = static_cast<float>(cfg.inlier_distance * cfg.inlier_distance);
  const float cos_n = std::cos(0.8f);
  const float cos_tol = std::cos(static_cast<float>(cfg.normal_tolerance));
  const float min_edge = static_cast<float>(2 * cfg.voxel);
  const float sim = static_cast<float>(cfg.edge_similarity);
  const int probe = std::min<int>(64, static_cast<int>(order.size()));
  const auto& sp = s.coarse.points;
  const auto& sn = s.coarse.normals;
  const auto& mp = m.coarse->points;
  const auto& mn = m.coarse->normals;
  long needed = cfg.max_iterations;
  const size_t keep = static_cast<size_t>(std::max(1, cfg.refine_candidates));
  // two matches agree when a rigid motion can take one pair onto the other: the edge is long
  // enough and as long in scene and model, and the cosines of the normals' angles differ by at
  // most 1 - cos(normal_tolerance)
  const bool guided = cfg.ransac_sampling == "guided";
  auto agree = [&](const Correspondence& A, const Correspondence& B) {
    const float ds = (sp[A.scene] - sp[B.scene]).norm(), dm = (mp[A.model] - mp[B.model]).norm();
    if (ds < min_edge || std::min(ds, dm) < sim * std::max(ds, dm)) return false;
    // the angle between the two normals is invariant under a rigid motion
    return !(std::abs(sn[A.scene].dot(sn[B.scene]) - mn[A.model].dot(mn[B.model])) > 1 - cos_tol);
  };
  // guided: a drawn match, then triplets from the matches that agree with it
  constexpr int kTripletsPerSeed = 20;
  std::vector<int> agreeing;
  int seed_match = -1, seed_left = 0;
  for (long it = 0; it < std::min<long>(needed, cfg.max_iterations); ++it) {
    ++*iterations;
    int c[3];
    if (guided) {
      if (seed_left == 0) {
        seed_match = pick(rng);
        seed_left = kTripletsPerSeed;
        agreeing.clear();
        for (int j = 0; j < n; ++j)
          if (corr[j].scene != corr[seed_match].scene && agree(corr[seed_match], corr[j])) agreeing.push_back(j);
      }
      --seed_left;
      if (agreeing.size() < 2) {
        seed_left = 0;
        continue;
      }
      std::uniform_int_distribution<size_t> among(0, agreeing.size() - 1);
      c[0] = seed_match;
      c[1] = agreeing[among(rng)];
      c[2] = agreeing[among(rng)];
    } else {
      c[0] = pick(rng), c[1] = pick(rng), c[2] = pick(rng);
    }
    if (c[0] == c[1] || c[0] == c[2] || c[1] == c[2]) continue;
    bool ok = true;
    for (int a = 0; a < 3 && ok; ++a) ok = agree(corr[c[a]], corr[c[(a + 1) % 3]]);
    if (!ok) continue;
    Eigen::Matrix3f M, S;
    for (int a = 0; a < 3; ++a) {
      M.col(a) = mp[corr[c[a]].model];
      S.col(a) = sp[corr[c[a]].scene];
    }
    const Eigen::Isometry3f T = kabsch(M, S);
    for (int a = 0; a < 3 && ok; ++a) {
      if ((T.linear() * mn[corr[c[a]].model]).dot(sn[corr[c[a]].scene]) < cos_tol) ok = false;
    }
    if (!ok) continue;
    const double floor_share = top.empty() ? 0.0 : 0.5 * top.back().score / static_cast<double>(order.size());
    const int score = scoreHypothesis(s, order, m, T, inl2, cos_n, probe, floor_share);
    if (top.size() == keep && score <= top.back().score) continue;
    // keep the best `keep` mutually distinct hypotheses, best first
    bool merged = false;
    for (auto& h : top) {
      if (!distinct(h.T, T, static_cast<float>(2 * cfg.inlier_distance))) {
        if (score > h.score) h = {T, score};
        merged = true;
        break;
      }
    }
    if (!merged) top.push_back({T, score});
    std::sort(top.begin(), top.end(), [](const Hypothesis& a, const Hypothesis& b) { return a.score > b.score; });
    if (top.size() > keep) top.resize(keep);
    if (top.front().T.matrix() == T.matrix()) {
      // adaptive termination from the share of descriptor matches this pose agrees with (it
      // assumes three independent draws: guided sampling, whose draws depend, mostly runs to
      // max_iterations)
      int n_agree = 0;
      for (const auto& cc : corr) n_agree += (T * mp[cc.model] - sp[cc.scene]).squaredNorm() < inl2;
      const double w = std::max(n_agree, 3) / static_cast<double>(n);
      const double p_all = w * w * w;
      if (p_all >= 1.0) needed = it + 1;
      else needed = std::max<long>(it + 1, static_cast<long>(std::ceil(std::log(1 - cfg.confidence) / std::log1p(-p_all))));
    }
  }
  return top;
}

}  // namespace cellsight::matching_detail
