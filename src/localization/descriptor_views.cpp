// Training and evaluation material for the learned descriptor: laser-line single views with
// known correspondences, whole-model clouds as the matcher prepares them, generated meshes.
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <random>
#include <unordered_map>

#include "cellsight/common/point_grid.hpp"
#include "cellsight/common/raycaster.hpp"
#include "cellsight/localization/descriptor_training.hpp"
#include "cellsight/localization/model_library.hpp"

namespace cellsight {
namespace {

using Vec3 = Eigen::Vector3f;

/// PCA normals over `radius` of `surface` at each point, turned to agree with `hint(i)`.
template <typename Hint>
std::vector<Vec3> pcaNormals(const std::vector<Vec3>& points, const std::vector<Vec3>& surface, float radius, Hint hint) {
  PointGrid grid(surface, radius);
  std::vector<Vec3> out(points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    Vec3 mean = Vec3::Zero();
    int n = 0;
    grid.forEachWithin(points[i], radius, [&](size_t j, float) {
      mean += surface[j];
      ++n;
    });
    const Vec3 h = hint(i);
    if (n < 3) {
      out[i] = h;
      continue;
    }
    mean /= static_cast<float>(n);
    Eigen::Matrix3f cov = Eigen::Matrix3f::Zero();
    grid.forEachWithin(points[i], radius, [&](size_t j, float) { cov += (surface[j] - mean) * (surface[j] - mean).transpose(); });
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3f> es(cov);
    Vec3 nn = es.eigenvectors().col(0);
    out[i] = nn.dot(h) < 0 ? -nn : nn;
  }
  return out;
}

Vec3 randomUnit(std::mt19937_64& rng) {
  std::normal_distribution<float> N(0.f, 1.f);
  Vec3 v(N(rng), N(rng), N(rng));
  return v.normalized();
}

}  // namespace

LaserViewSetup randomLaserSetup(uint64_t seed) {
  std::mt19937_64 rng(seed * 7919 + 13);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  LaserViewSetup s;
  const float tilt = 35.f * static_cast<float>(M_PI) / 180.f * std::sqrt(U(rng));
  const float az = 2.f * static_cast<float>(M_PI) * U(rng);
  const float dist = 0.5f + 0.3f * U(rng);
  const Vec3 view(std::sin(tilt) * std::cos(az), std::sin(tilt) * std::sin(az), std::cos(tilt));
  s.eye = dist * view;
  // the projector 0.25–0.45 m away, its direction 15–40° from the camera's
  const float angle = (15.f + 25.f * U(rng)) * static_cast<float>(M_PI) / 180.f;
  Vec3 side = view.cross(randomUnit(rng));
  if (side.norm() < 1e-3f) side = view.unitOrthogonal();
  side.normalize();
  Vec3 pdir = std::cos(angle) * view + std::sin(angle) * side;
  if (pdir.z() < 0.2f) pdir = (pdir + Vec3(0, 0, 0.5f)).normalized();
  s.projector = (0.25f + 0.2f * U(rng)) * pdir;
  // the sheet contains the projector's direction and a line across the camera baseline: its
  // normal lies (mostly) along the baseline, and the projector moves along that normal
  Vec3 across = pdir.cross(side).normalized();
  Vec3 normal = pdir.cross(across).normalized();
  s.sheet_normal = normal;
  const Vec3 wobble = randomUnit(rng) * 0.2f;
  s.sweep = (normal + wobble - wobble.dot(pdir) * pdir).normalized();
  if (std::abs(s.sweep.dot(s.sheet_normal)) < 0.5f) s.sweep = s.sheet_normal;
  s.noise = 0.00003 + 0.00005 * U(rng);
  return s;
}

LaserView laserView(const TriangleMesh& mesh, const Eigen::Isometry3d& pose, const LaserViewSetup& s, uint64_t seed,
                    const ScanCloud* given) {
  ScanCloud own;
  if (!given) own = sampleMesh(mesh, s.sample_spacing, seed, CellSample::kSurfacePoint);
  const ScanCloud& samples = given ? *given : own;
  RayCaster rc;
  rc.addMesh(mesh, pose);
  rc.commit();
  std::mt19937_64 rng(seed + 1);
  std::normal_distribution<float> N(0.f, static_cast<float>(s.noise));
  const Eigen::Isometry3f T = pose.cast<float>();
  const float cos_max = std::cos(static_cast<float>(s.max_view_angle));
  const float denom = s.sheet_normal.dot(s.sweep);
  struct Cell {
    Vec3 p = Vec3::Zero(), t = Vec3::Zero();
    int n = 0;
  };
  std::unordered_map<uint64_t, Cell> cells;
  const float inv = static_cast<float>(1.0 / s.voxel);
  for (size_t i = 0; i < samples.size(); ++i) {
    const Vec3 p = T * samples.points[i], n = T.linear() * samples.normals[i];
    Vec3 ray = p - s.eye;
    const float d = ray.norm();
    ray /= d;
    if (-n.dot(ray) < cos_max) continue;
    if (rc.occluded(s.eye, ray, 0.f, d - 0.0003f)) continue;
    if (std::abs(denom) < 1e-6f) continue;
    const Vec3 o = s.projector + (s.sheet_normal.dot(p - s.projector) / denom) * s.sweep;
    Vec3 l = p - o;
    const float dl = l.norm();
    l /= dl;
    if (-n.dot(l) < cos_max) continue;
    if (rc.occluded(o, l, 0.f, dl - 0.0003f)) continue;
    const Vec3 q = p + N(rng) * ray;
    const Eigen::Vector3i c = (q * inv).array().floor().cast<int>();
    const uint64_t key = (static_cast<uint64_t>(c.x() + (1 << 20)) << 42) | (static_cast<uint64_t>(c.y() + (1 << 20)) << 21) |
                         static_cast<uint64_t>(c.z() + (1 << 20));
    Cell& cell = cells[key];
    cell.p += q;
    cell.t += samples.points[i];
    ++cell.n;
  }
  LaserView v;
  v.pose = pose;
  v.cloud.frame_id = "world";
  std::vector<std::pair<uint64_t, Cell>> sorted(cells.begin(), cells.end());
  std::sort(sorted.begin(), sorted.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<Vec3> dense;
  for (const auto& kv : sorted) {
    v.cloud.append(kv.second.p / static_cast<float>(kv.second.n), 1.f);
    v.truth.push_back(kv.second.t / static_cast<float>(kv.second.n));
  }
  const Vec3 eye = s.eye;
  v.cloud.normals = pcaNormals(v.cloud.points, v.cloud.points, static_cast<float>(s.normal_radius),
                               [&](size_t i) { return Vec3((eye - v.cloud.points[i]).normalized()); });
  return v;
}

LaserView modelCloud(const TriangleMesh& mesh, double voxel, double normal_radius, uint64_t seed) {
  const ScanCloud coarse = sampleMesh(mesh, voxel, seed, CellSample::kSurfacePoint);
  const ScanCloud fine = sampleMesh(mesh, std::min(0.0005, voxel / 2), seed + 1, CellSample::kSurfacePoint);
  // generated meshes overlap: samples inside another primitive (no free direction) are dropped
  RayCaster rc;
  rc.addMesh(mesh, Eigen::Isometry3d::Identity());
  rc.commit();
  auto exposed = [&](const Vec3& p, const Vec3& n) {
    static const Vec3 dirs[] = {Vec3(1, 0, 0), Vec3(-1, 0, 0), Vec3(0, 1, 0), Vec3(0, -1, 0), Vec3(0, 0, 1), Vec3(0, 0, -1),
                                Vec3(1, 1, 1).normalized(), Vec3(-1, 1, 1).normalized(), Vec3(1, -1, 1).normalized(),
                                Vec3(-1, -1, 1).normalized(), Vec3(1, 1, -1).normalized(), Vec3(-1, 1, -1).normalized(),
                                Vec3(1, -1, -1).normalized(), Vec3(-1, -1, -1).normalized()};
    for (const Vec3& d : dirs) {
      if (d.dot(n) <= 0.05f) continue;
      if (!rc.occluded(p + 1e-4f * n, d, 0.f, 10.f)) return true;
    }
    return false;
  };
  LaserView v;
  v.cloud.frame_id = "model";
  std::vector<Vec3> hints;
  for (size_t i = 0; i < coarse.size(); ++i) {
    if (!exposed(coarse.points[i], coarse.normals[i])) continue;
    v.cloud.append(coarse.points[i], 1.f);
    v.truth.push_back(coarse.points[i]);
    hints.push_back(coarse.normals[i]);
  }
  std::vector<Vec3> surface;
  for (size_t i = 0; i < fine.size(); ++i)
    if (exposed(fine.points[i], fine.normals[i])) surface.push_back(fine.points[i]);
  v.cloud.normals = pcaNormals(v.cloud.points, surface, static_cast<float>(normal_radius), [&](size_t i) { return hints[i]; });
  return v;
}

TriangleMesh randomPartMesh(uint64_t seed) {
  std::mt19937_64 rng(seed * 104729 + 7);
  std::uniform_real_distribution<double> U(0, 1);
  auto len = [&](double lo, double hi) { return lo + (hi - lo) * U(rng); };
  const int parts = 1 + static_cast<int>(U(rng) * 4);
  TriangleMesh out;
  Eigen::AlignedBox3f box;
  for (int k = 0; k < parts; ++k) {
    TriangleMesh m;
    const double kind = U(rng);
    if (kind < 0.5) {
      m = makeBox(Eigen::Vector3d(len(0.008, 0.08), len(0.008, 0.08), len(0.004, 0.05)));
    } else if (kind < 0.8) {
      m = makeCylinder(len(0.004, 0.03), len(0.006, 0.08), 32);
    } else {
      const double r = len(0.008, 0.03);
      m = makeTube(r, r * len(0.5, 0.8), len(0.006, 0.06), 32);
    }
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    if (k > 0) {
      // axis-aligned turns mostly (machined parts), sometimes any; placed so it overlaps or
      // touches what is there
      if (U(rng) < 0.7) {
        const int a = static_cast<int>(U(rng) * 3);
        T.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::Unit(a)).toRotationMatrix();
      } else {
        T.linear() = Eigen::Quaterniond::UnitRandom().toRotationMatrix();
      }
      const Eigen::Vector3f lo = box.min(), hi = box.max();
      Eigen::Vector3d at;
      for (int a = 0; a < 3; ++a) at[a] = lo[a] + (hi[a] - lo[a]) * U(rng);
      const int face = static_cast<int>(U(rng) * 3);
      at[face] = U(rng) < 0.5 ? lo[face] : hi[face];
      T.translation() = at;
    }
    out.append(m, T);
    box = out.bounds();
  }
  // centred on its box
  Eigen::Isometry3d C = Eigen::Isometry3d::Identity();
  C.translation() = -box.center().cast<double>();
  out.transform(C);
  return out;
}

TriangleMesh randomFreeformMesh(uint64_t seed) {
  std::mt19937_64 rng(seed * 15485863 + 11);
  std::uniform_real_distribution<double> U(0, 1);
  auto len = [&](double lo, double hi) { return lo + (hi - lo) * U(rng); };
  // one smooth blob: a sphere, its radius rippled by a few low-frequency waves, stretched to an
  // ellipsoid and bent along its long axis (x)
  auto blob = [&](const Eigen::Vector3d& half) {
    TriangleMesh m = makeSphere(1.0, 4);
    struct Wave {
      Eigen::Vector3d k;
      double a, phase;
    };
    std::vector<Wave> waves;
    const int nw = 2 + static_cast<int>(U(rng) * 4);
    for (int w = 0; w < nw; ++w) {
      Eigen::Vector3d k(U(rng) - 0.5, U(rng) - 0.5, U(rng) - 0.5);
      k = k.normalized() * len(1.0, 4.0);
      waves.push_back({k, len(0.03, 0.15), len(0, 2 * M_PI)});
    }
    const double bend = len(-0.8, 0.8) / half.x(), twist = len(-0.6, 0.6) / half.x();
    for (auto& v : m.vertices) {
      const Eigen::Vector3d u = v.cast<double>().normalized();
      double r = 1;
      for (const auto& w : waves) r += w.a * std::sin(w.k.dot(u) + w.phase);
      Eigen::Vector3d p = (r * u).cwiseProduct(half);
      p.y() += bend * p.x() * p.x();
      const double t = twist * p.x();
      p = Eigen::Vector3d(p.x(), std::cos(t) * p.y() - std::sin(t) * p.z(), std::sin(t) * p.y() + std::cos(t) * p.z());
      v = p.cast<float>();
    }
    return m;
  };
  const int parts = 1 + static_cast<int>(U(rng) * 5);
  TriangleMesh out;
  for (int k = 0; k < parts; ++k) {
    // a body, then limbs, necks, heads: longer and thinner, rooted at a point of what is there
    const double a = k == 0 ? len(0.015, 0.06) : len(0.008, 0.045);
    const double thin = k == 0 ? len(0.4, 1.0) : len(0.15, 0.6);
    const Eigen::Vector3d half(a, a * thin * len(0.7, 1.0), a * thin * len(0.5, 1.0));
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    if (k > 0) {
      std::normal_distribution<double> N(0, 1);
      T.linear() = Eigen::Quaterniond(N(rng), N(rng), N(rng), N(rng)).normalized().toRotationMatrix();
      const auto& root = out.vertices[static_cast<size_t>(U(rng) * (out.vertices.size() - 1))];
      // the limb's near end at the root, sunk a little into the body
      T.translation() = root.cast<double>() + T.linear() * Eigen::Vector3d(0.7 * a, 0, 0);
    }
    out.append(blob(half), T);
  }
  Eigen::Isometry3d C = Eigen::Isometry3d::Identity();
  C.translation() = -out.bounds().center().cast<double>();
  out.transform(C);
  return out;
}

std::vector<std::pair<int, int>> trueCorrespondences(const LaserView& a, const LaserView& b, double tolerance) {
  std::vector<std::pair<int, int>> out;
  if (b.truth.empty()) return out;
  PointGrid grid(b.truth, static_cast<float>(tolerance));
  for (size_t i = 0; i < a.truth.size(); ++i) {
    int best = -1;
    float bd = std::numeric_limits<float>::max();
    grid.forEachWithin(a.truth[i], static_cast<float>(tolerance), [&](size_t j, float d2) {
      if (d2 < bd) bd = d2, best = static_cast<int>(j);
    });
    if (best >= 0) out.emplace_back(static_cast<int>(i), best);
  }
  return out;
}

Eigen::MatrixXf fpfhRows(const ScanCloud& c, double radius) {
  const auto f = computeFpfh(c, radius);
  Eigen::MatrixXf m(static_cast<Eigen::Index>(f.size()), 33);
  for (size_t i = 0; i < f.size(); ++i)
    for (int k = 0; k < 33; ++k) m(static_cast<Eigen::Index>(i), k) = f[i][k];
  return m;
}

PairMatchFigures pairMatchFigures(const LaserView& a, const Eigen::MatrixXf& da, const LaserView& b,
                                  const Eigen::MatrixXf& db, double tolerance) {
  PairMatchFigures f;
  const auto m = matchDescriptors(da, db, true, 12);
  f.matches = m.size();
  for (const auto& [i, j] : m) f.correct += (a.truth[i] - b.truth[j]).norm() <= tolerance;
  f.inlier_ratio = f.matches ? static_cast<double>(f.correct) / f.matches : 0;
  return f;
}

}  // namespace cellsight
