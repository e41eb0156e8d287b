// Orientation-free laser-line centres (Steger, "An unbiased detector of curvilinear structures",
// PAMI 1998), done sparsely so a 2 MP frame stays within the budget of the column methods:
//  1. candidates: pixels above background + min_contrast that are a (non-strict) maximum across
//     at least one of the four pixel directions — the crest of any line, whatever its direction;
//  2. at each candidate the Gaussian derivatives up to second order (separable, evaluated only
//     there); the Hessian's dominant eigenvector is the line normal n; the centre is where the
//     derivative along n vanishes, accepted only inside the candidate's own pixel, so every
//     crossing of the line yields one point;
//  3. points linked into polylines by walking along the tangent to the nearest compatible
//     neighbour; polylines judged by length and width, eroded at both ends (mixed pixels at
//     depth edges) and smoothed across the line by a local polynomial in the polyline's frame.
#include "ridge_line.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace cellsight::detail {

namespace {

struct Kernels {
  int r = 0;
  std::vector<float> w0, w1, w2;  ///< correlation weights: smoothing, d/dx, d²/dx²
  /// The same from the centre out (w0, w2 even, w1 odd): e*[k] = w*[r + k], k = 0 … r.
  std::vector<float> e0, e1, e2;
};

Kernels makeKernels(double sigma) {
  Kernels k;
  k.r = std::max(1, static_cast<int>(std::ceil(3.0 * sigma)));
  const int n = 2 * k.r + 1;
  std::vector<double> g(static_cast<size_t>(n)), d1(static_cast<size_t>(n)), d2(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    const double x = i - k.r;
    g[static_cast<size_t>(i)] = std::exp(-x * x / (2 * sigma * sigma));
  }
  const double sg = std::accumulate(g.begin(), g.end(), 0.0);
  for (auto& v : g) v /= sg;
  // d1: exact on linear ramps (Σ x·w1 = 1); d2: zero on constants, exact on x² (Σ x²·w2 = 2).
  double s1 = 0, m2 = 0;
  for (int i = 0; i < n; ++i) {
    const double x = i - k.r;
    d1[static_cast<size_t>(i)] = x * g[static_cast<size_t>(i)];
    s1 += x * d1[static_cast<size_t>(i)];
    d2[static_cast<size_t>(i)] = (x * x / (sigma * sigma) - 1.0) * g[static_cast<size_t>(i)];
    m2 += d2[static_cast<size_t>(i)];
  }
  double s2 = 0;
  for (int i = 0; i < n; ++i) {
    const double x = i - k.r;
    d1[static_cast<size_t>(i)] /= s1;
    d2[static_cast<size_t>(i)] -= m2 * g[static_cast<size_t>(i)];  // Σ g = 1: removes the DC part
    s2 += x * x * d2[static_cast<size_t>(i)];
  }
  for (auto& v : d2) v *= 2.0 / s2;
  for (int i = 0; i < n; ++i) {
    k.w0.push_back(static_cast<float>(g[static_cast<size_t>(i)]));
    k.w1.push_back(static_cast<float>(d1[static_cast<size_t>(i)]));
    k.w2.push_back(static_cast<float>(d2[static_cast<size_t>(i)]));
  }
  for (int i = 0; i <= k.r; ++i) {
    k.e0.push_back(k.w0[static_cast<size_t>(k.r + i)]);
    k.e1.push_back(k.w1[static_cast<size_t>(k.r + i)]);
    k.e2.push_back(k.w2[static_cast<size_t>(k.r + i)]);
  }
  return k;
}

/// Bilinear grey level, clamped to the image.
float sample(const cv::Mat& img, float u, float v) {
  if (!std::isfinite(u) || !std::isfinite(v)) return 0.f;
  u = std::clamp(u, 0.f, static_cast<float>(img.cols - 1));
  v = std::clamp(v, 0.f, static_cast<float>(img.rows - 1));
  const int x = std::min(static_cast<int>(u), img.cols - 2), y = std::min(static_cast<int>(v), img.rows - 2);
  const float a = u - static_cast<float>(x), b = v - static_cast<float>(y);
  const uint8_t* r0 = img.ptr<uint8_t>(y);
  const uint8_t* r1 = img.ptr<uint8_t>(y + 1);
  return (1 - b) * ((1 - a) * r0[x] + a * r0[x + 1]) + b * ((1 - a) * r1[x] + a * r1[x + 1]);
}

struct RidgePoint {
  float u, v, nx, ny, strength, width;
  float peak;    ///< height of the smoothed profile above the mean of its two sides, grey levels
  float offset;  ///< how far (px, max norm) the centre lies from the pixel it was computed at
  int x, y;  ///< the pixel the centre lies in
};

/// Points sorted by (y, x) with a row index: which point, if any, sits in a pixel.
class PixelIndex {
 public:
  PixelIndex(const std::vector<RidgePoint>& pts, int height) : pts_(pts), row_(static_cast<size_t>(height) + 1, 0) {
    for (const auto& p : pts) ++row_[static_cast<size_t>(p.y) + 1];
    std::partial_sum(row_.begin(), row_.end(), row_.begin());
  }
  /// Calls f(index) for every point in the box [x0, x1] × [y0, y1].
  template <class F>
  void forBox(int x0, int x1, int y0, int y1, F&& f) const {
    y0 = std::max(y0, 0);
    y1 = std::min(y1, static_cast<int>(row_.size()) - 2);
    for (int y = y0; y <= y1; ++y) {
      const auto b = pts_.begin() + row_[static_cast<size_t>(y)], e = pts_.begin() + row_[static_cast<size_t>(y) + 1];
      auto it = std::lower_bound(b, e, x0, [](const RidgePoint& p, int x) { return p.x < x; });
      for (; it != e && it->x <= x1; ++it) f(static_cast<size_t>(it - pts_.begin()));
    }
  }

