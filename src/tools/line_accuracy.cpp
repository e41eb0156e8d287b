// Line-centre accuracy of each estimator on rendered frames whose truth is known (the scene's
// camera, laser and noise model): (1) straight lines over the bare table vs noise level; (2) at
// the default noise, straight lines at every angle 0–90° to the image rows (the flange turned
// about the vertical) and curved traces (the line over the scene's parts, the 25 mm sphere
// among them). Error = distance across the line to the true trace (px); coverage = share of the
// noise-free trace's row/column crossings that get a centre. Prints Markdown tables and, with
// --json FILE, writes the figures.
// Usage: cellsight_line_accuracy <scene.yaml> [--json out.json] [--frames N]   (--help for details)
// Bad or unknown options are reported by CLI11 (non-zero exit); failures at run time print
// "error: ..." and exit 1.
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>

#include "cellsight/eval/evaluation.hpp"
#include "cellsight/common/file_io.hpp"
#include "cli_args.hpp"

using namespace cellsight;

namespace {

struct Variant {
  std::string name;
  LineExtractionConfig cfg;
};

struct Acc {
  double s2 = 0, cov = 0, fls = 0;
  size_t n = 0, frames = 0;
  double mx = 0, p95 = 0, in2 = 0;
  size_t in_n = 0;
  void add(const LineCentreErrors& e) {
    in2 += e.interior_rms_px * e.interior_rms_px * static_cast<double>(e.interior_points);
    in_n += e.interior_points;
    mx = std::max(mx, e.max_px);
    p95 += e.p95_px;
    s2 += e.rms_px * e.rms_px * static_cast<double>(e.points);
    n += e.points;
    cov += e.coverage;
    fls += e.false_share;
    ++frames;
  }
  double rms() const { return n ? std::sqrt(s2 / static_cast<double>(n)) : 0.0; }
  double interior() const { return in_n ? std::sqrt(in2 / static_cast<double>(in_n)) : 0.0; }
  double coverage() const { return frames ? cov / static_cast<double>(frames) : 0.0; }
  double falseShare() const { return frames ? fls / static_cast<double>(frames) : 0.0; }
  nlohmann::json json() const {
    return {{"rms_px", rms()}, {"points", n}, {"coverage", coverage()}, {"false_share", falseShare()},
            {"p95_px", frames ? p95 / static_cast<double>(frames) : 0.0}, {"max_px", mx},
            {"interior_rms_px", interior()}, {"interior_points", in_n}};
  }
};

}  // namespace

