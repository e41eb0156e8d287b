#include "cellsight/scanner/line_extraction.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "ridge_line.hpp"

namespace cellsight {

LineExtractionConfig::Estimator LineExtractionConfig::parseEstimator(const std::string& name) {
  if (name == "ridge" || name == "steger") return Estimator::kRidge;
  if (name == "run_centre" || name == "run_center" || name == "thesis") return Estimator::kRunCentre;
  if (name == "centroid" || name == "cog") return Estimator::kCentroid;
  if (name == "gaussian3" || name == "gaussian") return Estimator::kGaussian3;
  throw std::invalid_argument("unknown line estimator '" + name +
                              "' (use ridge, run_centre, centroid or gaussian3)");
}

const char* LineExtractionConfig::estimatorName(Estimator e) {
  switch (e) {
    case Estimator::kRidge: return "ridge";
    case Estimator::kRunCentre: return "run_centre";
    case Estimator::kCentroid: return "centroid";
    case Estimator::kGaussian3: return "gaussian3";
  }
  return "?";
}

double detail::backgroundLevel(const cv::Mat& img, double percentile) {
  // Histogram of every 2nd pixel of every 16th row: the line covers well under 2 % of the pixels.
  uint32_t hist[256] = {0};
  uint32_t n = 0;
  for (int v = 0; v < img.rows; v += 16) {
    const uint8_t* r = img.ptr<uint8_t>(v);
    for (int u = 0; u < img.cols; u += 2) ++hist[r[u]];
    n += static_cast<uint32_t>((img.cols + 1) / 2);
  }
  const double target = percentile * n;
  double acc = 0;
  for (int g = 0; g < 256; ++g) {
    acc += hist[g];
    if (acc >= target) return g;
  }
  return 255;
}

namespace {

void dropEdges(std::vector<LinePoint>& pts, const LineExtractionConfig& c, int& dropped) {
  if (c.segment_erode <= 0 && c.min_segment <= 1) return;
  std::vector<LinePoint> kept;
  kept.reserve(pts.size());
  size_t start = 0;
  while (start < pts.size()) {
    size_t end = start + 1;
    while (end < pts.size() && pts[end].u - pts[end - 1].u <= 1.5f &&
           std::abs(pts[end].v - pts[end - 1].v) <= c.segment_max_jump)
      ++end;
    const size_t n = end - start, e = static_cast<size_t>(std::max(0, c.segment_erode));
    if (n >= static_cast<size_t>(std::max(1, c.min_segment)) && n > 2 * e) {
      const int id = kept.empty() ? 0 : kept.back().segment + 1;
      for (size_t i = start + e; i < end - e; ++i) {
        kept.push_back(pts[i]);
        kept.back().segment = id;
      }
    }
    start = end;
  }
  dropped += static_cast<int>(pts.size() - kept.size());
  pts.swap(kept);
}

/// Local polynomial fit of degree `deg` to (x_k, y_k), evaluated at x = 0.
float localFit(const std::vector<LinePoint>& pts, long lo, long hi, size_t i, int deg, double scale) {
  Eigen::Matrix4d AtA = Eigen::Matrix4d::Zero();
  Eigen::Vector4d Atb = Eigen::Vector4d::Zero();
  for (long k = lo; k <= hi; ++k) {
    const double x = (pts[static_cast<size_t>(k)].u - pts[i].u) / scale;
    Eigen::Vector4d phi(1, x, x * x, x * x * x);
    for (int d = deg + 1; d < 4; ++d) phi[d] = 0;
    AtA += phi * phi.transpose();
    Atb += phi * pts[static_cast<size_t>(k)].v;
  }
  for (int d = deg + 1; d < 4; ++d) AtA(d, d) = 1;
  return static_cast<float>(AtA.ldlt().solve(Atb)(0));
}

void smooth(std::vector<LinePoint>& pts, const LineExtractionConfig& c) {
  if (c.smoothing_degree <= 0 || pts.size() < 3) return;
  const int h = c.smoothing_half_window;
  const int deg = std::min(c.smoothing_degree, 3);
  // Savitzky–Golay weights for a full window of unit-spaced columns.
  std::vector<double> sg(static_cast<size_t>(2 * h + 1));
  {
    Eigen::MatrixXd A(2 * h + 1, deg + 1);
    for (int k = -h; k <= h; ++k) {
      double p = 1;
      for (int d = 0; d <= deg; ++d, p *= k / (h + 1.0)) A(k + h, d) = p;
    }
    const Eigen::MatrixXd P = (A.transpose() * A).ldlt().solve(A.transpose());
    for (int k = 0; k <= 2 * h; ++k) sg[static_cast<size_t>(k)] = P(0, k);
  }
  std::vector<float> out(pts.size());
  size_t start = 0;
  while (start < pts.size()) {
    size_t end = start + 1;
    while (end < pts.size() && pts[end].u - pts[end - 1].u <= 1.5f &&
           std::abs(pts[end].v - pts[end - 1].v) <= c.smoothing_max_jump)
      ++end;
    for (size_t i = start; i < end; ++i) {
      const long lo = std::max<long>(static_cast<long>(start), static_cast<long>(i) - h);
      const long hi = std::min<long>(static_cast<long>(end) - 1, static_cast<long>(i) + h);
      const bool full = hi - lo == 2 * h && pts[static_cast<size_t>(hi)].u - pts[static_cast<size_t>(lo)].u == 2.f * h;
      if (full) {
        double acc = 0;
        for (long k = lo; k <= hi; ++k) acc += sg[static_cast<size_t>(k - lo)] * pts[static_cast<size_t>(k)].v;
        out[i] = static_cast<float>(acc);
      } else if (hi - lo >= 1) {
        out[i] = localFit(pts, lo, hi, i, std::min<int>(deg, static_cast<int>(hi - lo)), h + 1.0);
      } else {
        out[i] = pts[i].v;
      }
    }
    start = end;
  }
  for (size_t i = 0; i < pts.size(); ++i) pts[i].v = out[i];
}

}  // namespace

std::vector<LinePoint> extractLine(const cv::Mat& image, const LineExtractionConfig& c,
                                   LineExtractionStats* stats_out) {
  if (image.empty()) throw std::invalid_argument("extractLine: empty image");
  cv::Mat img;
  if (image.type() == CV_8UC1) {
    if (c.channel > 0) throw std::invalid_argument("extractLine: mono image has no channel " + std::to_string(c.channel));
    img = image;
  } else if (image.type() == CV_8UC3) {
    if (c.channel < 0 || c.channel > 2) {
      throw std::invalid_argument("extractLine: colour image needs channel 0, 1 or 2 (RGB)");
    }
    cv::extractChannel(image, img, c.channel);
  } else {
    throw std::invalid_argument("extractLine: image must be 8-bit mono or 3-channel");
  }
  LineExtractionStats st;
  if (c.estimator == LineExtractionConfig::Estimator::kRidge) {
    st.background = detail::backgroundLevel(img, c.background_percentile);
    auto pts = detail::extractRidge(img, c, st);
    st.found = static_cast<int>(pts.size());
    if (stats_out) *stats_out = st;
    return pts;
  }
  if (!c.line_along_rows) img = img.t();
  st.background = detail::backgroundLevel(img, c.background_percentile);
  const int W = img.cols, H = img.rows;
  const float bg = static_cast<float>(st.background);
  // Pass 1 (row-major, cache friendly, branch-free so the compiler vectorises it): per-column
  // maximum and the first row where it occurs.
  // Also the maximum of every block of kBlock rows, for the secondary-peak test below.
  constexpr int kBlock = 8;
  const int nblocks = (H + kBlock - 1) / kBlock;
  std::vector<uint16_t> mx(static_cast<size_t>(W), 0);
  std::vector<uint16_t> am(static_cast<size_t>(W), 0);
  std::vector<uint8_t> bmax(static_cast<size_t>(nblocks) * W, 0);
  {
    uint16_t* __restrict m = mx.data();
    uint16_t* __restrict a = am.data();
    for (int v = 0; v < H; ++v) {
      const uint8_t* __restrict r = img.ptr<uint8_t>(v);
      uint8_t* __restrict bm = bmax.data() + static_cast<size_t>(v / kBlock) * W;
      const uint16_t vv = static_cast<uint16_t>(v);
      for (int u = 0; u < W; ++u) {
        const uint16_t x = r[u];
        const bool gt = x > m[u];
        m[u] = gt ? x : m[u];
        a[u] = gt ? vv : a[u];
        bm[u] = r[u] > bm[u] ? r[u] : bm[u];
      }
    }
  }
  // Runs around each peak (column walks of a few pixels).
  std::vector<int> run_lo(static_cast<size_t>(W), -1), run_hi(static_cast<size_t>(W), -1);
  std::vector<float> thr(static_cast<size_t>(W), 0.f);
  const size_t step = img.step;
  const uint8_t* data = img.data;
  auto at = [&](int v, int u) { return static_cast<float>(data[static_cast<size_t>(v) * step + u]); };
  for (int u = 0; u < W; ++u) {
    ++st.scanned;
    const float peak = mx[u];
    if (peak < bg + c.min_contrast) {
      ++st.no_line;
      continue;
    }
    const float t = bg + static_cast<float>(c.threshold_fraction) * (peak - bg);
    int a = am[u], b = am[u];
    while (a > 0 && at(a - 1, u) >= t) --a;
    while (b < H - 1 && at(b + 1, u) >= t) ++b;
    if (b - a + 1 > c.max_run) {
      ++st.too_wide;
      continue;
    }
    run_lo[u] = a;
    run_hi[u] = b;
    thr[u] = t;
  }
  // Secondary peaks (reflections): the strongest pixel outside each column's run ± gap, from
  // the block maxima; only blocks that touch the window are read pixel by pixel.
  if (c.secondary_peak_ratio > 0) {
    const int gap = c.secondary_peak_gap;
    for (int u = 0; u < W; ++u) {
      if (run_lo[u] < 0) continue;
      const int lo = run_lo[u] - gap, hi = run_hi[u] + gap;
      int second = 0;
      for (int b = 0; b < nblocks; ++b) {
        const int r0 = b * kBlock, r1 = std::min(H - 1, r0 + kBlock - 1);
        if (r1 < lo || r0 > hi) {
          second = std::max<int>(second, bmax[static_cast<size_t>(b) * W + u]);
        } else {
          for (int v = r0; v <= r1; ++v) {
            if (v < lo || v > hi) second = std::max(second, static_cast<int>(at(v, u)));
          }
        }
      }
      if (second - bg >= c.secondary_peak_ratio * (mx[u] - bg)) {
        run_lo[u] = -1;
        ++st.ambiguous;
      }
    }
  }
  std::vector<LinePoint> pts;
  pts.reserve(static_cast<size_t>(W));
  for (int u = 0; u < W; ++u) {
    const int a = run_lo[u], b = run_hi[u];
    if (a < 0) continue;
    const float t = thr[u];
    const float peak = mx[u];
    float v = 0;
    switch (c.estimator) {
      case LineExtractionConfig::Estimator::kRunCentre: {
        // Threshold crossings interpolated linearly on both flanks.
        float lo = static_cast<float>(a), hi = static_cast<float>(b);
        if (a > 0) {
          const float i0 = at(a - 1, u), i1 = at(a, u);
          if (i1 > i0) lo = a - (i1 - t) / (i1 - i0);
        }
        if (b < H - 1) {
          const float i0 = at(b + 1, u), i1 = at(b, u);
          if (i1 > i0) hi = b + (i1 - t) / (i1 - i0);
        }
        v = 0.5f * (lo + hi);
        break;
      }
      case LineExtractionConfig::Estimator::kCentroid: {
        const int lo = std::max(0, a - c.centroid_margin), hi = std::min(H - 1, b + c.centroid_margin);
        float s = 0, sv = 0;
        const float floor = bg + static_cast<float>(c.centroid_floor) * (peak - bg);
        for (int k = lo; k <= hi; ++k) {
          const float w = std::max(0.f, at(k, u) - floor);
          s += w;
          sv += w * k;
        }
        v = s > 0 ? sv / s : 0.5f * (a + b);
        break;
      }
      case LineExtractionConfig::Estimator::kRidge:  // handled above
      case LineExtractionConfig::Estimator::kGaussian3: {
        const int p = am[u];
        if (peak >= 255.f || p == 0 || p == H - 1) {
          v = 0.5f * (a + b);  // saturated plateau or border: centre of the run
          break;
        }
        const float l0 = std::log(std::max(1.f, at(p - 1, u) - bg));
        const float l1 = std::log(std::max(1.f, at(p, u) - bg));
        const float l2 = std::log(std::max(1.f, at(p + 1, u) - bg));
        const float den = l0 - 2 * l1 + l2;
        v = p + (den < 0 ? std::clamp(0.5f * (l0 - l2) / den, -0.5f, 0.5f) : 0.f);
        break;
      }
    }
    if (peak >= 255.f) ++st.saturated;
    LinePoint lp;
    lp.u = static_cast<float>(u);
    lp.v = v;
    lp.peak = peak - bg;
    lp.width = static_cast<float>(b - a + 1);
    pts.push_back(lp);
  }
  dropEdges(pts, c, st.edge);
  smooth(pts, c);
  st.found = static_cast<int>(pts.size());
  if (!c.line_along_rows) {
    for (auto& p : pts) {
      std::swap(p.u, p.v);
      std::swap(p.nx, p.ny);
    }
  }
  if (!pts.empty()) st.segments = pts.back().segment + 1;
  if (stats_out) *stats_out = st;
  return pts;
}

}  // namespace cellsight