 private:
  const std::vector<RidgePoint>& pts_;
  std::vector<int> row_;
};

/// Shifts every point of a polyline across the line by a local polynomial fit of the normal
/// offsets of its neighbours (±h points) in the point's own (tangent, normal) frame.
void smoothPolyline(std::vector<RidgePoint>& poly, int degree, int h) {
  if (degree <= 0 || poly.size() < 3) return;
  degree = std::min(degree, 2);
  const std::vector<RidgePoint> src = poly;
  const long n = static_cast<long>(src.size());
  for (long i = 0; i < n; ++i) {
    const long lo = std::max(0L, i - h), hi = std::min(n - 1, i + h);
    const int deg = std::min<int>(degree, static_cast<int>(hi - lo) - 1);
    if (deg < 0) continue;
    const RidgePoint& pi = src[static_cast<size_t>(i)];
    const double tx = -pi.ny, ty = pi.nx;
    // Moments of a (along, scaled) and b (across): the normal equations of b = c0 + c1·a + c2·a².
    double S[5] = {0, 0, 0, 0, 0}, T[3] = {0, 0, 0};
    const double scale = h + 1.0;
    for (long k = lo; k <= hi; ++k) {
      const RidgePoint& pk = src[static_cast<size_t>(k)];
      const double du = pk.u - pi.u, dv = pk.v - pi.v;
      const double a = (du * tx + dv * ty) / scale, b = du * pi.nx + dv * pi.ny;
      const double a2 = a * a;
      S[0] += 1;
      S[1] += a;
      S[2] += a2;
      S[3] += a2 * a;
      S[4] += a2 * a2;
      T[0] += b;
      T[1] += b * a;
      T[2] += b * a2;
    }
    double c0 = std::numeric_limits<double>::quiet_NaN();
    if (deg >= 2) {  // Cramer's rule for c0 of the 3 × 3 system
      auto det3 = [](double a, double b, double c, double d, double e, double f, double g, double hh, double k) {
        return a * (e * k - f * hh) - b * (d * k - f * g) + c * (d * hh - e * g);
      };
      const double D = det3(S[0], S[1], S[2], S[1], S[2], S[3], S[2], S[3], S[4]);
      if (std::abs(D) > 1e-12) c0 = det3(T[0], S[1], S[2], T[1], S[2], S[3], T[2], S[3], S[4]) / D;
    }
    if (!std::isfinite(c0) && deg >= 1) {
      const double D = S[0] * S[2] - S[1] * S[1];
      if (std::abs(D) > 1e-12) c0 = (T[0] * S[2] - S[1] * T[1]) / D;
    }
    if (!std::isfinite(c0)) c0 = T[0] / S[0];
    poly[static_cast<size_t>(i)].u = static_cast<float>(pi.u + c0 * pi.nx);
    poly[static_cast<size_t>(i)].v = static_cast<float>(pi.v + c0 * pi.ny);
  }
}

}  // namespace