int main(int argc, char** argv) {
  std::string scene_file, json_path;
  int frames = 5;
  CLI::App app("Line-centre accuracy of each estimator on rendered frames with a known truth: straight lines vs noise, "
               "lines at 0-90 degrees and curved traces at the default noise. Prints Markdown tables.",
               "cellsight_line_accuracy");
  app.add_option("scene", scene_file, "scene YAML")->required()->check(CLI::ExistingFile);
  app.add_option("--json", json_path, "write the figures to this JSON file");
  app.add_option("--frames", frames, "frames per case")->check(cellsight_tools::positiveInt())->capture_default_str();
  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  try {
    const Scene full = loadScene(scene_file);
    Scene base = full;
    base.objects.clear();
    std::vector<Variant> variants;
    for (const std::string e : {"run_centre", "gaussian3", "centroid"}) {
      Variant v{e, {}};
      v.cfg.estimator = LineExtractionConfig::parseEstimator(e);
      v.cfg.smoothing_degree = 0;
      variants.push_back(v);
    }
    Variant sm{"centroid + quadratic smoothing", {}};
    sm.cfg.estimator = LineExtractionConfig::Estimator::kCentroid;
    variants.push_back(sm);
    Variant ridge_raw{"ridge, no smoothing", {}};
    ridge_raw.cfg.smoothing_degree = 0;
    variants.push_back(ridge_raw);
    variants.push_back({"ridge + quadratic smoothing (default)", {}});
    Variant steger{"ridge, Steger's step on I + smoothing", {}};
    steger.cfg.ridge_gaussian_profile = false;
    variants.push_back(steger);
    nlohmann::json out = {{"noise", nlohmann::json::array()}, {"angles", nlohmann::json::array()},
                          {"curved", nlohmann::json::array()}};

    // (1) Straight lines along the rows, noise ×0 … ×4.
    const std::vector<double> levels = {0.0, 0.5, 1.0, 2.0, 4.0};
    std::vector<std::vector<Acc>> table(variants.size());
    for (double level : levels) {
      Scene s = base;
      s.noise.enabled = level > 0;
      s.noise.sensor_sigma *= level;
      s.noise.speckle = std::min(1.0, s.noise.speckle * level);
      s.noise.dropout_probability = std::min(1.0, s.noise.dropout_probability * level);
      ScannerRenderer r(std::make_shared<CellGeometry>(s));
      for (size_t vi = 0; vi < variants.size(); ++vi) {
        Acc a;
        for (int f = 0; f < frames; ++f) {
          Eigen::Isometry3d F = s.robot.home;
          F.translation().y() = -0.20 + 0.02 * f;  // the line sweeps over the bare table
          a.add(lineCentreErrors(r, F, variants[vi].cfg, 1000 + static_cast<uint64_t>(f)));
        }
        table[vi].push_back(a);
        nlohmann::json j = a.json();
        j["estimator"] = variants[vi].name;
        j["noise_scale"] = level;
        out["noise"].push_back(j);
      }
    }
    std::cout << "Straight lines along the rows, px RMS across the line (coverage at x1):\n\n"
              << "| estimator | noise x0 | x0.5 | x1 (default) | x2 | x4 | coverage x1 |\n|---|---|---|---|---|---|---|\n";
    for (size_t vi = 0; vi < variants.size(); ++vi) {
      std::cout << "| " << variants[vi].name;
      for (const Acc& a : table[vi]) std::printf(" | %.4f", a.rms());
      std::printf(" | %.3f |\n", table[vi][2].coverage());
    }

    // (2) Default noise: lines at 0–90° to the rows, and curved traces over the parts.
    const std::vector<double> angles = {0, 15, 30, 45, 60, 75, 90};
    ScannerRenderer bare(std::make_shared<CellGeometry>(base));
    std::cout << "\nDefault noise, straight lines at an angle to the rows: px RMS / coverage / false centres\n\n| estimator";
    for (double a : angles) std::printf(" | %.0f°", a);
    std::cout << " |\n|---";
    for (size_t i = 0; i <= angles.size(); ++i) std::cout << "|---";
    std::cout << "|\n";
    for (const auto& v : variants) {
      std::cout << "| " << v.name;
      for (double deg : angles) {
        Acc a;
        for (int f = 0; f < frames; ++f) {
          // Turn the flange about the vertical through the table point under the laser: the
          // line turns by the same angle on the table and (the camera looks down) in the image.
          Eigen::Isometry3d F = base.robot.home;
          F.translation().y() = -0.16 + 0.02 * f;
          const Eigen::Vector3d pivot(F.translation().x(), F.translation().y() + 0.15, 0);
          const Eigen::Isometry3d turn = Eigen::Translation3d(pivot) *
                                         Eigen::AngleAxisd(deg * M_PI / 180, Eigen::Vector3d::UnitZ()) *
                                         Eigen::Translation3d(-pivot);
          a.add(lineCentreErrors(bare, turn * F, v.cfg, 2000 + static_cast<uint64_t>(f)));
        }
        std::printf(" | %.4f / %.2f / %.3f", a.rms(), a.coverage(), a.falseShare());
        nlohmann::json j = a.json();
        j["estimator"] = v.name;
        j["angle_deg"] = deg;
        out["angles"].push_back(j);
      }
      std::cout << " |\n";
    }
    ScannerRenderer parts(std::make_shared<CellGeometry>(full));
    const auto curved_frames = std::max(frames, 8);
    std::cout << "\nDefault noise, the line over the scene's parts (curved traces, depth edges, shadows), "
              << curved_frames << " frames:\n\n| estimator | px RMS, smooth surfaces (no edge within 3 px) | px RMS, all | coverage | false centres | p95 px | max px |\n|---|---|---|---|---|---|---|\n";
    for (const auto& v : variants) {
      Acc a;
      for (int f = 0; f < curved_frames; ++f) {
        Eigen::Isometry3d F = full.robot.home;
        F.translation().y() = -0.26 + 0.30 * f / std::max(1, curved_frames - 1);
        a.add(lineCentreErrors(parts, F, v.cfg, 3000 + static_cast<uint64_t>(f)));
      }
      std::printf("| %s | %.4f | %.4f | %.3f | %.4f | %.3f | %.3f |\n", v.name.c_str(), a.interior(), a.rms(), a.coverage(), a.falseShare(), a.p95 / static_cast<double>(a.frames), a.mx);
      nlohmann::json j = a.json();
      j["estimator"] = v.name;
      out["curved"].push_back(j);
    }
    if (!json_path.empty()) writeFileAtomic(json_path, out.dump(2) + "\n");
  } catch (const std::exception& e) {
    std::cerr << "error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
