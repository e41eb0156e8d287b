// PCL-heavy translation unit: scene normals and FPFH, descriptor k-d trees, exact nearest
// neighbours for the last ICP iterations and for fitness. The RANSAC scoring and most ICP
// iterations use a distance field of the model (O(1) per point) built once per model.
#include "cellsight/model_matching.hpp"

#include <pcl/features/fpfh.h>
#include <pcl/features/normal_3d.h>
#include <pcl/filters/voxel_grid.h>
#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstdio>
#include <cstdlib>
#include <atomic>
#include <chrono>
#include <cmath>
#include <numeric>
#include <random>
#include <stdexcept>
#include <thread>

#include "cellsight/errors.hpp"
#include "cellsight/fgr.hpp"
#include "cellsight/point_grid.hpp"
#include "cellsight/closest_point_grid.hpp"
#include "cellsight/raycaster.hpp"
#include "cellsight/yaml_reader.hpp"

namespace cellsight {
namespace {

using Clock = std::chrono::steady_clock;
using Vec3 = Eigen::Vector3f;

double seconds(Clock::time_point a) { return std::chrono::duration<double>(Clock::now() - a).count(); }

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

pcl::PointCloud<pcl::PointXYZ>::Ptr toXyz(const std::vector<Vec3>& pts) {
  pcl::PointCloud<pcl::PointXYZ>::Ptr c(new pcl::PointCloud<pcl::PointXYZ>);
  c->resize(pts.size());
  for (size_t i = 0; i < pts.size(); ++i) (*c)[i].getVector3fMap() = pts[i];
  c->width = static_cast<uint32_t>(pts.size());
  c->height = 1;
  return c;
}

pcl::PointCloud<pcl::FPFHSignature33>::Ptr toPclFpfh(const std::vector<Fpfh>& f) {
  pcl::PointCloud<pcl::FPFHSignature33>::Ptr c(new pcl::PointCloud<pcl::FPFHSignature33>);
  c->resize(f.size());
  for (size_t i = 0; i < f.size(); ++i) std::copy(f[i].begin(), f[i].end(), (*c)[i].histogram);
  return c;
}

bool validFpfh(const Fpfh& f) {
  float s = 0;
  for (float v : f) {
    if (!std::isfinite(v)) return false;
    s += v;
  }
  return s > 0;
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


/// Thins a cloud with normals to one point per cell (the first one met).
ScanCloud thinned(const ScanCloud& c, double cell) {
  std::vector<std::pair<std::tuple<int, int, int>, int>> keys;
  keys.reserve(c.size());
  for (size_t i = 0; i < c.size(); ++i) {
    const Vec3 g = c.points[i] / static_cast<float>(cell);
    keys.push_back({{static_cast<int>(std::floor(g.x())), static_cast<int>(std::floor(g.y())), static_cast<int>(std::floor(g.z()))},
                    static_cast<int>(i)});
  }
  std::stable_sort(keys.begin(), keys.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  ScanCloud out;
  out.frame_id = c.frame_id;
  for (size_t k = 0; k < keys.size(); ++k) {
    if (k > 0 && keys[k].first == keys[k - 1].first) continue;
    out.append(c.points[keys[k].second], 0.f);
    out.normals.push_back(c.normals[keys[k].second]);
  }
  return out;
}

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

}  // namespace

struct ModelMatcher::ModelIndex {
  std::string id;
  ModelInfo info;
  std::shared_ptr<const ScanCloud> coarse;  // at config.voxel, PCA normals (as a scan sees them)
  std::vector<Fpfh> fpfh;                   // of coarse (invalid ones zeroed)
  pcl::KdTreeFLANN<pcl::FPFHSignature33> fpfh_tree;
  std::vector<int> fpfh_valid;              // coarse indices with a valid descriptor
  std::shared_ptr<const ScanCloud> fine;    // at config.icp_spacing
  pcl::KdTreeFLANN<pcl::PointXYZ> fine_tree;
  DistanceField field;
  ScanCloud ppf_cloud;  // coarse cloud thinned to ppf_sampling
  PpfTable ppf;         // its point pair features (Drost et al. 2010)
  RayCaster caster;  // the mesh in the model frame (self-occlusion)
  ClosestPointGrid closest;  // candidate triangles per cell for the polish (empty: Embree only)
  PlanarFaces faces;         // flat faces and their creases (slack centring)
  bool has_mesh = true;  // false for a cloud model: visibility from the normals only
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  float diameter = 0;
  std::vector<Vec3> extremes;  // mesh vertices (cloud models: coarse points), for the support test
};

namespace {

/// One cluster prepared once for every model: coarse points with normals and FPFH, the points
/// ICP uses, and a k-d tree over all its points for the fitness test.
struct SceneData {
  std::vector<Vec3> all;       // finite input points
  ScanCloud coarse;            // voxelised, normals toward the viewpoint
  std::vector<Fpfh> fpfh;
  std::vector<int> fpfh_valid;
  pcl::KdTreeFLANN<pcl::FPFHSignature33> fpfh_tree;
  ScanCloud ppf;               // coarse thinned to ppf_sampling
  std::vector<Vec3> icp_points;
  PointGrid grid;                        // over `all` (scene_search: grid)
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;  // over `all` (scene_search: kdtree)
  float diameter = 0;  // lower bound of the largest point distance
};

std::unique_ptr<SceneData> prepareScene(const std::vector<Vec3>& finite, const MatchingConfig& cfg) {
  auto s = std::make_unique<SceneData>();
  s->all = finite;
  auto all = toXyz(finite);
  pcl::VoxelGrid<pcl::PointXYZ> vg;
  vg.setInputCloud(all);
  const float leaf = static_cast<float>(cfg.voxel);
  vg.setLeafSize(leaf, leaf, leaf);
  pcl::PointCloud<pcl::PointXYZ>::Ptr coarse(new pcl::PointCloud<pcl::PointXYZ>);
  vg.filter(*coarse);
  std::vector<Vec3> normals(coarse->size());
  if (cfg.scene_search == "grid") {
    // one grid serves the normals (radius normal_radius) and the fitness test (r_F)
    s->grid = PointGrid(finite, static_cast<float>(std::max(cfg.normal_radius, cfg.fitness_radius)));
    std::vector<Vec3> q(coarse->size());
    for (size_t i = 0; i < q.size(); ++i) q[i] = (*coarse)[i].getVector3fMap();
    normals = gridNormals(s->grid, q, static_cast<float>(cfg.normal_radius), cfg.viewpoint);
  } else {
    pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
    ne.setInputCloud(coarse);
    ne.setSearchSurface(all);
    ne.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
    ne.setRadiusSearch(cfg.normal_radius);
    ne.setViewPoint(cfg.viewpoint.x(), cfg.viewpoint.y(), cfg.viewpoint.z());
    pcl::PointCloud<pcl::Normal> n;
    ne.compute(n);
    for (size_t i = 0; i < n.size(); ++i) normals[i] = n[i].getNormalVector3fMap();
    s->tree.setInputCloud(all);
  }
  pcl::PointCloud<pcl::PointXYZ>::Ptr kept(new pcl::PointCloud<pcl::PointXYZ>);
  pcl::PointCloud<pcl::Normal>::Ptr kept_n(new pcl::PointCloud<pcl::Normal>);
  for (size_t i = 0; i < coarse->size(); ++i) {
    if (!normals[i].allFinite()) continue;
    kept->push_back((*coarse)[i]);
    pcl::Normal n;
    n.getNormalVector3fMap() = normals[i];
    kept_n->push_back(n);
    s->coarse.append((*coarse)[i].getVector3fMap(), 0.f);
    s->coarse.normals.push_back(normals[i].normalized());
  }
  if (kept->empty()) return s;
  s->ppf = thinned(s->coarse, cfg.ppf_sampling);
  const size_t cap = static_cast<size_t>(std::max(100.0, cfg.icp_max_points));
  const size_t step = std::max<size_t>(1, (finite.size() + cap - 1) / cap);
  for (size_t i = 0; i < finite.size(); i += step) s->icp_points.push_back(finite[i]);
  // a lower bound of the largest distance between two points (two farthest-point sweeps)
  auto farthest = [&](const Vec3& from) {
    size_t best = 0;
    float d = -1;
    for (size_t i = 0; i < s->coarse.size(); ++i) {
      const float di = (s->coarse.points[i] - from).squaredNorm();
      if (di > d) {
        d = di;
        best = i;
      }
    }
    return s->coarse.points[best];
  };
  const Vec3 b = farthest(s->coarse.points[0]), c = farthest(b);
  s->diameter = (b - c).norm();
  if (cfg.coarse == "ppf") return s;
  pcl::FPFHEstimation<pcl::PointXYZ, pcl::Normal, pcl::FPFHSignature33> fe;
  fe.setInputCloud(kept);
  fe.setInputNormals(kept_n);
  fe.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
  fe.setRadiusSearch(cfg.feature_radius);
  pcl::PointCloud<pcl::FPFHSignature33> f;
  fe.compute(f);
  s->fpfh.resize(f.size());
  std::vector<Fpfh> valid;
  for (size_t i = 0; i < f.size(); ++i) {
    std::copy(f[i].histogram, f[i].histogram + 33, s->fpfh[i].begin());
    if (validFpfh(s->fpfh[i])) {
      s->fpfh_valid.push_back(static_cast<int>(i));
      valid.push_back(s->fpfh[i]);
    }
  }
  if (!valid.empty()) s->fpfh_tree.setInputCloud(toPclFpfh(valid));
  return s;
}

/// At most `cap` points: a voxel grid of `leaf` (cell centroids), then every k-th point.
std::vector<Vec3> capPoints(const std::vector<Vec3>& pts, double leaf, size_t cap) {
  pcl::VoxelGrid<pcl::PointXYZ> vg;
  vg.setInputCloud(toXyz(pts));
  const float l = static_cast<float>(leaf);
  vg.setLeafSize(l, l, l);
  pcl::PointCloud<pcl::PointXYZ> v;
  vg.filter(v);
  const size_t step = (v.size() + cap - 1) / cap;
  std::vector<Vec3> out;
  out.reserve(cap);
  for (size_t i = 0; i < v.size(); i += std::max<size_t>(1, step)) out.push_back(v[i].getVector3fMap());
  return out;
}

struct Correspondence {
  int scene, model;
};

std::vector<Correspondence> correspondences(const SceneData& s, const ModelMatcher::ModelIndex& m,
                                            const MatchingConfig& cfg) {
  std::vector<Correspondence> one_way, mutual;
  if (s.fpfh_valid.empty() || m.fpfh_valid.empty()) return one_way;
  pcl::FPFHSignature33 q;
  std::vector<int> idx(1);
  std::vector<float> d2(1);
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

struct Hypothesis {
  Eigen::Isometry3f T = Eigen::Isometry3f::Identity();  // model → scene
  int score = 0;
};

/// Counts scene points explained by the model under T (model → scene), with early exit when
/// the first `probe` points already promise less than `floor`.
int scoreHypothesis(const SceneData& s, const std::vector<int>& order, const ModelMatcher::ModelIndex& m,
                    const Eigen::Isometry3f& T, float inlier2, float cos_normal, int probe, double floor_share) {
  const Eigen::Isometry3f Ti = T.inverse();
  const Eigen::Matrix3f Rt = Ti.linear();
  const auto& fp = m.fine->points;
  const auto& fn = m.fine->normals;
  int count = 0;
  for (size_t k = 0; k < order.size(); ++k) {
    if (static_cast<int>(k) == probe && count < floor_share * probe) return count * static_cast<int>(order.size()) / probe;
    const int i = order[k];
    const Vec3 q = Ti * s.coarse.points[i];
    const int j = m.field.lookup(q);
    if (j < 0) continue;
    if ((q - fp[j]).squaredNorm() > inlier2) continue;
    if ((Rt * s.coarse.normals[i]).dot(fn[j]) < cos_normal) continue;
    ++count;
  }
  return count;
}

Eigen::Isometry3f kabsch(const Eigen::Matrix3f& model_pts, const Eigen::Matrix3f& scene_pts) {
  Eigen::Isometry3f T = Eigen::Isometry3f::Identity();
  T.matrix() = Eigen::umeyama(model_pts, scene_pts, false);
  return T;
}

bool distinct(const Eigen::Isometry3f& a, const Eigen::Isometry3f& b, float dt) {
  if ((a.translation() - b.translation()).norm() > dt) return true;
  const Eigen::AngleAxisf d(a.linear().transpose() * b.linear());
  return std::abs(d.angle()) > 0.2f;
}

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
  for (long it = 0; it < std::min<long>(needed, cfg.max_iterations); ++it) {
    ++*iterations;
    int c[3] = {pick(rng), pick(rng), pick(rng)};
    if (c[0] == c[1] || c[0] == c[2] || c[1] == c[2]) continue;
    bool ok = true;
    for (int a = 0; a < 3 && ok; ++a) {
      const int b = (a + 1) % 3;
      const Correspondence &A = corr[c[a]], &B = corr[c[b]];
      const float ds = (sp[A.scene] - sp[B.scene]).norm(), dm = (mp[A.model] - mp[B.model]).norm();
      if (ds < min_edge || std::min(ds, dm) < sim * std::max(ds, dm)) ok = false;
      // the angle between the two normals is invariant under a rigid motion
      else if (std::abs(sn[A.scene].dot(sn[B.scene]) - mn[A.model].dot(mn[B.model])) > 1 - cos_tol) ok = false;
    }
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
      // adaptive termination from the share of descriptor matches this pose agrees with
      int agree = 0;
      for (const auto& cc : corr) agree += (T * mp[cc.model] - sp[cc.scene]).squaredNorm() < inl2;
      const double w = std::max(agree, 3) / static_cast<double>(n);
      const double p_all = w * w * w;
      if (p_all >= 1.0) needed = it + 1;
      else needed = std::max<long>(it + 1, static_cast<long>(std::ceil(std::log(1 - cfg.confidence) / std::log1p(-p_all))));
    }
  }
  return top;
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

/// PPF candidates → best `refine_candidates` distinct poses by their distance-field score.
float belowSupport(const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T, const Eigen::Vector4f& plane);

std::vector<Hypothesis> ppfHypotheses(const SceneData& s, const ModelMatcher::ModelIndex& m, const MatchingConfig& cfg,
                                      const Eigen::Vector4f* support, int* iterations) {
  std::vector<Hypothesis> votes = ppfVoting(s.ppf, m, cfg.ppf_ref_step);
  *iterations = static_cast<int>(votes.size());
  std::sort(votes.begin(), votes.end(), [](const Hypothesis& a, const Hypothesis& b) { return a.score > b.score; });
  if (votes.size() > static_cast<size_t>(cfg.ppf_candidates)) votes.resize(cfg.ppf_candidates);
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
  // a coarse pose may be a few millimetres off: only clearly sunken ones are dropped here
  const float sunk = static_cast<float>(cfg.max_support_penetration + 2 * cfg.inlier_distance);
  for (auto& v : votes) {
    if (support && belowSupport(m, v.T, *support) > sunk) continue;
    v.score = scoreHypothesis(s, order, m, v.T, inl2, std::cos(0.8f), probe, 0.5 * best_score / static_cast<double>(order.size()));
    best_score = std::max(best_score, v.score);
    bool merged = false;
    for (auto& h : top) {
      if (!distinct(h.T, v.T, static_cast<float>(2 * cfg.inlier_distance))) {
        if (v.score > h.score) h = v;
        merged = true;
        break;
      }
    }
    if (!merged) top.push_back(v);
  }
  std::sort(top.begin(), top.end(), [](const Hypothesis& a, const Hypothesis& b) { return a.score > b.score; });
  if (top.size() > keep) top.resize(keep);
  return top;
}

/// The mesh's closest point to q (model frame) within max_d: the candidate grid, else Embree.
ClosestPoint meshClosest(const ModelMatcher::ModelIndex& m, const Eigen::Vector3f& q, float max_d) {
  bool covered = false;
  ClosestPoint c;
  if (!m.closest.empty()) c = m.closest.closestPoint(q, max_d, &covered);
  if (!covered && !(m.closest.margin() >= max_d)) c = m.caster.closestPoint(q, max_d);
  return c;
}

/// One scene point in the ICP's exact polish (model frame).
struct PolishRow {
  Eigen::Vector3d q, n;  // the point; the face normal, or (outside) the direction from its closest point
  double r;              // signed distance along n
  int tri = -1;          // its closest mesh triangle (-1: not from the mesh)
  bool outside = false;  // beyond an edge or corner: closest to it
};

/// Centres the pose in its slack. A part seen from one side is often pinned only by the ends
/// of its scanned faces: a flat top is free in-plane (two translations and the turn about its
/// normal) while its scanned patch stays inside the face, and the patch is smaller than the face
/// by what the scanner loses at edges (segment ends, the last line before an edge). ICP stops
/// where the first scan points reach an edge: one end of the slack. Here each direction the
/// points over faces constrain weakly (eigenvalues of their point-to-plane normal matrix below
/// icp_slack_eigen_ratio of the largest) is followed both ways to where the k-th point leaves
/// the surface (it moves off its face's plane by icp_slack_tolerance, or past one of the face's
/// creases: PlanarFaces), and the pose moves to the middle: the centre of the poses the scan
/// allows, exact when the scanner loses as much at opposite edges. Motions are linearised at the
/// polished pose (sub-millimetre and sub-degree). A direction bounded on one side or none (a
/// turn about an axis of symmetry) is left alone. Rotates the rows with the pose; returns the
/// change (model frame, applied after X).
Eigen::Isometry3d centreInSlack(const ModelMatcher::ModelIndex& m, std::vector<PolishRow>& rows, bool fresh,
                                const MatchingConfig& cfg) {
  Eigen::Isometry3d total = Eigen::Isometry3d::Identity();
  if (rows.size() < 20 || m.faces.groups.empty()) return total;
  const double L = std::max(0.5 * static_cast<double>(m.diameter), 1e-3);
  const double tol = cfg.icp_slack_tolerance;
  // rows measured before a last step that was not negligible: measure again at the final pose
  const float cap = static_cast<float>(std::max(2 * tol + 3 * cfg.icp_huber_floor, 0.001));
  for (auto& r : rows) {
    if (fresh) break;
    const ClosestPoint c = meshClosest(m, r.q.cast<float>(), cap);
    if (!c.found) {
      r.tri = -1;
      continue;
    }
    const Eigen::Vector3d dv = r.q - c.point.cast<double>(), nf = c.normal.cast<double>();
    const double d = dv.norm();
    r.tri = c.triangle;
    r.outside = !(d < 1e-9 || std::abs(nf.dot(dv)) >= 0.999 * d);
    r.n = r.outside ? Eigen::Vector3d(dv / d) : nf;
    r.r = r.outside ? d : nf.dot(dv);
  }
  Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
  std::vector<double> crease(rows.size());
  for (size_t i = 0; i < rows.size(); ++i) {
    const PolishRow& r = rows[i];
    if (r.tri < 0) continue;
    crease[i] = r.outside ? 0.0 : m.faces.creaseDistance(r.tri, r.q);
    if (r.outside) continue;
    Eigen::Matrix<double, 6, 1> J;
    J << r.q.cross(r.n) / L, r.n;
    A += J * J.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eig(A);
  const double top = eig.eigenvalues().maxCoeff();
  if (!(top > 0)) return total;
  const size_t k = std::max<size_t>(2, rows.size() / 500);  // the k-th point leaving ends the slack
  for (int pass = 0; pass < 2; ++pass) {
    for (int e = 0; e < 6; ++e) {
      if (eig.eigenvalues()[e] > cfg.icp_slack_eigen_ratio * top) continue;
      const Eigen::Vector3d w = eig.eigenvectors().col(e).head<3>() / L, t = eig.eigenvectors().col(e).tail<3>();
      // a turn about an axis of symmetry (a sphere: any turn about its centre) moves nothing
      if (m.info.symmetry.type == Symmetry::Type::kSpherical && (w.cross(m.centroid) + t).norm() < 0.5 * w.norm() * L) continue;
      if (m.info.symmetry.type == Symmetry::Type::kAxial &&
          std::abs(w.dot(m.info.symmetry.axis.normalized())) * L > 0.9 * eig.eigenvectors().col(e).norm()) continue;
      // Each way: the motion at which the k-th point leaves. A first-order guess for every point
      // (off its face's plane, or across one of the face's creases) brackets it; the exact
      // closest point then decides, for the points the guess puts inside the bracket (a point
      // near a crease may just pass onto the next face, so guesses are only guesses).
      auto leaves = [&](size_t i, double tx) {
        const PolishRow& r = rows[i];
        const Eigen::Vector3d q = r.q + tx * (w.cross(r.q) + t);
        return !meshClosest(m, q.cast<float>(), static_cast<float>(std::abs(r.r) + tol)).found;
      };
      double end[2] = {0, 0}, first[2] = {0, 0};
      bool bounded = true;
      struct Guess {
        double lb, x;  // x < 0: not computed yet
        size_t i;
        Eigen::Vector3d vt;
      };
      std::vector<Guess> guesses[2];
      auto settle = [&](Guess& g) {
        if (g.x >= 0) return g.x;
        const double off = -g.x - 1;
        g.x = std::min(off, m.faces.creaseExit(rows[g.i].tri, rows[g.i].q, g.vt) + tol / g.vt.norm());
        return g.x;
      };
      for (int side = 0; side < 2 && bounded; ++side) {
        const double sgn = side ? -1.0 : 1.0;
        // lower bounds first (off the plane exactly; a crease no nearer than its distance), then
        // crease exits in order of the bound until the k-th smallest guess is settled
        std::vector<Guess>& guess = guesses[side];
        guess.reserve(rows.size());
        for (size_t i = 0; i < rows.size(); ++i) {
          const PolishRow& r = rows[i];
          if (r.tri < 0) continue;
          const Eigen::Vector3d v = sgn * (w.cross(r.q) + t);
          const double u = r.n.dot(v);
          Guess g{0, 0, i, Eigen::Vector3d::Zero()};
          if (r.outside) {
            g.x = u > 0 ? tol / u : std::numeric_limits<double>::infinity();
            g.lb = g.x;
          } else {
            g.x = u > 0 ? (std::abs(r.r) + tol - r.r) / u
                        : u < 0 ? (std::abs(r.r) + tol + r.r) / -u : std::numeric_limits<double>::infinity();
            g.vt = v - r.n * u;
            const double speed = g.vt.norm();
            g.lb = speed > 0 ? std::min(g.x, crease[i] / speed) : g.x;
            if (g.lb < g.x) g.x = -g.x - 1;  // crease exit still to compute (off-plane: -x - 1)
          }
          guess.push_back(g);
        }
        if (guess.size() < k) {
          bounded = false;
          break;
        }
        std::vector<double> kbest;  // max-heap of the k smallest settled guesses
        for (auto& g : guess) {
          if (kbest.size() == k && g.lb >= kbest.front()) continue;
          const double x = settle(g);
          if (kbest.size() < k) {
            kbest.push_back(x);
            std::push_heap(kbest.begin(), kbest.end());
          } else if (x < kbest.front()) {
            std::pop_heap(kbest.begin(), kbest.end());
            kbest.back() = x;
            std::push_heap(kbest.begin(), kbest.end());
          }
        }
        first[side] = kbest.front();
      }
      for (int side = 0; side < 2 && bounded; ++side) {
        const double sgn = side ? -1.0 : 1.0;
        std::vector<Guess>& guess = guesses[side];
        double hi = std::min(cfg.icp_slack_range, std::max(2 * first[side], 1e-5));
        std::vector<size_t> exits;
        for (;;) {
          exits.clear();
          for (auto& g : guess) {
            if (g.lb > 3 * hi || (g.x >= 0 && g.x > 3 * hi)) continue;  // beyond; unsettled: ask the mesh
            if (leaves(g.i, sgn * hi)) exits.push_back(g.i);
          }
          if (exits.size() >= k || hi >= cfg.icp_slack_range) break;
          hi = std::min(cfg.icp_slack_range, 4 * hi);
        }
        if (exits.size() < k) {
          bounded = false;
          break;
        }
        double lo = 0;  // allowed; hi: not allowed
        for (int it = 0; it < cfg.icp_slack_steps; ++it) {
          const double mid = 0.5 * (lo + hi);
          size_t n = 0;
          for (size_t j = 0; j < exits.size() && n < k; ++j) n += leaves(exits[j], sgn * mid) ? 1 : 0;
          (n < k ? lo : hi) = mid;
        }
        end[side] = lo;
      }
      if (!bounded) continue;
      const double hi = end[0], lo = -end[1];
      const double c = 0.5 * (hi + lo);
      Eigen::Isometry3d D = Eigen::Isometry3d::Identity();
      const Eigen::Vector3d wc = c * w;
      if (wc.norm() > 1e-15) D.linear() = Eigen::AngleAxisd(wc.norm(), wc.normalized()).toRotationMatrix();
      D.translation() = c * t;
      // the next direction starts from here: first-order distances, and crease distances kept
      // as lower bounds (less the point's move)
      for (size_t i = 0; i < rows.size(); ++i) {
        PolishRow& r = rows[i];
        const Eigen::Vector3d q = D * r.q;
        if (!r.outside) r.r += r.n.dot(q - r.q);
        crease[i] = std::max(0.0, crease[i] - (q - r.q).norm());
        r.q = q;
        r.n = D.linear() * r.n;
      }
      total = D * total;
    }
  }
  return total;
}

struct Refined {
  Eigen::Isometry3f T = Eigen::Isometry3f::Identity();
  double rmse = 0;
  std::vector<PolishRow> polished;  // the exact polish's last rows, at T (mesh models)
  bool polished_fresh = false;      // their distances hold at T (the last step was below 1 µm)
};

/// Robust point-to-plane ICP of the scene points onto the model (Huber weights, shrinking
/// correspondence distance); distance-field correspondences, then exact ones.
/// `max_points`: the scene points used (evenly thinned); `polish`: finish with exact neighbours.
Refined icp(const SceneData& s, const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T0,
            const MatchingConfig& cfg, size_t max_points, bool polish) {
  const size_t stride = std::max<size_t>(1, (s.icp_points.size() + max_points - 1) / std::max<size_t>(1, max_points));
  Eigen::Isometry3d X = T0.inverse().cast<double>();  // scene → model
  const auto& fp = m.fine->points;
  const auto& fn = m.fine->normals;
  double dmax = std::max(2 * cfg.inlier_distance, 4 * cfg.icp_spacing);
  const double dmin = std::max(3 * cfg.icp_spacing, 0.5 * cfg.fitness_radius);
  const int exact_iterations = cfg.icp_exact_iterations;
  double rmse = 0;
  int exact_done = 0;
  // eigenvalues below this share of the largest are taken as unconstrained directions
  const double degenerate_ratio = 1e-6;
  std::vector<int> idx(1);
  std::vector<float> d2(1);
  std::vector<double> res;
  Eigen::Matrix<double, 6, 1> prev_step = Eigen::Matrix<double, 6, 1>::Zero();  // scaled
  std::vector<PolishRow> polished;  // the last exact iteration's rows (at the final pose)
  bool polished_fresh = false;      // measured within a converged step of the final pose
  for (int it = 0; it < cfg.icp_iterations + (polish ? exact_iterations : 0); ++it) {
    const bool exact = it >= cfg.icp_iterations || exact_done > 0;
    Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
    using Row = PolishRow;
    std::vector<Row> rows;
    rows.reserve(s.icp_points.size() / stride + 1);
    for (size_t pi = 0; pi < s.icp_points.size(); pi += stride) {
      const Vec3& p = s.icp_points[pi];
      const Eigen::Vector3d q = X * p.cast<double>();
      int j;
      if (exact && m.has_mesh && cfg.icp_mesh_polish) {
        // exact: the closest point of the mesh itself. A scan point beyond a face's edge is
        // pulled back over the edge; against the nearest sample's tangent plane it would not
        // be (the plane runs on past the edge), and a flat part could slide.
        const ClosestPoint c = meshClosest(m, q.cast<float>(), static_cast<float>(dmax));
        if (!c.found) continue;
        const Eigen::Vector3d cp = c.point.cast<double>(), nf = c.normal.cast<double>(), dv = q - cp;
        const double dist = dv.norm();
        if (dist < 1e-9 || std::abs(nf.dot(dv)) >= 0.999 * dist) {
          rows.push_back({q, nf, nf.dot(dv), c.triangle, false});  // over the face: point-to-plane
        } else {
          rows.push_back({q, dv / dist, dist, c.triangle, true});  // beyond an edge or corner: toward it
        }
        continue;
      }
      if (exact) {
        pcl::PointXYZ qq(static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()));
        if (m.fine_tree.nearestKSearch(qq, 1, idx, d2) < 1) continue;
        j = idx[0];
      } else {
        j = m.field.lookup(q.cast<float>());
        if (j < 0) continue;
      }
      const Eigen::Vector3d mp = fp[j].cast<double>(), n = fn[j].cast<double>();
      if ((q - mp).norm() > dmax) continue;
      rows.push_back({q, n, n.dot(q - mp), -1, false});
    }
    if (rows.size() < 6) break;
    // robust scale from the median absolute residual of every k-th row (256–511 rows: it sets
    // the Huber scale and the next correspondence distance, where a few per cent do not matter)
    const size_t every = std::max<size_t>(1, rows.size() / 256);
    res.clear();
    for (size_t i = 0; i < rows.size(); i += every) res.push_back(std::abs(rows[i].r));
    std::nth_element(res.begin(), res.begin() + res.size() / 2, res.end());
    const double sigma = std::max(1.4826 * res[res.size() / 2], 1e-5);
    // Huber scale from the residuals, but not below the floor: with a clean scan sigma is a few
    // hundredths of a millimetre, and a smaller scale would damp the few points on side walls
    // and edges — the only ones that fix a flat part's in-plane position — to a crawl.
    const double huber = std::max(1.5 * sigma, cfg.icp_huber_floor);
    double ss = 0;
    for (const auto& row : rows) {
      const double w = std::abs(row.r) <= huber ? 1.0 : huber / std::abs(row.r);
      Eigen::Matrix<double, 6, 1> J;
      J << row.q.cross(row.n), row.n;
      for (int i = 0; i < 6; ++i) {  // upper triangle only (A is symmetric)
        const double wi = w * J[i];
        for (int j = i; j < 6; ++j) A(i, j) += wi * J[j];
      }
      b -= w * J * row.r;
      ss += row.r * row.r;
    }
    A.triangularView<Eigen::StrictlyLower>() = A.transpose();
    rmse = std::sqrt(ss / rows.size());
    // Degeneracy-aware step: directions the data do not constrain (a U-profile seen from
    // above says nothing along its extrusion; exact face normals make that exactly singular)
    // get no step instead of an arbitrary one. Rotation is scaled by the part's size so that
    // the eigenvalues compare like with like.
    const double L = std::max(0.5 * static_cast<double>(m.diameter), 1e-3);
    Eigen::Matrix<double, 6, 1> scale;
    scale << L, L, L, 1, 1, 1;
    const Eigen::Matrix<double, 6, 6> As = scale.asDiagonal().inverse() * A * scale.asDiagonal().inverse();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eig(As);
    const double floor_ev = degenerate_ratio * eig.eigenvalues().maxCoeff();
    Eigen::Matrix<double, 6, 1> xs = Eigen::Matrix<double, 6, 1>::Zero();
    const Eigen::Matrix<double, 6, 1> bs = scale.asDiagonal().inverse() * b;
    for (int k = 0; k < 6; ++k) {
      const double ev = eig.eigenvalues()[k];
      if (ev > floor_ev && ev > 0) xs += eig.eigenvectors().col(k) * (eig.eigenvectors().col(k).dot(bs) / ev);
    }
    const Eigen::Matrix<double, 6, 1> x = scale.asDiagonal().inverse() * xs;
    if (!x.allFinite()) break;
    Eigen::Isometry3d D = Eigen::Isometry3d::Identity();
    const double angle = x.head<3>().norm();
    if (angle > 1e-12) D.linear() = Eigen::AngleAxisd(angle, x.head<3>() / angle).toRotationMatrix();
    D.translation() = x.tail<3>();
    X = D * X;
    if (exact && m.has_mesh && cfg.icp_mesh_polish) {
      polished = std::move(rows);
      for (auto& row : polished) row.q = D * row.q;
    }
    dmax = std::max(dmin, std::min(dmax, 4 * sigma + cfg.icp_spacing));
    // converged: the field's correspondences are good to its cell, so stop them at 10 µm steps;
    // the exact polish stops at 1 µm
    const double tol = exact ? 1e-6 : 1e-5;
    // a turn about an axis of symmetry (or any turn of a sphere about its centre) changes
    // nothing: it does not count as motion
    Eigen::Vector3d w = x.head<3>(), v = x.tail<3>();
    if (m.info.symmetry.type == Symmetry::Type::kAxial) {
      const Eigen::Vector3d a = m.info.symmetry.axis.normalized();
      w -= a * a.dot(w);
    } else if (m.info.symmetry.type == Symmetry::Type::kSpherical) {
      v += w.cross(m.centroid);
      w.setZero();
    }
    // on the field, a step that turns back on the previous one is its quantisation (nearest
    // sample per cell) bouncing the pose around the minimum: converged as far as it can tell
    const bool bounced = !exact && it > 0 && xs.dot(prev_step) < 0;
    prev_step = xs;
    const bool small = (w.norm() < 10 * tol && v.norm() < tol) || bounced;
    if (exact) {
      polished_fresh = small;
      if (++exact_done >= exact_iterations || small) break;
    } else if (small) {
      if (!polish) break;
      exact_done = 1;  // converged on the field: polish with exact neighbours
    }
  }
  Refined r;
  r.T = X.inverse().cast<float>();
  r.rmse = rmse;
  r.polished = std::move(polished);
  r.polished_fresh = polished_fresh;
  return r;
}

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

/// Share of the model's points visible from the viewpoint (facing it, not hidden by the part
/// itself) that have a scene point within r_F.
double visibleFitness(const SceneData& s, const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T,
                      const MatchingConfig& cfg) {
  const Eigen::Isometry3f Ti = T.inverse();
  const Vec3 eye = Ti * cfg.viewpoint;
  const float cos_max = std::cos(static_cast<float>(cfg.max_view_angle));
  const float r2 = static_cast<float>(cfg.fitness_radius * cfg.fitness_radius);
  std::vector<int> idx(1);
  std::vector<float> d2(1);
  size_t visible = 0, matched = 0;
  const auto& mp = m.coarse->points;
  const auto& mn = m.coarse->normals;
  for (size_t i = 0; i < mp.size(); ++i) {
    if (cfg.check_visibility) {
      const Vec3 ray = mp[i] - eye;
      const float dist = ray.norm();
      if (dist <= 0) continue;
      const Vec3 dir = ray / dist;
      if (-mn[i].dot(dir) < cos_max) continue;
      if (m.has_mesh && m.caster.occluded(eye, dir, 0.f, dist - static_cast<float>(std::max(0.0005, 0.5 * cfg.voxel)))) continue;
    }
    ++visible;
    const Vec3 p = T * mp[i];
    if (cfg.scene_search == "grid") {
      matched += s.grid.anyWithin(p, static_cast<float>(cfg.fitness_radius));
    } else if (s.tree.nearestKSearch(pcl::PointXYZ(p.x(), p.y(), p.z()), 1, idx, d2) == 1 && d2[0] <= r2) {
      ++matched;
    }
  }
  return visible ? static_cast<double>(matched) / visible : 0.0;
}

/// How far the model under T reaches below the support plane (m; <= 0: not at all).
float belowSupport(const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T, const Eigen::Vector4f& plane) {
  float lowest = std::numeric_limits<float>::infinity();
  for (const auto& v : m.extremes) lowest = std::min(lowest, plane.head<3>().dot(T * v) + plane.w());
  return m.extremes.empty() ? 0.f : -lowest;
}

bool accepted(const PartDetection& d, const MatchingConfig& cfg);

PartDetection matchPair(const SceneData& s, const ModelMatcher::ModelIndex& m, const MatchingConfig& cfg,
                    const Eigen::Vector4f* support, uint64_t seed) {
  PartDetection d;
  d.model = m.id;
  d.matcher = cfg.coarse;
  std::vector<Hypothesis> candidates;
  const auto t_coarse = Clock::now();
  if (cfg.coarse == "ppf") {
    candidates = ppfHypotheses(s, m, cfg, support, &d.iterations);
  } else if (cfg.coarse == "fgr") {
    std::vector<Vec3> sp, mp;
    std::vector<Fpfh> sf, mf;
    for (int i : s.fpfh_valid) {
      sp.push_back(s.coarse.points[i]);
      sf.push_back(s.fpfh[i]);
    }
    for (int i : m.fpfh_valid) {
      mp.push_back(m.coarse->points[i]);
      mf.push_back(m.fpfh[i]);
    }
    FgrOptions o;
    o.max_correspondence_distance = cfg.inlier_distance;
    o.seed = static_cast<int>(seed % 1000003);
    Hypothesis h;
    try {
      h.T = fastGlobalRegistration(mp, mf, sp, sf, o).cast<float>();
      candidates.push_back(h);
    } catch (const std::exception&) {
      // Open3D throws when too few matches survive its tuple test: no hypothesis
    }
    d.iterations = o.iterations;
  } else {
    candidates = ransac(s, m, correspondences(s, m, cfg), cfg, seed, &d.iterations);
  }
  d.coarse_seconds = seconds(t_coarse);
  const auto t_refine = Clock::now();
  double best = -1;
  // Every candidate is refined on a thinned scene (distance-field neighbours only) and scored;
  // the best one is then refined on all the ICP points and polished with exact neighbours.
  auto evaluate = [&](const Eigen::Isometry3f& T0, size_t points, bool polish, PartDetection* c) {
    Refined r = icp(s, m, T0, cfg, points, polish);
    if (!r.T.matrix().allFinite()) return false;
    if (support && belowSupport(m, r.T, *support) > cfg.max_support_penetration) return false;
    auto score = [&](const Eigen::Isometry3f& T, PartDetection* out) {
      *out = d;
      out->pose = T.cast<double>();
      out->rmse = r.rmse;
      out->coverage = coverage(s, m, T, cfg.fitness_radius);
      out->fitness = visibleFitness(s, m, T, cfg);
      out->score = out->fitness * (cfg.min_coverage > 0 ? out->coverage : 1.0);
    };
    score(r.T, c);
    // a polished pose good enough to report goes to the middle of its slack (kept if it still is)
    if (polish && cfg.icp_centre_slack && !r.polished.empty() && accepted(*c, cfg)) {
      const Eigen::Isometry3f T = (r.T.cast<double>() * centreInSlack(m, r.polished, r.polished_fresh, cfg).inverse()).cast<float>();
      PartDetection centred;
      if (T.matrix().allFinite() && !(support && belowSupport(m, T, *support) > cfg.max_support_penetration)) {
        score(T, &centred);
        if (accepted(centred, cfg)) *c = centred;
      }
    }
    return true;
  };
  const size_t all_points = static_cast<size_t>(std::max(100.0, cfg.icp_max_points));
  const size_t screen_points = std::min(all_points, static_cast<size_t>(std::max(100.0, cfg.icp_screen_points)));
  PartDetection chosen = d;
  for (const auto& h : candidates) {
    if (!h.T.matrix().allFinite()) continue;
    PartDetection c;
    if (evaluate(h.T, screen_points, false, &c) && c.score > best) {
      best = c.score;
      chosen = c;
    }
  }
  PartDetection fine;
  if (best < 0) {
    fine = d;
  } else if (!evaluate(chosen.pose.cast<float>(), all_points, true, &fine)) {
    fine = chosen;
  }
  fine.refine_seconds = seconds(t_refine);
  return fine;
}

bool accepted(const PartDetection& d, const MatchingConfig& cfg) {
  return d.score > 0 && d.fitness >= cfg.min_fitness && d.coverage >= cfg.min_coverage && d.rmse <= cfg.max_rmse;
}

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

ModelMatcher::ModelMatcher(std::shared_ptr<const ModelLibrary> library, const MatchingConfig& config)
    : library_(std::move(library)), config_(config) {
  if (!library_) throw std::invalid_argument("ModelMatcher: no model library");
  if (config_.coarse != "ppf" && config_.coarse != "ransac" && config_.coarse != "fgr") {
    throw std::invalid_argument("ModelMatcher: coarse must be 'ppf', 'ransac' or 'fgr' (got '" + config_.coarse + "')");
  }
  if (config_.scene_search != "grid" && config_.scene_search != "kdtree") {
    throw std::invalid_argument("ModelMatcher: scene_search must be 'grid' or 'kdtree' (got '" + config_.scene_search + "')");
  }
  if (config_.threads <= 0) config_.threads = std::max(1u, std::thread::hardware_concurrency());
}

ModelMatcher::~ModelMatcher() = default;

std::shared_ptr<const ModelMatcher::ModelIndex> ModelMatcher::index(const std::string& id) const {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = indices_.find(id);
    if (it != indices_.end()) return it->second;
  }
  const ModelEntry& e = library_->model(id);
  auto m = std::make_shared<ModelIndex>();
  m->id = id;
  m->info = e.info;
  m->fine = library_->cloud(id, config_.icp_spacing);
  {
    // Descriptors see the model as a scan sees it: PCA normals over normal_radius (not the
    // mesh's sharp face normals), turned outwards; computed on the coarse cloud like the scene's.
    auto coarse = std::make_shared<ScanCloud>(*library_->cloud(id, config_.voxel));
    auto pts = toXyz(coarse->points);
    pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
    ne.setInputCloud(pts);
    ne.setSearchSurface(toXyz(m->fine->points));
    ne.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
    ne.setRadiusSearch(config_.normal_radius);
    pcl::PointCloud<pcl::Normal> normals;
    ne.compute(normals);
    for (size_t i = 0; i < coarse->size(); ++i) {
      Vec3 n = normals[i].getNormalVector3fMap();
      if (!n.allFinite() || n.norm() < 0.5f) continue;
      n.normalize();
      coarse->normals[i] = n.dot(coarse->normals[i]) < 0 ? -n : n;
    }
    m->coarse = coarse;
  }
  if (config_.coarse == "ppf") {
    m->ppf_cloud = thinned(*m->coarse, config_.ppf_sampling);
    m->ppf = buildPpf(m->ppf_cloud, static_cast<float>(config_.ppf_distance_step), config_.ppf_angle_bins,
                      static_cast<size_t>(config_.ppf_max_bucket));
  } else {
    m->fpfh = computeFpfh(*m->coarse, config_.feature_radius);
    std::vector<Fpfh> valid;
    for (size_t i = 0; i < m->fpfh.size(); ++i) {
      if (!validFpfh(m->fpfh[i])) continue;
      m->fpfh_valid.push_back(static_cast<int>(i));
      valid.push_back(m->fpfh[i]);
    }
    if (!valid.empty()) m->fpfh_tree.setInputCloud(toPclFpfh(valid));
  }
  m->fine_tree.setInputCloud(toXyz(m->fine->points));
  // the surface centroid: exact from the mesh (a mean of the random fine samples is off by
  // ~R/sqrt(3N), 0.08 mm on the 25 mm sphere, which turns into pose error wherever a symmetry
  // leaves the rotation free); the mean of the points for a cloud model
  if (!e.mesh.faces.empty() && e.mesh.area() > 0) {
    m->centroid = e.mesh.surfaceCentroid();
  } else {
    for (const auto& p : m->fine->points) m->centroid += p.cast<double>();
    if (!m->fine->points.empty()) m->centroid /= static_cast<double>(m->fine->size());
  }
  m->diameter = e.bounds.diagonal().norm();
  if (!e.mesh.faces.empty()) {
    for (const auto& v : e.mesh.vertices) m->extremes.push_back(v.cast<float>());
  } else {
    m->extremes = m->coarse->points;
  }
  // distance field: cells of ≈ 1/3 of the coarse inlier distance (at most 4 M cells); each
  // fine point claims the cells within the margin whose centre it is nearest to
  const float margin = static_cast<float>(std::max(2 * config_.inlier_distance, 6 * config_.icp_spacing));
  const Eigen::Vector3f lo = e.bounds.min() - Vec3::Constant(margin), hi = e.bounds.max() + Vec3::Constant(margin);
  const Eigen::Vector3f size = hi - lo;
  float cell = static_cast<float>(std::max(config_.icp_spacing, config_.inlier_distance / 3));
  cell = std::max(cell, std::cbrt(size.prod() / 4e6f));
  m->field.origin = lo;
  m->field.cell = cell;
  m->field.dims = (size / cell).array().ceil().cast<int>().max(1);
  const Eigen::Vector3i D = m->field.dims;
  m->field.nearest.assign(static_cast<size_t>(D.x()) * D.y() * D.z(), -1);
  std::vector<float> best(m->field.nearest.size(), margin * margin);
  const int r = static_cast<int>(std::ceil(margin / cell));
  for (size_t j = 0; j < m->fine->size(); ++j) {
    const Vec3& p = m->fine->points[j];
    const Eigen::Vector3i c = ((p - lo) / cell).array().floor().cast<int>();
    for (int z = std::max(0, c.z() - r); z <= std::min(D.z() - 1, c.z() + r); ++z) {
      for (int y = std::max(0, c.y() - r); y <= std::min(D.y() - 1, c.y() + r); ++y) {
        for (int x = std::max(0, c.x() - r); x <= std::min(D.x() - 1, c.x() + r); ++x) {
          const size_t k = (static_cast<size_t>(z) * D.y() + y) * D.x() + x;
          const float d2 = (lo + cell * Vec3(x + 0.5f, y + 0.5f, z + 0.5f) - p).squaredNorm();
          if (d2 < best[k]) {
            best[k] = d2;
            m->field.nearest[k] = static_cast<int32_t>(j);
          }
        }
      }
    }
  }
  m->has_mesh = !e.mesh.faces.empty();
  if (m->has_mesh) m->caster.addMesh(e.mesh, Eigen::Isometry3d::Identity());
  m->caster.commit();
  if (m->has_mesh) m->faces = planarFaces(e.mesh);
  if (m->has_mesh && config_.icp_mesh_polish && config_.closest_point_grid && e.mesh.faces.size() <= 5000) {
    const float dmin = static_cast<float>(std::max(3 * config_.icp_spacing, 0.5 * config_.fitness_radius));
    const float cell = static_cast<float>(std::max(2 * config_.icp_spacing, 0.001));
    // margin: the polish's smallest correspondence distance and a cell (farther points are
    // rare in the polish: the RayCaster answers them)
    m->closest = ClosestPointGrid(e.mesh, cell, dmin + cell);
  }
  std::lock_guard<std::mutex> lock(mutex_);
  return indices_.emplace(id, m).first->second;
}

void ModelMatcher::prepare(const std::vector<std::string>& models_in) const {
  const std::vector<std::string> models = models_in.empty() ? library_->ids() : models_in;
  for (const auto& id : models) library_->model(id);
  for (const auto& id : models) index(id);
}

Eigen::Vector3d ModelMatcher::centroid(const std::string& model) const { return index(model)->centroid; }

std::vector<PartDetection> ModelMatcher::locate(const std::vector<ScanCloud>& clusters,
                                            const std::vector<std::string>& models_in, MatchStats* stats,
                                            const Eigen::Vector3f* viewpoint, const Eigen::Vector4f* support_plane) const {
  const auto t0 = Clock::now();
  MatchingConfig cfg = config_;
  if (viewpoint) cfg.viewpoint = *viewpoint;
  MatchStats local;
  MatchStats& st = stats ? *stats : local;
  st = MatchStats();
  std::vector<std::string> models = models_in.empty() ? library_->ids() : models_in;
  for (const auto& id : models) library_->model(id);  // unknown id: throws before any work
  std::vector<std::shared_ptr<const ModelIndex>> idx(models.size());
  parallelFor(models.size(), cfg.threads, [&](size_t i) { idx[i] = index(models[i]); });

  struct Work {
    int cluster;
    std::vector<Vec3> points;
    std::unique_ptr<SceneData> scene;
    double scene_seconds = 0;
    std::vector<PartDetection> per_model;
  };
  std::vector<PartDetection> out;
  std::vector<Work> round;
  for (size_t c = 0; c < clusters.size(); ++c) {
    Work w;
    w.cluster = static_cast<int>(c);
    for (const auto& p : clusters[c].points) {
      if (p.allFinite()) w.points.push_back(p);
    }
    if (w.points.size() < 3) {
      st.warnings.push_back("cluster " + std::to_string(c) + ": " + std::to_string(w.points.size()) +
                            " finite points, nothing to match");
      continue;
    }
    const size_t cap = static_cast<size_t>(std::max(1000.0, cfg.max_cluster_points));
    if (w.points.size() > cap) {
      const size_t before = w.points.size();
      w.points = capPoints(w.points, cfg.icp_spacing, cap);
      st.warnings.push_back("cluster " + std::to_string(c) + ": " + std::to_string(before) +
                            " points, above max_cluster_points " + std::to_string(cap) + ": thinned to " +
                            std::to_string(w.points.size()) + " (crop the scene or raise the limit)");
    }
    round.push_back(std::move(w));
  }
  for (int instance = 0; instance < std::max(1, cfg.max_instances) && !round.empty(); ++instance) {
    parallelFor(round.size(), cfg.threads, [&](size_t i) {
      const auto t = Clock::now();
      round[i].scene = prepareScene(round[i].points, cfg);
      round[i].scene_seconds = seconds(t);
    });
    for (const auto& w : round) st.scene_seconds += w.scene_seconds;
    std::vector<std::pair<size_t, size_t>> pairs;
    for (size_t w = 0; w < round.size(); ++w) {
      round[w].per_model.assign(models.size(), PartDetection());
      for (size_t m = 0; m < models.size(); ++m) {
        const bool too_big = cfg.min_coverage > 0 &&
                             round[w].scene->diameter > 1.15f * idx[m]->diameter + 2 * static_cast<float>(cfg.voxel);
        if (too_big) {
          ++st.pairs_skipped_by_size;
          continue;
        }
        pairs.emplace_back(w, m);
      }
    }
    st.pairs += pairs.size();
    parallelFor(pairs.size(), cfg.threads, [&](size_t k) {
      const auto [w, m] = pairs[k];
      if (round[w].scene->coarse.size() < 3) return;
      const uint64_t seed = cfg.seed + 7919 * static_cast<uint64_t>(round[w].cluster) + 104729 * m + 15485863ull * instance;
      round[w].per_model[m] = matchPair(*round[w].scene, *idx[m], cfg, support_plane, seed);
      round[w].per_model[m].cluster = round[w].cluster;
    });
    std::vector<Work> next;
    for (auto& w : round) {
      const PartDetection* best = nullptr;
      size_t best_m = 0;
      for (size_t m = 0; m < models.size(); ++m) {
        const PartDetection& d = w.per_model[m];
        st.coarse_seconds += d.coarse_seconds;
        st.refine_seconds += d.refine_seconds;
        if (!d.model.empty() && !accepted(d, cfg)) st.rejected.push_back(d);
        if (accepted(d, cfg) && (!best || d.score > best->score)) {
          best = &d;
          best_m = m;
        }
      }
      if (!best) continue;
      PartDetection d = *best;
      // leftover points (another part touching this one) get another search
      const ModelIndex& mi = *idx[best_m];
      const Eigen::Isometry3f Ti = d.pose.cast<float>().inverse();
      const float r2 = static_cast<float>(4 * cfg.fitness_radius * cfg.fitness_radius);
      Work rest;
      rest.cluster = w.cluster;
      for (const auto& p : w.points) {
        const Vec3 q = Ti * p;
        const int j = mi.field.lookup(q);
        if (j < 0 || (q - mi.fine->points[j]).squaredNorm() > r2) rest.points.push_back(p);
      }
      d.pose = canonicalPose(mi.info, mi.centroid, d.pose);
      out.push_back(d);
      if (cfg.min_coverage > 0 && static_cast<int>(rest.points.size()) >= cfg.min_instance_points) {
        next.push_back(std::move(rest));
      }
    }
    round = std::move(next);
  }
  st.seconds = seconds(t0);
  return out;
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
  positive("ppf_sampling", c.ppf_sampling);
  positive("ppf_distance_step", c.ppf_distance_step);
  c.ppf_angle_bins = m.getInt("ppf_angle_bins", c.ppf_angle_bins);
  if (c.ppf_angle_bins < 4 || c.ppf_angle_bins > 255) m.fail("ppf_angle_bins", "must be in [4, 255]");
  c.ppf_ref_step = m.getInt("ppf_ref_step", c.ppf_ref_step);
  if (c.ppf_ref_step < 1) m.fail("ppf_ref_step", "must be >= 1");
  atLeast("ppf_max_bucket", c.ppf_max_bucket, 1);
  atLeast("ppf_candidates", c.ppf_candidates, 1);
  atLeast("max_iterations", c.max_iterations, 1);
  c.confidence = m.getDouble("confidence", c.confidence);
  if (!(c.confidence > 0 && c.confidence < 1)) m.fail("confidence", "must be in (0, 1)");
  share("edge_similarity", c.edge_similarity);
  positive("normal_tolerance", c.normal_tolerance);
  positive("inlier_distance", c.inlier_distance);
  atLeast("refine_candidates", c.refine_candidates, 1);
  positive("icp_spacing", c.icp_spacing);
  c.icp_iterations = m.getInt("icp_iterations", c.icp_iterations);
  positive("icp_max_points", c.icp_max_points);
  positive("icp_screen_points", c.icp_screen_points);
  positive("max_cluster_points", c.max_cluster_points);
  atLeast("icp_exact_iterations", c.icp_exact_iterations, 0);
  c.icp_mesh_polish = m.getBool("icp_mesh_polish", c.icp_mesh_polish);
  c.icp_centre_slack = m.getBool("icp_centre_slack", c.icp_centre_slack);
  positive("icp_slack_range", c.icp_slack_range);
  positive("icp_slack_tolerance", c.icp_slack_tolerance);
  share("icp_slack_eigen_ratio", c.icp_slack_eigen_ratio);
  atLeast("icp_slack_steps", c.icp_slack_steps, 1);
  c.closest_point_grid = m.getBool("closest_point_grid", c.closest_point_grid);
  c.icp_huber_floor = m.getDouble("icp_huber_floor", c.icp_huber_floor);
  if (!(c.icp_huber_floor >= 0)) m.fail("icp_huber_floor", "must be >= 0");
  positive("fitness_radius", c.fitness_radius);
  share("min_fitness", c.min_fitness);
  share("min_coverage", c.min_coverage);
  positive("max_rmse", c.max_rmse);
  c.check_visibility = m.getBool("check_visibility", c.check_visibility);
  if (m.has("viewpoint")) c.viewpoint = m.getVector3("viewpoint").cast<float>();
  positive("max_view_angle", c.max_view_angle);
  positive("max_support_penetration", c.max_support_penetration);
  c.max_instances = m.getInt("max_instances", c.max_instances);
  c.min_instance_points = m.getInt("min_instance_points", c.min_instance_points);
  c.threads = m.getInt("threads", c.threads);
  c.seed = static_cast<uint64_t>(m.getInt("seed", static_cast<int>(c.seed)));
  m.finish();
  return c;
}

}  // namespace cellsight
