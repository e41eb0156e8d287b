#include "cellsight/eval/fixture_eval.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <random>
#include <sstream>
#include <opencv2/calib3d.hpp>

#include "cellsight/common/errors.hpp"
#include "cellsight/sim/calibration_captures.hpp"
#include "cellsight/sim/renderer.hpp"

namespace cellsight {
namespace {

struct Acc {
  std::vector<double> v;
  void add(double x) { v.push_back(x); }
  double mean() const {
    double s = 0;
    for (double x : v) s += x;
    return v.empty() ? 0 : s / static_cast<double>(v.size());
  }
  double sigma() const {
    if (v.size() < 2) return 0;
    const double m = mean();
    double s = 0;
    for (double x : v) s += (x - m) * (x - m);
    return std::sqrt(s / static_cast<double>(v.size() - 1));
  }
  double max() const { return v.empty() ? 0 : *std::max_element(v.begin(), v.end()); }
  ErrorSummary summary() const { return {mean(), sigma(), max()}; }
};

double medianOf(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

std::vector<FixtureTruth> fixtureTruth(const Scene& scene, const FixtureRegistry& registry) {
  std::vector<FixtureTruth> out;
  for (const FixtureType& type : registry.fixtures) {
    FixtureTruth t;
    t.type = type.type;
    t.program = type.program;
    bool placed = false;
    for (const QrFixture& f : scene.fixtures) {
      for (const FixtureCode& c : type.codes) {
        if (c.payload != f.payload) continue;
        t.payloads.push_back(c.payload);
        if (!placed) {
          // the scene fixture frame is the code's frame (centre of the printed face, z up)
          t.T_base_fixture = f.T_base_fixture * c.T_fixture_code.inverse();
          placed = true;
        }
      }
    }
    if (!placed) continue;
    t.T_base_ucs = t.T_base_fixture * type.T_fixture_ucs;
    out.push_back(std::move(t));
  }
  return out;
}

FixtureSimResult evaluateFixturesSim(const Scene& scene, const FixtureRegistry& registry,
                                     const CameraIntrinsics& camera, const Eigen::Isometry3d& T_base_camera,
                                     const FixtureSimConfig& config) {
  const auto truth = fixtureTruth(scene, registry);
  auto geometry = std::make_shared<CellGeometry>(scene);
  FixtureRenderer renderer(geometry);
  QrDetectorConfig dc = config.detector;
  dc.expected_codes = 0;
  for (const auto& t : truth) dc.expected_codes += static_cast<int>(t.payloads.size());
  QrDetector detector(dc);

  std::map<std::string, Acc> t_err, r_err, ft_err, fr_err, st_err, sr_err, sig;
  std::map<std::string, int> found;
  std::vector<double> detect_ms, adjust_ms;
  FixtureSimResult result;
  result.renders = config.renders;
  using clock = std::chrono::steady_clock;
  for (int k = 0; k < config.renders; ++k) {
    const cv::Mat image = renderer.render(config.seed * 1000003ull + static_cast<uint64_t>(k));
    const auto t0 = clock::now();
    const auto detections = detector.detect(image, &camera);
    const auto t1 = clock::now();
    const AdjustmentResult adj = adjustFixtures(detections, registry, camera, T_base_camera, config.adjustment);
    const auto t2 = clock::now();
    for (const auto& m : adj.messages) ++result.messages[m];
    for (const auto& d : detections) ++result.decoders[d.decoder];
    detect_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
    adjust_ms.push_back(std::chrono::duration<double, std::milli>(t2 - t1).count());
    if (!config.dump_misses.empty() && adj.fixtures.size() < truth.size()) {
      std::filesystem::create_directories(config.dump_misses);
      cv::imwrite(config.dump_misses + "/render_" + std::to_string(k) + ".png", image);
    }
    for (const FixtureInstance& inst : adj.fixtures) {
      const auto it = std::find_if(truth.begin(), truth.end(), [&](const FixtureTruth& t) { return t.type == inst.type; });
      if (it == truth.end() || inst.id != inst.type) {
        ++result.false_fixtures;
        continue;
      }
      ++found[inst.type];
      const auto [dt, dr] = poseDifference(inst.T_base_ucs, it->T_base_ucs);
      t_err[inst.type].add(dt);
      r_err[inst.type].add(dr);
      const auto [fdt, fdr] = poseDifference(inst.T_base_ucs_free, it->T_base_ucs);
      ft_err[inst.type].add(fdt);
      fr_err[inst.type].add(fdr);
      sig[inst.type].add(inst.sigma_translation);
      // the first code of the fixture alone, free 6-DoF
      for (size_t ci : inst.codes) {
        const CodeObservation& o = adj.codes[ci];
        if (o.status != "ok" || o.detection.payload != it->payloads.front()) continue;
        const auto [sdt, sdr] = poseDifference(o.T_base_ucs_free, it->T_base_ucs);
        st_err[inst.type].add(sdt);
        sr_err[inst.type].add(sdr);
      }
    }
  }
  for (const FixtureTruth& t : truth) {
    FixtureErrorStats s;
    s.type = t.type;
    s.program = t.program;
    s.markers = static_cast<int>(t.payloads.size());
    s.found = found[t.type];
    s.t_err = t_err[t.type].summary();
    s.r_err = r_err[t.type].summary();
    s.free_t_err = ft_err[t.type].summary();
    s.free_r_err = fr_err[t.type].summary();
    s.single_t_err = st_err[t.type].summary();
    s.single_r_err = sr_err[t.type].summary();
    s.reported_sigma = sig[t.type].summary();
    result.fixtures.push_back(s);
  }
  result.detect_ms_median = medianOf(detect_ms);
  result.adjust_ms_median = medianOf(adjust_ms);
  return result;
}

DecodeRate evaluateDecodeRate(const std::string& folder, const QrDetectorConfig& config) {
  namespace fs = std::filesystem;
  if (!fs::is_directory(folder)) throw ConfigError("decode rate: '" + folder + "' is not a folder");
  std::vector<fs::path> images;
  for (const auto& e : fs::recursive_directory_iterator(folder)) {
    const std::string ext = e.path().extension().string();
    if (e.is_regular_file() && (ext == ".png" || ext == ".jpg" || ext == ".jpeg")) images.push_back(e.path());
  }
  std::sort(images.begin(), images.end());
  QrDetectorConfig no_refine = config;
  no_refine.refine = false;  // decoding only
  QrDetector detector(no_refine);
  DecodeRate rate;
  for (const auto& img : images) {
    fs::path txt = img;
    txt.replace_extension(".txt");
    if (!fs::exists(txt)) continue;
    std::ifstream in(txt, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    const std::string expected = ss.str();
    const cv::Mat gray = cv::imread(img.string(), cv::IMREAD_GRAYSCALE);
    ++rate.images;
    if (gray.empty()) {
      rate.missed.push_back(fs::relative(img, folder).string() + " (unreadable)");
      continue;
    }
    auto hit = [&](const std::vector<QrDetection>& d) {
      return std::any_of(d.begin(), d.end(), [&](const QrDetection& q) { return q.payload == expected; });
    };
    const bool all = hit(detector.detect(gray));
    const bool zbar = hit(detector.detectZbar(gray));
    const bool wechat = hit(detector.detectWechat(gray));
    rate.decoded += all;
    rate.decoded_zbar_only += zbar;
    rate.decoded_wechat_only += wechat;
    if (!all) rate.missed.push_back(fs::relative(img, folder).string());
  }
  return rate;
}

}  // namespace cellsight

namespace cellsight {
namespace {

std::vector<Eigen::Vector3d> boardPoints(int cols, int rows, double square) {
  std::vector<Eigen::Vector3d> p;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) p.emplace_back(c * square, r * square, 0.0);
  }
  return p;
}

// the point of the table under the camera's optical axis
Eigen::Vector3d tableUnderCamera(const Scene& scene) {
  const Eigen::Isometry3d& T = scene.fixture_camera.T_base_camera;
  const Eigen::Vector3d axis = T.linear().col(2), C = T.translation();
  return C + axis * ((scene.table.z - C.z()) / axis.z());
}

}  // namespace

HandEyeInput simulateHandEyeViews(const Scene& scene, const HandEyeSweepConfig& c, uint64_t seed,
                                  Eigen::Isometry3d* true_X, Eigen::Isometry3d* true_Y) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> N(0.0, 1.0);
  const CameraConfig& cam = scene.fixture_camera;
  HandEyeInput in;
  in.camera = cam.intrinsics;
  in.target_points = boardPoints(9, 6, 0.03);
  // the board on top of the tool, printed side up (its z into the board = the flange's z, down),
  // centred over the flange, 60 mm behind the flange face
  Eigen::Isometry3d Y = Eigen::Isometry3d::Identity();
  Y.translation() = Eigen::Vector3d(-0.12, -0.075, -0.06);
  const Eigen::Isometry3d X = cam.T_base_camera;
  const std::vector<Eigen::Isometry3d> flanges =
      handEyeFlangePoses(scene, cam, Y, in.target_points, c.views, seed * 31 + 1);
  in.axes_reference = 0;
  in.axes_moves = {1, 2, 3, 4, 5, 6};
  const std::vector<cv::Point3d> obj = [&] {
    std::vector<cv::Point3d> o;
    for (const auto& p : in.target_points) o.emplace_back(p.x(), p.y(), p.z());
    return o;
  }();
  const cv::Matx33d K(cam.intrinsics.fx, 0, cam.intrinsics.cx, 0, cam.intrinsics.fy, cam.intrinsics.cy, 0, 0, 1);
  const std::vector<double> dist(cam.intrinsics.dist.begin(), cam.intrinsics.dist.end());
  for (const auto& F : flanges) {
    HandEyeView v;
    const Eigen::Isometry3d T = X.inverse() * F * Y;
    std::vector<cv::Point2d> img;
    for (const auto& p : in.target_points) {
      const Eigen::Vector2d uv = cam.intrinsics.project(T * p);
      img.emplace_back(uv.x() + c.corner_sigma_px * N(rng), uv.y() + c.corner_sigma_px * N(rng));
    }
    cv::Vec3d rvec, tvec;
    cv::solvePnP(obj, img, K, dist, rvec, tvec, false, cv::SOLVEPNP_ITERATIVE);
    cv::Matx33d R;
    cv::Rodrigues(rvec, R);
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) v.T_camera_target.linear()(i, j) = R(i, j);
      v.T_camera_target.translation()(i) = tvec[i];
    }
    v.corners = img;
    Eigen::Isometry3d reported = F;
    reported.translation() += c.repeatability_mm * 1e-3 * Eigen::Vector3d(N(rng), N(rng), N(rng));
    const Eigen::Vector3d w = c.flange_rotation_deg * M_PI / 180 * Eigen::Vector3d(N(rng), N(rng), N(rng));
    if (w.norm() > 0) reported.linear() = F.linear() * Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
    v.T_base_flange = reported;
    in.views.push_back(std::move(v));
  }
  in.touched_origin = (flanges[0] * Y).translation() + (c.pointer_sigma_mm + c.repeatability_mm) * 1e-3 *
                                                          Eigen::Vector3d(N(rng), N(rng), N(rng));
  if (true_X) *true_X = X;
  if (true_Y) *true_Y = Y;
  return in;
}

