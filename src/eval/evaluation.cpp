#include "cellsight/eval/evaluation.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "cellsight/eval/sim_scan.hpp"

namespace cellsight {

double pointTriangleDistance(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                             const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  return (p - closestPointOnTriangle(p, a, b, c)).norm();
}

SurfaceDistance::SurfaceDistance(const Scene& scene) : table_(scene.table) {
  for (const auto& o : scene.objects) {
    const TriangleMesh m = loadValidMesh(o.info.mesh_file);
    Object obj;
    for (const auto& f : m.faces) {
      obj.a.push_back(o.T_base_object * m.vertices[f[0]].cast<double>());
      obj.b.push_back(o.T_base_object * m.vertices[f[1]].cast<double>());
      obj.c.push_back(o.T_base_object * m.vertices[f[2]].cast<double>());
      obj.box.extend(obj.a.back());
      obj.box.extend(obj.b.back());
      obj.box.extend(obj.c.back());
    }
    objects_.push_back(std::move(obj));
  }
}

double SurfaceDistance::operator()(const Eigen::Vector3d& p) const { return nearest(p, nullptr); }

double SurfaceDistance::nearest(const Eigen::Vector3d& p, int* object) const {
  double best = std::numeric_limits<double>::infinity();
  int which = -1;
  const Eigen::Vector2d rel = p.head<2>() - table_.center;
  if (std::abs(rel.x()) <= table_.size.x() / 2 && std::abs(rel.y()) <= table_.size.y() / 2) {
    best = std::abs(p.z() - table_.z);
  }
  for (size_t k = 0; k < objects_.size(); ++k) {
    const Object& o = objects_[k];
    if (o.box.exteriorDistance(p) >= best) continue;
    for (size_t i = 0; i < o.a.size(); ++i) {
      const double d = pointTriangleDistance(p, o.a[i], o.b[i], o.c[i]);
      if (d < best) {
        best = d;
        which = static_cast<int>(k);
      }
    }
  }
  if (object) *object = which;
  return best;
}

SurfaceErrorStats SurfaceDistance::stats(const std::vector<Eigen::Vector3d>& points, std::vector<int>* on_object,
                                         double radius) const {
  SurfaceErrorStats s;
  std::vector<double> errs;
  errs.reserve(points.size());
  if (on_object) on_object->assign(points.size(), -1);
  for (size_t i = 0; i < points.size(); ++i) {
    int k = -1;
    errs.push_back(nearest(points[i], &k));
    if (on_object && errs.back() <= radius) (*on_object)[i] = k;
  }
  s.points = errs.size();
  if (errs.empty()) return s;
  double s2 = 0, s1 = 0;
  for (double e : errs) {
    s2 += e * e;
    s1 += e;
    s.max = std::max(s.max, e);
  }
  s.rms = std::sqrt(s2 / static_cast<double>(errs.size()));
  s.mean_abs = s1 / static_cast<double>(errs.size());
  std::nth_element(errs.begin(), errs.begin() + static_cast<long>(errs.size() * 99 / 100), errs.end());
  s.p99 = errs[errs.size() * 99 / 100];
  return s;
}

}  // namespace cellsight