std::vector<LinePoint> extractRidge(const cv::Mat& img, const LineExtractionConfig& c, LineExtractionStats& st) {
  const Kernels K = makeKernels(c.ridge_sigma);
  const int r = K.r, n = 2 * r + 1, W = img.cols, H = img.rows;
  const float bg = static_cast<float>(st.background);
  // Hysteresis: candidates from half the contrast, a polyline needs one crest at full contrast.
  const double T_level = std::ceil(bg + 0.5 * c.min_contrast);
  if (!(T_level <= 255)) return {};  // no pixel can reach it (also a NaN or huge min_contrast)
  const int T = static_cast<int>(T_level);
  const float min_strength = static_cast<float>(0.25 * c.min_contrast);
  const float low_contrast = static_cast<float>(0.5 * c.min_contrast);
  std::vector<RidgePoint> pts;
  if (T > 255 || W <= 2 * r + 2 || H <= 2 * r + 2) return {};
  const uint8_t thr = static_cast<uint8_t>(std::max(T, 0));
  std::vector<float> h0(static_cast<size_t>(n)), h1(static_cast<size_t>(n)), h2(static_cast<size_t>(n));
  const size_t step = img.step;
  constexpr int kChunk = 32;
  for (int y = r; y < H - r; ++y) {
    const uint8_t* row = img.ptr<uint8_t>(y);
    for (int x0 = r; x0 < W - r; x0 += kChunk) {
      const int x1 = std::min(W - r, x0 + kChunk);
      uint8_t m = 0;
      for (int x = x0; x < x1; ++x) m = row[x] > m ? row[x] : m;  // vectorised: skips dark chunks
      if (m < thr) continue;
      for (int x = x0; x < x1; ++x) {
        const uint8_t p = row[x];
        if (p < thr) continue;
        const uint8_t* up = row - step;
        const uint8_t* dn = row + step;
        const bool crest = (p >= row[x - 1] && p >= row[x + 1]) || (p >= up[x] && p >= dn[x]) ||
                           (p >= up[x - 1] && p >= dn[x + 1]) || (p >= up[x + 1] && p >= dn[x - 1]);
        if (!crest) continue;
        ++st.scanned;
        // Separable Gaussian derivatives at (x, y): rows first, then down the column; the
        // kernels' symmetry halves the products (sums and differences of mirrored pixels).
        const float* e0 = K.e0.data();
        const float* e1 = K.e1.data();
        const float* e2 = K.e2.data();
        for (int j = 0; j < n; ++j) {
          const uint8_t* q = img.ptr<uint8_t>(y - r + j) + x;
          const float c0 = q[0];
          float a0 = e0[0] * c0, a1 = 0, a2 = e2[0] * c0;
          for (int k = 1; k <= r; ++k) {
            const float sum = static_cast<float>(q[k] + q[-k]), dif = static_cast<float>(q[k] - q[-k]);
            a0 += e0[k] * sum;
            a1 += e1[k] * dif;
            a2 += e2[k] * sum;
          }
          h0[static_cast<size_t>(j)] = a0;
          h1[static_cast<size_t>(j)] = a1;
          h2[static_cast<size_t>(j)] = a2;
        }
        const float* H0 = h0.data() + r;
        const float* H1 = h1.data() + r;
        const float* H2 = h2.data() + r;
        float g = e0[0] * H0[0], gx = e0[0] * H1[0], gxx = e0[0] * H2[0], gy = 0, gxy = 0, gyy = e2[0] * H0[0];
        for (int k = 1; k <= r; ++k) {
          g += e0[k] * (H0[k] + H0[-k]);
          gx += e0[k] * (H1[k] + H1[-k]);
          gxx += e0[k] * (H2[k] + H2[-k]);
          gy += e1[k] * (H0[k] - H0[-k]);
          gxy += e1[k] * (H1[k] - H1[-k]);
          gyy += e2[k] * (H0[k] + H0[-k]);
        }
        const float G = g - bg;
        const float mean = 0.5f * (gxx + gyy), dev = std::sqrt(0.25f * (gxx - gyy) * (gxx - gyy) + gxy * gxy);
        const float l1 = mean - dev, l2 = mean + dev;  // l1: the most negative (across a bright line)
        if (!(G >= min_strength) || !(l1 < 0) || !(l2 > static_cast<float>(c.ridge_max_isotropy) * l1)) {
          ++st.not_ridge;
          continue;
        }
        float nx = gxy, ny = l1 - gxx;
        const float ax = l1 - gyy, ay = gxy;
        if (ax * ax + ay * ay > nx * nx + ny * ny) {
          nx = ax;
          ny = ay;
        }
        const float norm = std::sqrt(nx * nx + ny * ny);
        if (norm > 1e-12f) {
          nx /= norm;
          ny /= norm;
        } else if (gxx <= gyy) {
          nx = 1;
          ny = 0;
        } else {
          nx = 0;
          ny = 1;
        }
        const float gn = gx * nx + gy * ny;
        const float den = l1 * G - gn * gn;  // < 0 on a ridge
        if (!(den < 0) || !(G > 0)) {
          ++st.not_ridge;
          continue;
        }
        const float t = c.ridge_gaussian_profile ? -gn * G / den : -gn / l1;
        const float px = t * nx, py = t * ny;
        // Up to one pixel away: noise may make the neighbour of the centre's pixel the crest.
        // The point belongs to the pixel its centre lies in; duplicates are resolved below.
        if (!(std::abs(px) <= 1.0f && std::abs(py) <= 1.0f)) {
          ++st.not_ridge;
          continue;
        }
        const float S2 = -G * G / den;  // total profile variance (line ⊗ smoothing), log-curvature
        const float s2 = S2 - static_cast<float>(c.ridge_sigma * c.ridge_sigma);
        // Contrast against the line's own surroundings (a glow or a lit surface raises both):
        // the smoothed centre minus the mean of the image 2.5 profile σ out on both sides.
        const float cu = static_cast<float>(x) + px, cv_ = static_cast<float>(y) + py;
        const float d = std::clamp(2.5f * std::sqrt(std::max(S2, 1.f)), 2.f, 30.f);
        const float side = 0.5f * (sample(img, cu + d * nx, cv_ + d * ny) + sample(img, cu - d * nx, cv_ - d * ny));
        const float contrast = g + 0.5f * gn * t - side;
        if (!(contrast >= low_contrast)) {
          ++st.not_ridge;
          continue;
        }
        RidgePoint rp;
        rp.u = static_cast<float>(x) + px;
        rp.v = static_cast<float>(y) + py;
        rp.nx = nx;
        rp.ny = ny;
        rp.strength = G;
        rp.peak = contrast;
        rp.width = 2.3548f * std::sqrt(std::max(0.f, s2));
        rp.x = static_cast<int>(std::lround(rp.u));
        rp.y = static_cast<int>(std::lround(rp.v));
        rp.offset = std::max(std::abs(px), std::abs(py));
        pts.push_back(rp);
      }
    }
  }

  // One point per pixel: the one computed closest to it.
  std::sort(pts.begin(), pts.end(), [](const RidgePoint& a, const RidgePoint& b) {
    return a.y != b.y ? a.y < b.y : a.x != b.x ? a.x < b.x : a.offset < b.offset;
  });
  pts.erase(std::unique(pts.begin(), pts.end(), [](const RidgePoint& a, const RidgePoint& b) { return a.x == b.x && a.y == b.y; }),
            pts.end());
  pts.erase(std::remove_if(pts.begin(), pts.end(), [&](const RidgePoint& a) { return a.x < 0 || a.y < 0 || a.x >= W || a.y >= H; }),
            pts.end());

  // Linking: strongest unvisited point first, walk both ways along the tangent.
  const PixelIndex index(pts, H);
  std::vector<uint8_t> used(pts.size(), 0);
  std::vector<size_t> order(pts.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return pts[a].strength > pts[b].strength; });
  const int R = static_cast<int>(std::ceil(c.link_max_gap));
  const float max_gap2 = static_cast<float>(c.link_max_gap * c.link_max_gap);
  const float min_cos = static_cast<float>(std::cos(c.link_max_angle));
  auto suppressBeside = [&](size_t i) {  // other centres of the same cross-section
    const RidgePoint& p = pts[i];
    index.forBox(p.x - 1, p.x + 1, p.y - 1, p.y + 1, [&](size_t q) {
      if (used[q]) return;
      const float du = pts[q].u - p.u, dv = pts[q].v - p.v;
      if (std::abs(-du * p.ny + dv * p.nx) < 0.7f) used[q] = 1;
    });
  };
  std::vector<LinePoint> out;
  out.reserve(pts.size());
  std::vector<RidgePoint> poly, back;
  std::vector<std::vector<RidgePoint>> polylines;
  for (size_t seed : order) {
    if (used[seed]) continue;
    used[seed] = 1;
    suppressBeside(seed);
    poly.assign(1, pts[seed]);
    back.clear();
    for (int dir = 0; dir < 2; ++dir) {
      size_t cur = seed;
      float tx = -pts[seed].ny, ty = pts[seed].nx;
      if (dir == 1) {
        tx = -tx;
        ty = -ty;
      }
      while (true) {
        const RidgePoint& p = pts[cur];
        size_t best = pts.size();
        float best_cost = 1e30f, btx = 0, bty = 0;
        index.forBox(p.x - R, p.x + R, p.y - R, p.y + R, [&](size_t q) {
          if (used[q]) return;
          const float du = pts[q].u - p.u, dv = pts[q].v - p.v;
          const float d2 = du * du + dv * dv;
          const float along = du * tx + dv * ty;
          if (d2 > max_gap2 || along <= 0.3f) return;
          float qtx = -pts[q].ny, qty = pts[q].nx;
          float cosang = qtx * tx + qty * ty;
          if (cosang < 0) {
            cosang = -cosang;
            qtx = -qtx;
            qty = -qty;
          }
          if (cosang < min_cos) return;
          const float lateral = std::abs(du * p.nx + dv * p.ny);
          const float cost = std::sqrt(d2) + 2.f * lateral + 4.f * (1.f - cosang);
          if (cost < best_cost) {
            best_cost = cost;
            best = q;
            btx = qtx;
            bty = qty;
          }
        });
        if (best == pts.size()) break;
        used[best] = 1;
        suppressBeside(best);
        (dir == 0 ? poly : back).push_back(pts[best]);
        cur = best;
        tx = btx;
        ty = bty;
      }
    }
    if (!back.empty()) poly.insert(poly.begin(), back.rbegin(), back.rend());
    polylines.push_back(poly);
  }
  // Which polyline each centre ended up in, for the end test below.
  std::vector<int> owner(pts.size(), -1);
  {
    size_t k = 0;
    for (const auto& pl : polylines) {
      for (const auto& q : pl) {
        // pts is sorted by pixel and has one point per pixel: find it.
        index.forBox(q.x, q.x, q.y, q.y, [&](size_t i) { owner[i] = static_cast<int>(k); });
      }
      ++k;
    }
  }
  // An end that meets another polyline within a few pixels is a corner or a junction of one
  // surface's trace, not a depth edge: it keeps its centres.
  const int J = static_cast<int>(std::ceil(c.link_max_gap + 1.0));
  // Judge every polyline first: long enough, bright enough, a line rather than a lit area.
  std::vector<uint8_t> kept(polylines.size(), 0);
  for (size_t k = 0; k < polylines.size(); ++k) {
    const auto& poly = polylines[k];
    std::vector<float> widths;
    widths.reserve(poly.size());
    float peak = 0;
    for (const auto& q : poly) {
      widths.push_back(q.width);
      peak = std::max(peak, q.peak);
    }
    std::nth_element(widths.begin(), widths.begin() + static_cast<long>(widths.size() / 2), widths.end());
    if (peak < static_cast<float>(c.min_contrast)) {
      st.no_line += static_cast<int>(poly.size());
    } else if (widths[widths.size() / 2] > static_cast<float>(c.max_run)) {
      st.too_wide += static_cast<int>(poly.size());
    } else if (poly.size() < static_cast<size_t>(std::max(1, c.min_segment))) {
      st.edge += static_cast<int>(poly.size());
    } else {
      kept[k] = 1;
    }
  }
  auto joined = [&](const RidgePoint& end, size_t self) {
    bool found = false;
    index.forBox(end.x - J, end.x + J, end.y - J, end.y + J, [&](size_t i) {
      if (owner[i] >= 0 && static_cast<size_t>(owner[i]) != self && kept[static_cast<size_t>(owner[i])] &&
          std::hypot(pts[i].u - end.u, pts[i].v - end.v) <= static_cast<float>(J))
        found = true;
    });
    return found;
  };
  // The Gaussian derivatives reach past a polyline's free end (a depth edge, the fan's end): the
  // centres within σ of it are biased, so they go too.
  const size_t e = c.segment_erode <= 0
                       ? 0
                       : static_cast<size_t>(c.segment_erode) + static_cast<size_t>(std::ceil(c.ridge_sigma));
  std::vector<std::pair<size_t, size_t>> erosion(polylines.size(), {0, 0});  // decided before any is cut
  for (size_t k = 0; k < polylines.size(); ++k) {
    if (kept[k]) erosion[k] = {joined(polylines[k].front(), k) ? 0 : e, joined(polylines[k].back(), k) ? 0 : e};
  }
  int segment = 0;
  for (size_t k = 0; k < polylines.size(); ++k) {
    if (!kept[k]) continue;
    std::vector<RidgePoint>& poly = polylines[k];
    const auto [e_front, e_back] = erosion[k];
    if (poly.size() <= e_front + e_back) {
      st.edge += static_cast<int>(poly.size());
      continue;
    }
    st.edge += static_cast<int>(e_front + e_back);
    poly.erase(poly.end() - static_cast<long>(e_back), poly.end());
    poly.erase(poly.begin(), poly.begin() + static_cast<long>(e_front));
    smoothPolyline(poly, std::min(c.smoothing_degree, 3), c.smoothing_half_window);
    for (const RidgePoint& q : poly) {
      LinePoint lp;
      lp.u = q.u;
      lp.v = q.v;
      lp.peak = q.peak;
      lp.width = q.width;
      lp.nx = q.nx;
      lp.ny = q.ny;
      lp.segment = segment;
      if (img.ptr<uint8_t>(q.y)[q.x] == 255) ++st.saturated;
      out.push_back(lp);
    }
    ++segment;
  }
  st.segments = segment;
  return out;
}

}  // namespace cellsight::detail
