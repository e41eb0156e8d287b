// Line-centre accuracy of each estimator vs noise level, on rendered lines with a known centre
// (the scene's camera, laser and noise model over a bare table). Prints a Markdown table and,
// with --json FILE, writes the figures.
// Usage: cellsight_line_accuracy <scene.yaml> [--json out.json] [--frames N]   (--help for details)
// Bad or unknown options are reported by CLI11 (non-zero exit); failures at run time print
// "error: ..." and exit 1.
#include <iostream>
#include <nlohmann/json.hpp>

#include "cellsight/eval/evaluation.hpp"
#include "cellsight/common/file_io.hpp"
#include "cli_args.hpp"

using namespace cellsight;

int main(int argc, char** argv) {
  std::string scene_file, json_path;
  int frames = 5;
  CLI::App app("Line-centre accuracy of each estimator vs noise level, on rendered lines with a known centre (the "
               "scene's camera, laser and noise model over a bare table). Prints a Markdown table.",
               "cellsight_line_accuracy");
  app.add_option("scene", scene_file, "scene YAML")->required()->check(CLI::ExistingFile);
  app.add_option("--json", json_path, "write the figures to this JSON file");
  app.add_option("--frames", frames, "frames per noise level")->check(cellsight_tools::positiveInt())->capture_default_str();
  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  try {
    Scene base = loadScene(scene_file);
    base.objects.clear();
    struct Variant {
      std::string name;
      LineExtractionConfig cfg;
    };
    std::vector<Variant> variants;
    for (const std::string e : {"run_centre", "gaussian3", "centroid"}) {
      Variant v{e, {}};
      v.cfg.estimator = LineExtractionConfig::parseEstimator(e);
      v.cfg.smoothing_degree = 0;
      variants.push_back(v);
    }
    Variant sm{"centroid + quadratic smoothing (default)", {}};
    variants.push_back(sm);
    const std::vector<double> levels = {0.0, 0.5, 1.0, 2.0, 4.0};
    nlohmann::json out = nlohmann::json::array();
    std::cout << "| estimator | noise ×0 | ×0.5 | ×1 (default) | ×2 | ×4 |\n|---|---|---|---|---|---|\n";
    std::vector<std::vector<double>> table(variants.size());
    for (double level : levels) {
      Scene s = base;
      s.noise.enabled = level > 0;
      s.noise.sensor_sigma *= level;
      s.noise.speckle = std::min(1.0, s.noise.speckle * level);
      s.noise.dropout_probability = std::min(1.0, s.noise.dropout_probability * level);
      ScannerRenderer r(std::make_shared<CellGeometry>(s));
      for (size_t vi = 0; vi < variants.size(); ++vi) {
        double s2 = 0;
        size_t n = 0, expected = 0;
        for (int f = 0; f < frames; ++f) {
          Eigen::Isometry3d F = s.robot.home;
          F.translation().y() = -0.20 + 0.02 * f;  // the line sweeps over the bare table
          const LineCentreErrors e = lineCentreErrors(r, F, variants[vi].cfg, 1000 + f);
          s2 += e.rms_px * e.rms_px * e.columns;
          n += e.columns;
          expected += e.expected;
        }
        const double rms = n ? std::sqrt(s2 / n) : 0;
        table[vi].push_back(rms);
        out.push_back({{"estimator", variants[vi].name}, {"noise_scale", level}, {"rms_px", rms},
                       {"columns", n}, {"coverage", expected ? double(n) / expected : 0.0}});
      }
    }
    for (size_t vi = 0; vi < variants.size(); ++vi) {
      std::cout << "| " << variants[vi].name;
      for (double x : table[vi]) std::printf(" | %.4f", x);
      std::cout << " |\n";
    }
    if (!json_path.empty()) writeFileAtomic(json_path, out.dump(2) + "\n");
  } catch (const std::exception& e) {
    std::cerr << "error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
