#include "cellsight/eval/fixture_eval.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <sstream>

#include "cellsight/common/errors.hpp"
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
  FixtureAdjustmentConfig free_cfg = config.adjustment;
  free_cfg.table_constrained = false;

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
    detect_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
    adjust_ms.push_back(std::chrono::duration<double, std::milli>(t2 - t1).count());
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
  (void)free_cfg;
  for (const FixtureTruth& t : truth) {
    FixtureErrorStats s;
    s.type = t.type;
    s.program = t.program;
    s.markers = static_cast<int>(t.payloads.size());
    s.found = found[t.type];
    s.t_err_mean = t_err[t.type].mean();
    s.t_err_sigma = t_err[t.type].sigma();
    s.t_err_max = t_err[t.type].max();
    s.r_err_mean = r_err[t.type].mean();
    s.r_err_sigma = r_err[t.type].sigma();
    s.r_err_max = r_err[t.type].max();
    s.free_t_err_mean = ft_err[t.type].mean();
    s.free_t_err_sigma = ft_err[t.type].sigma();
    s.free_r_err_mean = fr_err[t.type].mean();
    s.free_r_err_sigma = fr_err[t.type].sigma();
    s.single_t_err_mean = st_err[t.type].mean();
    s.single_r_err_mean = sr_err[t.type].mean();
    s.sigma_translation_reported = sig[t.type].mean();
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
