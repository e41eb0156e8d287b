#include "cellsight/sim/renderer.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace cellsight {

// ---------------------------------------------------------------- noise
namespace {
const std::array<float, 65536>& gaussianTable() {
  static const std::array<float, 65536> table = [] {
    std::array<float, 65536> t{};
    // Inverse-CDF sampling at the bin centres gives an exact, symmetric N(0,1) table.
    for (size_t i = 0; i < t.size(); ++i) {
      const double p = (static_cast<double>(i) + 0.5) / static_cast<double>(t.size());
      // Acklam's rational approximation of the normal quantile (|error| < 1.2e-9).
      static const double a[] = {-3.969683028665376e+01, 2.209460984245205e+02,
                                 -2.759285104469687e+02, 1.383577518672690e+02,
                                 -3.066479806614716e+01, 2.506628277459239e+00};
      static const double b[] = {-5.447609879822406e+01, 1.615858368580409e+02,
                                 -1.556989798598866e+02, 6.680131188771972e+01,
                                 -1.328068155288572e+01};
      static const double c[] = {-7.784894002430293e-03, -3.223964580411365e-01,
                                 -2.400758277161838e+00, -2.549732539343734e+00,
                                 4.374664141464968e+00,  2.938163982698783e+00};
      static const double d[] = {7.784695709041462e-03, 3.224671290700398e-01,
                                 2.445134137142996e+00, 3.754408661907416e+00};
      double x;
      if (p < 0.02425) {
        const double q = std::sqrt(-2 * std::log(p));
        x = (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
            ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1);
      } else if (p > 1 - 0.02425) {
        const double q = std::sqrt(-2 * std::log(1 - p));
        x = -(((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
            ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1);
      } else {
        const double q = p - 0.5, r = q * q;
        x = (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q /
            (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1);
      }
      t[i] = static_cast<float>(x);
    }
    return t;
  }();
  return table;
}
}  // namespace

NoiseSource::NoiseSource(uint64_t seed) : state_(seed * 0x9E3779B97F4A7C15ull + 0x632BE59BD9B4E019ull) {}

uint64_t NoiseSource::next() {
  uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

double NoiseSource::uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }

float NoiseSource::gaussian() { return gaussianTable()[next() & 0xFFFF]; }

// ---------------------------------------------------------------- geometry
CellGeometry::CellGeometry(const Scene& scene) : scene_(scene) {
  // Table: a 20 mm slab whose top face is at table.z.
  TriangleMesh table = makeBox({scene.table.size.x(), scene.table.size.y(), 0.02});
  Eigen::Isometry3d T_table = Eigen::Isometry3d::Identity();
  T_table.translation() << scene.table.center.x(), scene.table.center.y(), scene.table.z - 0.01;
  caster_.addMesh(table, T_table);
  surfaces_.push_back({Kind::kTable, 0, scene.table.reflectivity, 0.0});
  for (size_t i = 0; i < scene.objects.size(); ++i) {
    const auto& o = scene.objects[i];
    caster_.addMesh(loadValidMesh(o.info.mesh_file), o.T_base_object);
    surfaces_.push_back({Kind::kObject, static_cast<int>(i), o.reflectivity, o.shininess});
  }
  for (size_t i = 0; i < scene.fixtures.size(); ++i) {
    const auto& f = scene.fixtures[i];
    // A 3 mm plate whose top face carries the code (the fixture frame's z = 0 plane).
    TriangleMesh plate = makeBox({f.plate_size, f.plate_size, 0.003});
    Eigen::Isometry3d T = f.T_base_fixture * Eigen::Translation3d(0, 0, -0.0015);
    caster_.addMesh(plate, T);
    surfaces_.push_back({Kind::kFixture, static_cast<int>(i), 0.85, 0.0});
    codes_.push_back(encodeQr(f.payload));
    T_fixture_base_.push_back(f.T_base_fixture.inverse());
  }
  caster_.commit();
}

double CellGeometry::fixtureAlbedo(int fixture, const Eigen::Vector3d& p_world) const {
  const auto& f = scene_.fixtures[static_cast<size_t>(fixture)];
  const Eigen::Vector3d p = T_fixture_base_[static_cast<size_t>(fixture)] * p_world;
  const double white = 0.85, black = 0.05;
  if (std::abs(p.z()) > 5e-4) return white;  // plate sides
  const QrMatrix& code = codes_[static_cast<size_t>(fixture)];
  const double half = f.code_size / 2;
  if (std::abs(p.x()) >= half || std::abs(p.y()) >= half) return white;  // quiet zone
  // Printed code: column index grows with +x, row index grows with -y (top row at +y).
  const int col = std::min(code.size - 1, static_cast<int>((p.x() + half) / f.code_size * code.size));
  const int row = std::min(code.size - 1, static_cast<int>((half - p.y()) / f.code_size * code.size));
  return code.dark(row, col) ? black : white;
}

// ---------------------------------------------------------------- scanner camera
ScannerRenderer::ScannerRenderer(std::shared_ptr<const CellGeometry> geometry,
                                 ScannerRenderOptions options)
    : geometry_(std::move(geometry)), options_(options) {
  const CameraConfig& cam = geometry_->scene().scanner_camera;
  width_ = cam.intrinsics.width;
  height_ = cam.intrinsics.height;
  const size_t n = static_cast<size_t>(width_) * static_cast<size_t>(height_);
  const Eigen::Matrix3f R = cam.T_base_camera.linear().cast<float>();
  camera_center_ = cam.T_base_camera.translation().cast<float>();
  dirs_.resize(n);
  points_.resize(n);
  normals_.resize(n);
  albedo_.assign(n, -1.f);
  shininess_.assign(n, 0.f);
  footprint_.assign(n, 0.f);
  for (int v = 0; v < height_; ++v) {
    for (int u = 0; u < width_; ++u) {
      const size_t i = static_cast<size_t>(v) * width_ + u;
      dirs_[i] = (R * cam.intrinsics.pixelRay({u, v}).cast<float>()).normalized();
    }
  }
  const RayCaster& rc = geometry_->caster();
  for (size_t i = 0; i < n; ++i) {
    const RayHit h = rc.intersect(camera_center_, dirs_[i]);
    if (!h.hit) continue;
    Eigen::Vector3f normal = h.normal;
    if (normal.dot(dirs_[i]) > 0) normal = -normal;  // open surfaces: face the camera
    points_[i] = camera_center_ + h.t * dirs_[i];
    normals_[i] = normal;
    const auto& s = geometry_->surface(h.geometry);
    albedo_[i] = static_cast<float>(
        s.kind == CellGeometry::Kind::kFixture
            ? geometry_->fixtureAlbedo(s.index, points_[i].cast<double>())
            : s.reflectivity);
    shininess_[i] = static_cast<float>(s.shininess);
    ++hit_count_;
  }
  // Pixel footprint on the surface: neighbour rays cut the tangent plane.
  for (int v = 0; v < height_; ++v) {
    for (int u = 0; u < width_; ++u) {
      const size_t i = static_cast<size_t>(v) * width_ + u;
      if (albedo_[i] < 0) continue;
      float fp = 0;
      for (int k = 0; k < 2; ++k) {
        const int du = k == 0 ? (u + 1 < width_ ? 1 : -1) : 0;
        const int dv = k == 1 ? (v + 1 < height_ ? 1 : -1) : 0;
        const Eigen::Vector3f& d = dirs_[i + du + static_cast<size_t>(dv) * width_ - 0];
        const float denom = normals_[i].dot(d);
        const float t = std::abs(denom) > 1e-4f
                            ? normals_[i].dot(points_[i] - camera_center_) / denom
                            : 1e3f;
        fp = std::max(fp, std::min(0.05f, (camera_center_ + t * d - points_[i]).norm()));
      }
      footprint_[i] = fp;
    }
  }
  const float ambient = static_cast<float>(geometry_->scene().noise.ambient);
  ambient_.resize(n);
  for (size_t i = 0; i < n; ++i) ambient_[i] = albedo_[i] > 0 ? ambient * albedo_[i] : 0.f;
  constexpr int kTile = 16;
  for (int v0 = 0; v0 < height_; v0 += kTile) {
    for (int u0 = 0; u0 < width_; u0 += kTile) {
      Eigen::AlignedBox3f box;
      float fp = 0;
      const int u1 = std::min(width_, u0 + kTile), v1 = std::min(height_, v0 + kTile);
      for (int v = v0; v < v1; ++v) {
        for (int u = u0; u < u1; ++u) {
          const size_t i = static_cast<size_t>(v) * width_ + u;
          if (albedo_[i] < 0) continue;
          box.extend(points_[i]);
          fp = std::max(fp, footprint_[i]);
        }
      }
      if (box.isEmpty()) continue;
      tiles_.push_back({box.center(), box.sizes() / 2, fp, u0, v0, u1, v1});
    }
  }
}

Plane ScannerRenderer::planeInCamera(const Eigen::Isometry3d& T_base_flange) const {
  const auto& sc = geometry_->scene();
  return laserPlane(sc.scanner_camera.T_base_camera.inverse() * T_base_flange *
                    sc.laser.T_flange_laser);
}

void ScannerRenderer::laserPass(const Eigen::Isometry3d& T_base_flange, cv::Mat& laser,
                                uint64_t seed, bool noisy) const {
  const Scene& sc = geometry_->scene();
  const Eigen::Isometry3d T_base_laser = T_base_flange * sc.laser.T_flange_laser;
  const Eigen::Vector3f o = T_base_laser.translation().cast<float>();
  const Eigen::Vector3f xL = T_base_laser.linear().col(0).cast<float>();
  const Eigen::Vector3f nL = T_base_laser.linear().col(1).cast<float>();
  const Eigen::Vector3f zL = T_base_laser.linear().col(2).cast<float>();
  const float sigma = static_cast<float>(sc.laser.line_width / (2.0 * std::sqrt(2.0 * std::log(2.0))));
  const float inv2s2 = 1.f / (2.f * sigma * sigma);
  const float band = static_cast<float>(options_.band_sigmas) * sigma;
  const float tan_half_fan = static_cast<float>(std::tan(sc.laser.fan_angle / 2));
  const float brightness = static_cast<float>(sc.laser.brightness);
  const int ss = std::max(1, options_.supersample);
  const float ns = nL.dot(o);
  const RayCaster& rc = geometry_->caster();
  const Eigen::Isometry3f T_cam_base = sc.scanner_camera.T_base_camera.inverse().cast<float>();
  const NoiseConfig& noise = sc.noise;
  NoiseSource rng(seed ^ 0xA5A5A5A5ull);
  laser.create(height_, width_, CV_32F);
  laser.setTo(0);
  auto* out = reinterpret_cast<float*>(laser.data);
  for (const Tile& tile : tiles_) {
    // The sheet's distance over the tile's box: |centre distance| − box extent along n.
    const float reach = std::abs(nL.x()) * tile.half.x() + std::abs(nL.y()) * tile.half.y() +
                        std::abs(nL.z()) * tile.half.z();
    if (std::abs(nL.dot(tile.center) - ns) - reach > band + tile.footprint) continue;
    for (int tv = tile.v0; tv < tile.v1; ++tv) {
    for (int tu = tile.u0; tu < tile.u1; ++tu) {
    const size_t i = static_cast<size_t>(tv) * width_ + tu;
    if (albedo_[i] < 0) continue;
    const Eigen::Vector3f& P = points_[i];
    const float s = nL.dot(P) - ns;
    if (std::abs(s) > band + footprint_[i]) continue;
    const Eigen::Vector3f dvec = P - o;
    const float z = zL.dot(dvec);
    if (z <= 0 || std::abs(xL.dot(dvec)) > z * tan_half_fan) continue;
    const float dist = dvec.norm();
    const Eigen::Vector3f l = -dvec / dist;
    const Eigen::Vector3f& N = normals_[i];
    const float cosi = N.dot(l);
    if (cosi <= 0) continue;
    const Eigen::Vector3f origin = P + N * 2e-6f;
    if (rc.occluded(origin, l, 0.f, (o - origin).norm() - 1e-5f)) continue;  // laser shadow
    // Sheet-distance gradient across the pixel (neighbour rays cut the tangent plane).
    const int u = tu, v = tv;
    float g[2];
    for (int k = 0; k < 2; ++k) {
      const int du = k == 0 ? (u + 1 < width_ ? 1 : -1) : 0;
      const int dv = k == 1 ? (v + 1 < height_ ? 1 : -1) : 0;
      const Eigen::Vector3f& d = dirs_[i + static_cast<size_t>(du + dv * width_)];
      const float denom = N.dot(d);
      const float t = std::abs(denom) > 1e-4f ? N.dot(P - camera_center_) / denom : 0.f;
      g[k] = (du + dv) * nL.dot(camera_center_ + t * d - P);
    }
    float profile = 0;
    for (int a = 0; a < ss; ++a) {
      const float da = (a + 0.5f) / ss - 0.5f;
      for (int b = 0; b < ss; ++b) {
        const float db = (b + 0.5f) / ss - 0.5f;
        const float sk = s + da * g[0] + db * g[1];
        profile += std::exp(-sk * sk * inv2s2);
      }
    }
    profile /= static_cast<float>(ss * ss);
    float intensity = brightness * albedo_[i] * cosi * profile;
    if (noisy) {
      if (rng.uniform() < noise.dropout_probability) continue;
      intensity *= std::max(0.f, 1.f + static_cast<float>(noise.speckle) * rng.gaussian());
    }
    out[i] += intensity;
    // Stray reflection: shiny surfaces mirror part of the laser onto other surfaces.
    if (noisy && shininess_[i] > 0 && profile > 0.3f && noise.stray_gain > 0) {
      const Eigen::Vector3f din = dvec / dist;
      const Eigen::Vector3f r = din - 2.f * din.dot(N) * N;
      const RayHit h = rc.intersect(origin, r, 1e-4f);
      if (!h.hit) continue;
      const Eigen::Vector3f Q = origin + h.t * r;
      const float cosq = -h.normal.dot(r);
      if (cosq <= 0) continue;
      const Eigen::Vector3f qc = T_cam_base * Q;
      if (qc.z() <= 0) continue;
      const Eigen::Vector2d uv = sc.scanner_camera.intrinsics.project(qc.cast<double>());
      const int qu = static_cast<int>(std::lround(uv.x())), qv = static_cast<int>(std::lround(uv.y()));
      if (qu < 1 || qv < 1 || qu >= width_ - 1 || qv >= height_ - 1) continue;
      const size_t qi = static_cast<size_t>(qv) * width_ + qu;
      if (albedo_[qi] < 0 || (points_[qi] - Q).norm() > 2e-3f) continue;  // hidden from camera
      const float spot = brightness * static_cast<float>(noise.stray_gain) * shininess_[i] *
                         albedo_[qi] * cosq * profile;
      static const float kernel[3][3] = {{0.3f, 0.6f, 0.3f}, {0.6f, 1.f, 0.6f}, {0.3f, 0.6f, 0.3f}};
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          out[qi + static_cast<size_t>(dy * width_ + dx)] += spot * kernel[dy + 1][dx + 1];
    }
    }
    }
  }
}

cv::Mat ScannerRenderer::renderLaserOnly(const Eigen::Isometry3d& T_base_flange) const {
  cv::Mat laser;
  laserPass(T_base_flange, laser, 0, false);
  return laser;
}

cv::Mat ScannerRenderer::render(const Eigen::Isometry3d& T_base_flange, uint64_t frame_seed) const {
  const Scene& sc = geometry_->scene();
  const bool noisy = options_.noise && sc.noise.enabled;
  cv::Mat laser;
  laserPass(T_base_flange, laser, frame_seed, noisy);
  const bool with_ambient = options_.ambient && sc.noise.enabled;
  const float sigma = noisy ? static_cast<float>(sc.noise.sensor_sigma) : 0.f;
  const bool rgb = sc.scanner_camera.encoding == "rgb8";
  const int channel = sc.laser.colour == "red" ? 0 : sc.laser.colour == "green" ? 1 : 2;
  const size_t n = points_.size();
  // Sensor noise: a window of a fixed N(0,1) field at a per-frame random offset, so the pass
  // over every pixel is a straight, vectorisable loop.
  const std::vector<float>& field = noiseField();
  NoiseSource rng(frame_seed);
  const size_t span = rgb ? 3 * n : n;
  const size_t offset = span < field.size() ? static_cast<size_t>(rng.next() % (field.size() - span)) : 0;
  const float* __restrict nz = field.data() + offset;
  const float* __restrict l = reinterpret_cast<const float*>(laser.data);
  const float* __restrict amb = ambient_.data();
  const float amb_scale = with_ambient ? 1.f : 0.f;
  cv::Mat img(height_, width_, rgb ? CV_8UC3 : CV_8UC1);
  uint8_t* __restrict px = img.data;
  if (!rgb) {
    for (size_t i = 0; i < n; ++i) {
      float x = amb_scale * amb[i] + l[i] + sigma * nz[i] + 0.5f;
      x = x < 0.f ? 0.f : (x > 255.f ? 255.f : x);
      px[i] = static_cast<uint8_t>(x);
    }
  } else {
    for (size_t i = 0; i < n; ++i) {
      for (int c = 0; c < 3; ++c) {
        float x = amb_scale * amb[i] + (c == channel ? l[i] : 0.f) + sigma * nz[3 * i + c] + 0.5f;
        x = x < 0.f ? 0.f : (x > 255.f ? 255.f : x);
        px[3 * i + c] = static_cast<uint8_t>(x);
      }
    }
  }
  return img;
}

const std::vector<float>& ScannerRenderer::noiseField() {
  static const std::vector<float> field = [] {
    std::vector<float> f(size_t(1) << 23);  // 8 Mi samples: room for an rgb8 2 MP frame
    NoiseSource rng(0x5EEDull);
    for (auto& x : f) x = rng.gaussian();
    return f;
  }();
  return field;
}

// ---------------------------------------------------------------- fixture camera
FixtureRenderer::FixtureRenderer(std::shared_ptr<const CellGeometry> geometry, double light,
                                 int supersample)
    : geometry_(std::move(geometry)) {
  const CameraConfig& cam = geometry_->scene().fixture_camera;
  const int w = cam.intrinsics.width, h = cam.intrinsics.height;
  const Eigen::Matrix3d R = cam.T_base_camera.linear();
  const Eigen::Vector3f C = cam.T_base_camera.translation().cast<float>();
  const RayCaster& rc = geometry_->caster();
  const int ss = std::max(1, supersample);
  clean_.create(h, w, CV_32F);
  for (int v = 0; v < h; ++v) {
    auto* row = clean_.ptr<float>(v);
    for (int u = 0; u < w; ++u) {
      double acc = 0;
      for (int a = 0; a < ss; ++a) {
        for (int b = 0; b < ss; ++b) {
          const Eigen::Vector2d pix(u + (a + 0.5) / ss - 0.5, v + (b + 0.5) / ss - 0.5);
          const Eigen::Vector3f d = (R * cam.intrinsics.pixelRay(pix)).cast<float>();
          const RayHit hit = rc.intersect(C, d);
          if (!hit.hit) {
            acc += 15.0;
            continue;
          }
          const auto& s = geometry_->surface(hit.geometry);
          const Eigen::Vector3d p = (C + hit.t * d).cast<double>();
          const double albedo = s.kind == CellGeometry::Kind::kFixture
                                    ? geometry_->fixtureAlbedo(s.index, p)
                                    : s.reflectivity;
          const double up = std::max(0.f, hit.normal.z());
          acc += light * albedo * (0.3 + 0.7 * up);
        }
      }
      row[u] = static_cast<float>(acc / (ss * ss));
    }
  }
  if (cam.blur_sigma_px > 0) cv::GaussianBlur(clean_, clean_, cv::Size(0, 0), cam.blur_sigma_px);
}

cv::Mat FixtureRenderer::render(uint64_t frame_seed) const {
  const Scene& sc = geometry_->scene();
  const float sigma = sc.noise.enabled ? static_cast<float>(sc.noise.sensor_sigma) : 0.f;
  const bool rgb = sc.fixture_camera.encoding == "rgb8";
  NoiseSource rng(frame_seed);
  cv::Mat img(clean_.rows, clean_.cols, rgb ? CV_8UC3 : CV_8UC1);
  for (int v = 0; v < clean_.rows; ++v) {
    const float* src = clean_.ptr<float>(v);
    uint8_t* dst = img.ptr<uint8_t>(v);
    for (int u = 0; u < clean_.cols; ++u) {
      for (int c = 0; c < (rgb ? 3 : 1); ++c) {
        const float x = src[u] + (sigma > 0 ? sigma * rng.gaussian() : 0.f);
        dst[(rgb ? 3 : 1) * u + c] =
            static_cast<uint8_t>(x <= 0.f ? 0 : x >= 255.f ? 255 : static_cast<int>(x + 0.5f));
      }
    }
  }
  return img;
}

}  // namespace cellsight