namespace cellsight {

LineCentreErrors lineCentreErrors(const ScannerRenderer& renderer, const Eigen::Isometry3d& T_base_flange,
                                  const LineExtractionConfig& config, uint64_t seed) {
  const CameraConfig& cam = renderer.camera();
  const CameraIntrinsics& K = cam.intrinsics;
  const RayCaster& caster = renderer.geometry().caster();
  const Plane sheet = renderer.planeInCamera(T_base_flange);  // camera optical frame
  const Eigen::Isometry3d& T_base_camera = cam.T_base_camera;
  const Eigen::Vector3f origin = T_base_camera.translation().cast<float>();
  // f(u, v): signed distance (m) to the sheet of the surface point seen at pixel (u, v).
  auto f = [&](double u, double v, int& geometry) {
    const Eigen::Vector2d xy = K.undistortPixel({u, v});
    const Eigen::Vector3d d_cam = Eigen::Vector3d(xy.x(), xy.y(), 1.0).normalized();
    const RayHit h = caster.intersect(origin, (T_base_camera.linear() * d_cam).cast<float>());
    geometry = h.hit ? h.geometry : -1;
    return h.hit ? sheet.distance(d_cam * static_cast<double>(h.t)) : 0.0;
  };
  const cv::Mat img = renderer.render(T_base_flange, seed);
  LineExtractionConfig c = config;
  c.line_along_rows = lineAlongRows(sheet);  // the column methods search across the trace, as the node does
  const auto pts = extractLine(img, c);
  const cv::Mat clean = renderer.renderLaserOnly(T_base_flange);
  LineCentreErrors e;
  e.centres = pts.size();
  double s2 = 0, s1 = 0;
  std::vector<double> errs;
  for (const auto& p : pts) {
    const int iu = static_cast<int>(std::lround(p.u)), iv = static_cast<int>(std::lround(p.v));
    if (iu < 0 || iv < 0 || iu >= clean.cols || iv >= clean.rows || clean.at<float>(iv, iu) < 20.f) continue;
    int g0, g1, g2, g3, g4;
    const double f0 = f(p.u, p.v, g0);
    const double fx = (f(p.u + 0.5, p.v, g1) - f(p.u - 0.5, p.v, g2));
    const double fy = (f(p.u, p.v + 0.5, g3) - f(p.u, p.v - 0.5, g4));
    if (g0 < 0 || g1 != g0 || g2 != g0 || g3 != g0 || g4 != g0) continue;
    const double grad = std::hypot(fx, fy);
    if (!(grad > 0)) continue;
    const double err = std::abs(f0 / grad);
    int h1, h2, h3, h4;
    f(p.u + 3, p.v, h1);
    f(p.u - 3, p.v, h2);
    f(p.u, p.v + 3, h3);
    f(p.u, p.v - 3, h4);
    if (h1 == g0 && h2 == g0 && h3 == g0 && h4 == g0) {
      e.interior_rms_px += err * err;
      ++e.interior_points;
    }
    s2 += err * err;
    s1 += err;
    e.max_px = std::max(e.max_px, err);
    errs.push_back(err);
    ++e.points;
  }
  if (e.interior_points) e.interior_rms_px = std::sqrt(e.interior_rms_px / static_cast<double>(e.interior_points));
  if (e.points) {
    e.rms_px = std::sqrt(s2 / static_cast<double>(e.points));
    e.mean_px = s1 / static_cast<double>(e.points);
    const auto k = errs.begin() + static_cast<long>(errs.size() * 95 / 100);
    std::nth_element(errs.begin(), k, errs.end());
    e.p95_px = *k;
  }
  cv::Mat clean8;
  clean.convertTo(clean8, CV_8U);
  LineCoverageRule rule;
  rule.min_contrast = 20;
  rule.background = 0;
  rule.smooth_sigma = 0;
  const LineCoverage cov = lineCoverage(clean8, pts, rule);
  e.coverage = cov.coverage();
  e.false_share = cov.falseShare();
  return e;
}

LineCoverage lineCoverage(const cv::Mat& mono, const std::vector<LinePoint>& centres, const LineCoverageRule& rule) {
  if (mono.empty() || mono.type() != CV_8UC1) throw std::invalid_argument("lineCoverage: needs a CV_8UC1 image");
  if (rule.max_width < 1 || rule.max_width > std::min(mono.cols, mono.rows)) {
    throw std::invalid_argument("lineCoverage: max_width must lie in [1, the image's smaller side]");
  }
  if (!(rule.tolerance_px >= 0 && rule.tolerance_px <= 100)) {
    throw std::invalid_argument("lineCoverage: tolerance_px must lie in [0, 100]");
  }
  cv::Mat sm;
  if (rule.smooth_sigma > 0) cv::GaussianBlur(mono, sm, cv::Size(), rule.smooth_sigma);
  else sm = mono.clone();  // the top-hat below works in place
  cv::Mat glow;  // lit areas wider than a line (the opening keeps them, drops lines), widened
  if (rule.skip_lit_areas) {
    const int k = 2 * rule.max_width + 1;
    cv::Mat base;
    cv::morphologyEx(sm, base, cv::MORPH_OPEN, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(k, k)));
    cv::compare(base, (rule.background >= 0 ? rule.background : 0) + 0.5 * rule.min_contrast, glow, cv::CMP_GE);
    cv::dilate(glow, glow, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(k, k)));
  }
  double bg = rule.background;
  if (bg < 0) {
    // Local background: a white top-hat keeps what is narrower than the element (a line) and
    // removes what is wider (a glow, a lit area).
    const int k = 2 * rule.max_width + 1;
    cv::morphologyEx(sm, sm, cv::MORPH_TOPHAT, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(k, k)));
    bg = 0;
  }
  const double T = bg + rule.min_contrast;
  LineCoverage out;
  out.mask = cv::Mat::zeros(mono.size(), CV_8UC1);
  out.missed = cv::Mat::zeros(mono.size(), CV_8UC1);
  cv::Mat lit;  // a centre near a pixel at half the contrast or more is not counted as false
  cv::compare(sm, bg + 0.5 * rule.min_contrast, lit, cv::CMP_GE);
  // Centres by pixel row and column, for the "is there a centre in this run" test.
  const int W = mono.cols, H = mono.rows;
  std::vector<std::vector<float>> by_col(static_cast<size_t>(W)), by_row(static_cast<size_t>(H));
  // A centre serves the crossings of its own and the neighbouring columns and rows (a line at a
  // slant gets one centre per pixel it passes, not one per row and one per column).
  for (const auto& p : centres) {
    if (!std::isfinite(p.u) || !std::isfinite(p.v)) continue;
    const long u = std::lround(p.u), v = std::lround(p.v);
    for (long d = -1; d <= 1; ++d) {
      if (u + d >= 0 && u + d < W) by_col[static_cast<size_t>(u + d)].push_back(p.v);
      if (v + d >= 0 && v + d < H) by_row[static_cast<size_t>(v + d)].push_back(p.u);
    }
  }
  const double tol = rule.tolerance_px;
  auto runs = [&](bool transpose, auto on_run) {
    const int n_lines = transpose ? H : W, len = transpose ? W : H;
    for (int i = 0; i < n_lines; ++i) {
      auto value = [&](int j) { return transpose ? sm.at<uint8_t>(i, j) : sm.at<uint8_t>(j, i); };
      int j = 0;
      while (j < len) {
        if (value(j) < T) {
          ++j;
          continue;
        }
        int k = j;
        while (k + 1 < len && value(k + 1) >= T) ++k;
        if (k - j + 1 <= rule.max_width) on_run(i, j, k);
        j = k + 1;
      }
    }
  };
  // Run length through a pixel along the other direction (above the threshold).
  auto across = [&](bool transpose, int i, int m) {
    const int y = transpose ? i : m, x = transpose ? m : i;  // the pixel
    int a = 0, b = 0;
    if (transpose) {  // a row run: measure down the column
      while (y - a - 1 >= 0 && sm.at<uint8_t>(y - a - 1, x) >= T) ++a;
      while (y + b + 1 < H && sm.at<uint8_t>(y + b + 1, x) >= T) ++b;
    } else {
      while (x - a - 1 >= 0 && sm.at<uint8_t>(y, x - a - 1) >= T) ++a;
      while (x + b + 1 < W && sm.at<uint8_t>(y, x + b + 1) >= T) ++b;
    }
    return a + b + 1;
  };
  for (bool t : {false, true}) {
    const auto& on = t ? by_row : by_col;
    runs(t, [&](int i, int j, int k) {
      const int mid = (j + k) / 2;
      if (!glow.empty() && (t ? glow.at<uint8_t>(i, mid) : glow.at<uint8_t>(mid, i))) return;
      // A crossing runs across the line: not longer than the run the other way through its
      // middle, and the line goes on through that middle both ways (a run along a thin line,
      // split by speckle, or a fringe along its edge, is not a crossing).
      if (k - j + 1 > across(t, i, mid)) return;
      if (i == 0 || i + 1 >= (t ? H : W)) return;
      const uint8_t before = t ? sm.at<uint8_t>(i - 1, mid) : sm.at<uint8_t>(mid, i - 1);
      const uint8_t after = t ? sm.at<uint8_t>(i + 1, mid) : sm.at<uint8_t>(mid, i + 1);
      if (before < T || after < T) return;
      ++out.crossings;
      const auto& cs = on[static_cast<size_t>(i)];
      const bool hit = std::any_of(cs.begin(), cs.end(), [&](float c) { return c >= j - tol && c <= k + tol; });
      if (hit) ++out.covered;
      for (int m = j; m <= k; ++m) {
        (t ? out.mask.at<uint8_t>(i, m) : out.mask.at<uint8_t>(m, i)) = 255;
        if (!hit) (t ? out.missed.at<uint8_t>(i, m) : out.missed.at<uint8_t>(m, i)) = 255;
      }
    });
  }
  cv::Mat near;
  const int r = static_cast<int>(std::ceil(tol));
  cv::dilate(out.mask | lit, near, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * r + 1, 2 * r + 1)));
  for (const auto& p : centres) {
    ++out.centres;
    if (!std::isfinite(p.u) || !std::isfinite(p.v)) {
      ++out.false_centres;
      continue;
    }
    const long u = std::lround(p.u), v = std::lround(p.v);
    if (u < 0 || v < 0 || u >= W || v >= H || !near.at<uint8_t>(static_cast<int>(v), static_cast<int>(u))) ++out.false_centres;
  }
  return out;
}

}  // namespace cellsight