std::vector<HandEyeSweepRow> handEyeSweep(const Scene& scene, const HandEyeSweepConfig& base) {
  const std::vector<std::pair<std::string, std::vector<double>>> factors = {
      {"corner_sigma_px", {0.0, 0.05, 0.1, 0.2, 0.5, 1.0}},
      {"repeatability_mm", {0.0, 0.01, 0.02, 0.05, 0.1, 0.2}},
      {"flange_rotation_deg", {0.0, 0.001, 0.002, 0.005, 0.01, 0.02}}};
  const Eigen::Vector3d p = tableUnderCamera(scene);
  std::vector<HandEyeSweepRow> rows;
  for (const auto& [factor, values] : factors) {
    for (double value : values) {
      HandEyeSweepConfig c = base;
      if (factor == "corner_sigma_px") c.corner_sigma_px = value;
      if (factor == "repeatability_mm") c.repeatability_mm = value;
      if (factor == "flange_rotation_deg") c.flange_rotation_deg = value;
      HandEyeSweepRow row;
      row.factor = factor;
      row.value = value;
      for (HandEyeMethod m : allHandEyeMethods()) row.methods.push_back(handEyeMethodName(m));
      row.t_err_mm.assign(row.methods.size(), 0.0);
      row.r_err_deg.assign(row.methods.size(), 0.0);
      row.failures.assign(row.methods.size(), 0);
      std::vector<int> ok(row.methods.size(), 0);
      for (int t = 0; t < c.trials; ++t) {
        Eigen::Isometry3d X, Y;
        const HandEyeInput in = simulateHandEyeViews(scene, c, c.seed * 7919 + static_cast<uint64_t>(t), &X, &Y);
        const auto methods = allHandEyeMethods();
        for (size_t k = 0; k < methods.size(); ++k) {
          const HandEyeResult r = calibrateEyeToHand(in, methods[k]);
          if (!r.ok) {
            ++row.failures[k];
            continue;
          }
          // where the calibrated camera puts a table point it sees, vs where it is
          const Eigen::Vector3d q = r.T_base_camera * (X.inverse() * p);
          row.t_err_mm[k] += (q - p).norm() * 1000;
          row.r_err_deg[k] += poseDifference(r.T_base_camera, X).second * 180 / M_PI;
          ++ok[k];
        }
      }
      for (size_t k = 0; k < row.methods.size(); ++k) {
        row.t_err_mm[k] = ok[k] ? row.t_err_mm[k] / ok[k] : std::nan("");
        row.r_err_deg[k] = ok[k] ? row.r_err_deg[k] / ok[k] : std::nan("");
      }
      rows.push_back(std::move(row));
    }
  }
  return rows;
}

}  // namespace cellsight
