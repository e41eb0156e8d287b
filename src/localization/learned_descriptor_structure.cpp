// The learned descriptor's input geometry: per cloud, which points each level of the network
// samples (farthest points) and groups, the groups' offsets in their local reference frames, and
// the weights that carry features back down. Includes libtorch for the tensors built here, like
// learned_descriptor.cpp and descriptor_training.cpp.
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <numeric>
#include <utility>
#include <vector>

#include "cellsight/common/point_grid.hpp"
#include "cellsight/localization/model_library.hpp"
#include "learned_descriptor_impl.hpp"

namespace cellsight {
namespace descriptor_detail {
namespace {

using Vec3 = Eigen::Vector3f;

/// Farthest-point sampling of m of the points (the first: the one farthest from the mean); with
/// `spacing` > 0, until every point lies within `spacing` of a centre (m is not used). Exact
/// farthest-point order: each new centre lowers the distance of the points nearer it than the
/// current farthest distance only, which a grid finds once that distance is a few cells; a
/// lazy max-heap gives the next farthest point.
std::vector<int> farthestPoints(const std::vector<Vec3>& p, int m, float spacing = 0) {
  const int n = static_cast<int>(p.size());
  std::vector<int> out;
  if (spacing > 0) m = n;
  if (m >= n && spacing <= 0) {
    out.resize(n);
    std::iota(out.begin(), out.end(), 0);
    return out;
  }
  Vec3 mean = Vec3::Zero();
  for (const auto& q : p) mean += q;
  mean /= static_cast<float>(n);
  int first = 0;
  float far = -1;
  for (int i = 0; i < n; ++i) {
    const float d = (p[i] - mean).squaredNorm();
    if (d > far) far = d, first = i;
  }
  std::vector<float> dist(n, std::numeric_limits<float>::max());
  out.reserve(std::min(m, n));
  const float cell = spacing > 0 ? 2 * spacing : 0.f;
  std::unique_ptr<PointGrid> grid;
  if (cell > 0) grid = std::make_unique<PointGrid>(p, cell);
  std::vector<std::pair<float, int>> heap;  // (distance, point), lazily updated
  const float stop = spacing * spacing;
  int cur = first;
  for (int k = 0; k < m; ++k) {
    out.push_back(cur);
    const Vec3 c = p[cur];
    const float reach = dist[cur];  // no point is farther than this from the centres so far
    dist[cur] = 0;
    auto lower = [&](int i, float d) {
      if (d < dist[i]) {
        dist[i] = d;
        if (grid) {
          heap.emplace_back(d, i);
          std::push_heap(heap.begin(), heap.end());
        }
      }
    };
    if (grid && reach < 64 * cell * cell) {
      grid->forEachWithin(c, std::sqrt(reach), [&](size_t i, float d2) { lower(static_cast<int>(i), d2); });
    } else {
      for (int i = 0; i < n; ++i) lower(i, (p[i] - c).squaredNorm());
    }
    if (grid) {
      while (!heap.empty() && heap.front().first != dist[heap.front().second]) {
        std::pop_heap(heap.begin(), heap.end());
        heap.pop_back();
      }
      if (heap.empty()) break;
      cur = heap.front().second;
    } else {
      float best = -1;
      for (int i = 0; i < n; ++i)
        if (dist[i] > best) best = dist[i], cur = i;
    }
    if (spacing > 0 && dist[cur] <= stop) break;
  }
  return out;
}

/// Frame of a group: columns x, y, z. z along the smallest spread (signed by the centre's
/// normal), x along the largest (signed towards the side holding more of the group).
Eigen::Matrix3f groupFrame(const std::vector<Vec3>& p, const std::vector<int>& members, const Vec3& c, const Vec3& normal,
                           float r) {
  Eigen::Matrix3f cov = Eigen::Matrix3f::Zero();
  float wsum = 0;
  for (int j : members) {
    const Vec3 d = p[j] - c;
    const float w = std::max(0.f, r - d.norm());
    cov += w * d * d.transpose();
    wsum += w;
  }
  Eigen::Matrix3f R = Eigen::Matrix3f::Identity();
  if (wsum <= 0) return R;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3f> es(cov / wsum);
  Vec3 z = es.eigenvectors().col(0), x = es.eigenvectors().col(2);
  if (normal.allFinite() && z.dot(normal) < 0) z = -z;
  float side = 0;
  for (int j : members) {
    const Vec3 d = p[j] - c;
    const float w = std::max(0.f, r - d.norm());
    side += w * d.dot(x);
  }
  if (side < 0) x = -x;
  R.col(0) = x;
  R.col(2) = z;
  R.col(1) = z.cross(x);
  return R;
}

/// The rotation-invariant part of a group member's input (the point pair feature of FPFH and
/// PPF): its distance, the offset along the centre's normal, the normals' agreement, the
/// member's normal along the offset.
void appendInvariant(const Vec3& d, const Vec3& nc, const Vec3& nj, std::vector<float>& x) {
  const float len = d.norm();
  const Vec3 u = len > 1e-6f ? Vec3(d / len) : Vec3::Zero();
  x.insert(x.end(), {len, nc.dot(d), nc.dot(nj), nj.dot(u)});
}

/// Up to k of the points in the list, spread evenly over it; fewer are repeated cyclically.
void pick(const std::vector<int>& found, int k, std::vector<int64_t>& out) {
  const size_t f = found.size();
  for (int i = 0; i < k; ++i) {
    if (f >= static_cast<size_t>(k)) out.push_back(found[static_cast<size_t>(i) * f / k]);
    else out.push_back(found[i % f]);
  }
}

torch::Tensor toTensor(const std::vector<float>& v, std::vector<int64_t> shape) {
  return torch::from_blob(const_cast<float*>(v.data()), shape, torch::kFloat32).clone();
}
torch::Tensor toTensor(const std::vector<int64_t>& v) {
  return torch::from_blob(const_cast<int64_t*>(v.data()), {static_cast<int64_t>(v.size())}, torch::kInt64).clone();
}

}  // namespace

Structure buildStructure(const std::vector<Vec3>& p0, const std::vector<Vec3>& n0, const DescriptorNetConfig& c) {
  const bool lrf = c.rotation == "lrf";
  Structure s;
  s.n = static_cast<int64_t>(p0.size());
  if (c.fpfh_radius > 0) {
    ScanCloud cloud;
    cloud.points = p0;
    cloud.normals = n0;
    cloud.intensity.assign(p0.size(), 1.f);
    const std::vector<Fpfh> f = computeFpfh(cloud, c.fpfh_radius);
    std::vector<float> x(p0.size() * 33, 0.f);
    for (size_t i = 0; i < f.size() && i < p0.size(); ++i)
      for (int k = 0; k < 33; ++k)
        if (std::isfinite(f[i][k])) x[i * 33 + k] = f[i][k] / 100.f;
    s.fpfh = toTensor(x, {s.n, 33});
  }
  // per-point encoder: every point's neighbourhood
  {
    const float r = static_cast<float>(c.point_radius);
    const int k = c.point_samples;
    PointGrid grid(p0, r);
    std::vector<float> x;
    x.reserve(p0.size() * k * 6);
    std::vector<int> found;
    std::vector<int64_t> chosen;
    for (size_t i = 0; i < p0.size(); ++i) {
      found.clear();
      grid.forEachWithin(p0[i], r, [&](size_t j, float) { found.push_back(static_cast<int>(j)); });
      if (found.empty()) found.push_back(static_cast<int>(i));
      const Eigen::Matrix3f R = lrf ? groupFrame(p0, found, p0[i], n0[i], r) : Eigen::Matrix3f::Identity();
      chosen.clear();
      pick(found, k, chosen);
      for (int64_t j : chosen) {
        const Vec3 d = R.transpose() * (p0[j] - p0[i]);
        const Vec3 nn = R.transpose() * n0[j];
        x.insert(x.end(), {d.x(), d.y(), d.z(), nn.x(), nn.y(), nn.z()});
        appendInvariant(p0[j] - p0[i], n0[i], n0[j], x);
      }
    }
    s.x0 = toTensor(x, {s.n, k, kPointInputs});
  }
  std::vector<Vec3> prev = p0, prev_n = n0;
  for (size_t l = 0; l < c.centres.size(); ++l) {
    Structure::Level L;
    const std::vector<int> centre =
        farthestPoints(prev, c.centres[l], c.centre_spacing.empty() ? 0.f : static_cast<float>(c.centre_spacing[l]));
    L.m = static_cast<int64_t>(centre.size());
    const float rs = static_cast<float>(c.radius_small[l]), rl = static_cast<float>(c.radius_large[l]);
    const int ks = c.samples_small[l], kl = c.samples_large[l];
    PointGrid grid(prev, rl);
    std::vector<int64_t> is, il;
    std::vector<float> xs, xl;
    std::vector<int> found_s, found_l;
    for (int ci : centre) {
      found_s.clear();
      found_l.clear();
      const float rs2 = rs * rs;
      grid.forEachWithin(prev[ci], rl, [&](size_t j, float d2) {
        found_l.push_back(static_cast<int>(j));
        if (d2 <= rs2) found_s.push_back(static_cast<int>(j));
      });
      if (found_l.empty()) found_l.push_back(ci);
      if (found_s.empty()) found_s.push_back(ci);
      const Eigen::Matrix3f R = lrf ? groupFrame(prev, found_l, prev[ci], prev_n[ci], rl) : Eigen::Matrix3f::Identity();
      const size_t s0 = is.size(), l0 = il.size();
      pick(found_s, ks, is);
      pick(found_l, kl, il);
      for (size_t q = s0; q < is.size(); ++q) {
        const Vec3 d = R.transpose() * (prev[is[q]] - prev[ci]);
        xs.insert(xs.end(), {d.x(), d.y(), d.z()});
        appendInvariant(prev[is[q]] - prev[ci], prev_n[ci], prev_n[is[q]], xs);
      }
      for (size_t q = l0; q < il.size(); ++q) {
        const Vec3 d = R.transpose() * (prev[il[q]] - prev[ci]);
        xl.insert(xl.end(), {d.x(), d.y(), d.z()});
        appendInvariant(prev[il[q]] - prev[ci], prev_n[ci], prev_n[il[q]], xl);
      }
    }
    L.idx_small = toTensor(is);
    L.idx_large = toTensor(il);
    L.rel_small = toTensor(xs, {L.m, ks, kGroupInputs});
    L.rel_large = toTensor(xl, {L.m, kl, kGroupInputs});
    // feature propagation: each previous point's three nearest centres, inverse-distance weights
    std::vector<int64_t> up;
    std::vector<float> w;
    up.reserve(prev.size() * 3);
    w.reserve(prev.size() * 3);
    // with spaced centres every point has one within the spacing: the three nearest are
    // looked up in a grid (all centres scanned only where fewer than three are near)
    const float near = c.centre_spacing.empty() ? 0.f : 3.f * static_cast<float>(c.centre_spacing[l]);
    std::vector<Vec3> centre_points;
    for (int ci : centre) centre_points.push_back(prev[ci]);
    std::unique_ptr<PointGrid> centre_grid;
    if (near > 0) centre_grid = std::make_unique<PointGrid>(centre_points, near);
    for (const auto& q : prev) {
      int b[3] = {0, 0, 0};
      float d[3] = {std::numeric_limits<float>::max(), std::numeric_limits<float>::max(),
                    std::numeric_limits<float>::max()};
      auto consider = [&](size_t k, float dd) {
        if (dd >= d[2]) return;
        int at = 2;
        while (at > 0 && dd < d[at - 1]) {
          d[at] = d[at - 1];
          b[at] = b[at - 1];
          --at;
        }
        d[at] = dd;
        b[at] = static_cast<int>(k);
      };
      if (centre_grid) centre_grid->forEachWithin(q, near, consider);
      if (d[2] == std::numeric_limits<float>::max()) {
        d[0] = d[1] = d[2] = std::numeric_limits<float>::max();
        for (size_t k = 0; k < centre_points.size(); ++k) consider(k, (centre_points[k] - q).squaredNorm());
      }
      float ws[3], sum = 0;
      for (int a = 0; a < 3; ++a) {
        if (d[a] == std::numeric_limits<float>::max()) {  // fewer than 3 centres
          ws[a] = 0;
          b[a] = b[0];
        } else {
          ws[a] = 1.f / (std::sqrt(d[a]) + 1e-4f);
        }
        sum += ws[a];
      }
      for (int a = 0; a < 3; ++a) {
        up.push_back(b[a]);
        w.push_back(ws[a] / sum);
      }
    }
    L.up_idx = toTensor(up);
    L.up_w = toTensor(w, {static_cast<int64_t>(prev.size()), 3, 1});
    std::vector<Vec3> next, next_n;
    for (int ci : centre) {
      next.push_back(prev[ci]);
      next_n.push_back(prev_n[ci]);
    }
    prev = std::move(next);
    prev_n = std::move(next_n);
    s.levels.push_back(std::move(L));
  }
  return s;
}

}  // namespace descriptor_detail
}  // namespace cellsight
