// Line extraction on recorded frames: the centres of every frame (CSV or JSON), overlays in a
// colour that contrasts with the laser (one chosen frame, or every frame into a folder), and —
// with --reference-contrast — the share of the visible line's row/column crossings that got a
// centre and the share of centres where no line is visible (lineCoverage(), a threshold rule
// independent of the extractor; its crossings are drawn in blue on the overlay, those without a
// centre in white).
// Usage: cellsight_extract_line --images <dir or files...> [--channel red|green|blue|mono]
//          [--settings config/scanner.yaml] [--estimator ridge|centroid|gaussian3|run_centre] [--along rows|columns]
//          [--centres out.csv|out.json] [--overlay out.png [--overlay-index N]] [--overlay-dir DIR]
//          [--reference-contrast G] [--json out.json]                       (--help for details)
// Bad or unknown options are reported by CLI11 (non-zero exit); no readable image, or images of
// different sizes: "error: ..." and exit 2.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "cellsight/common/file_io.hpp"
#include "cellsight/common/image_io.hpp"
#include "cellsight/eval/evaluation.hpp"
#include "cellsight/scanner/calibrate.hpp"
#include "cellsight/scanner/line_extraction.hpp"
#include "cellsight/scanner/scanner_config.hpp"
#include "cli_args.hpp"

using namespace cellsight;
namespace fs = std::filesystem;

namespace {

/// The frame brightened for the eye, the reference crossings in blue (white: no centre in them)
/// and the centres in a colour
/// far from the laser's (cyan for a red line, magenta for green, yellow for blue, green for mono).
cv::Mat overlayOf(const cv::Mat& img, int channel, const std::vector<LinePoint>& pts, const cv::Mat& reference,
                  const cv::Mat& missed) {
  cv::Mat vis;
  if (img.channels() == 3) cv::cvtColor(img, vis, cv::COLOR_RGB2BGR);
  else cv::cvtColor(img, vis, cv::COLOR_GRAY2BGR);
  vis *= 2.0;  // laser frames are dark
  if (!reference.empty()) vis.setTo(cv::Scalar(255, 0, 0), reference);
  if (!missed.empty()) vis.setTo(cv::Scalar(255, 255, 255), missed);
  const cv::Scalar colour = channel == 0 ? cv::Scalar(255, 255, 0) : channel == 1 ? cv::Scalar(255, 0, 255)
                            : channel == 2 ? cv::Scalar(0, 255, 255) : cv::Scalar(0, 255, 0);
  for (const auto& p : pts) {
    const int u = static_cast<int>(std::lround(p.u)), v = static_cast<int>(std::lround(p.v));
    if (u >= 0 && v >= 0 && u < vis.cols && v < vis.rows) vis.at<cv::Vec3b>(v, u) = cv::Vec3b(
        static_cast<uint8_t>(colour[0]), static_cast<uint8_t>(colour[1]), static_cast<uint8_t>(colour[2]));
  }
  return vis;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> inputs;
  std::string channel = "mono", along = "rows", estimator, overlay, overlay_dir, json, centres_path, settings;
  int overlay_index = -1;
  double reference_contrast = 0;
  int rule_width = LineCoverageRule{}.max_width;
  bool skip_glow = false;
  CLI::App app("Line extraction on recorded frames: centres per frame (CSV/JSON), overlays, and the share of the "
               "visible line that got a centre.",
               "cellsight_extract_line");
  app.add_option("--images", inputs, "image folders (*.png, *.jpg, *.jpeg, sorted) and/or image files")
      ->required()
      ->check(CLI::ExistingPath);
  app.add_option("--channel", channel, "colour channel with the laser, or mono (grey)")
      ->check(CLI::IsMember({"red", "green", "blue", "mono"}))
      ->capture_default_str();
  app.add_option("--settings", settings, "scanner settings YAML whose line: section to use (as the triangulation node)")
      ->check(CLI::ExistingFile);
  app.add_option("--estimator", estimator, "line-centre estimator: ridge (any direction) or a column method "
                                           "[default: the settings' estimator, else ridge]")
      ->check(cellsight_tools::parsedBy([](const std::string& e) { LineExtractionConfig::parseEstimator(e); },
                                        "{ridge,centroid,gaussian3,run_centre}"));
  app.add_option("--along", along,
                 "column methods only: rows: the line runs along rows (one centre per column); columns: one per row")
      ->check(CLI::IsMember({"rows", "columns"}))
      ->capture_default_str();
  app.add_option("--centres", centres_path, "write every frame's centres: .csv (frame,u,v,nx,ny,width,peak,segment) or .json");
  app.add_option("--overlay", overlay, "write the overlay of one frame to this PNG");
  app.add_option("--overlay-index", overlay_index, "frame of --overlay (0-based; negative: the middle frame)")
      ->capture_default_str();
  app.add_option("--overlay-dir", overlay_dir, "write an overlay of every frame into this folder (<frame name>.png)");
  app.add_option("--reference-contrast", reference_contrast,
                 "grey levels above background that make a line visible to the reference rule (0: no reference)")
      ->check(cellsight_tools::nonNegative())
      ->capture_default_str();
  app.add_option("--reference-width", rule_width, "widest run (px) the reference rule takes for a line crossing")
      ->check(cellsight_tools::positiveInt())
      ->capture_default_str();
  app.add_flag("--reference-skip-glow", skip_glow,
               "count no reference crossing in or near lit areas wider than a line (glow, specular spots)");
  app.add_option("--json", json, "write the figures to this JSON file");
  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  return cellsight_tools::runTool([&] {
    const std::vector<std::string> files = listImages(inputs);
    if (files.empty()) {
      std::cerr << "error: no images (*.png, *.jpg, *.jpeg) in " << inputs.front() << (inputs.size() > 1 ? " ..." : "")
                << "\n";
      return 2;
    }
    LineExtractionConfig cfg = settings.empty() ? LineExtractionConfig{} : loadScannerSettings(settings).line;
    if (!estimator.empty()) cfg.estimator = LineExtractionConfig::parseEstimator(estimator);  // checked by the parser
    estimator = LineExtractionConfig::estimatorName(cfg.estimator);
    cfg.line_along_rows = along != "columns";
    cfg.channel = channel == "red" ? 0 : channel == "green" ? 1 : channel == "blue" ? 2 : -1;
    if (overlay_index < 0) overlay_index = static_cast<int>(files.size() / 2);
    if (!overlay_dir.empty()) fs::create_directories(overlay_dir);
    LineCoverageRule rule;
    rule.min_contrast = reference_contrast;
    rule.max_width = rule_width;
    rule.skip_lit_areas = skip_glow;
    nlohmann::json per_frame = nlohmann::json::array();
    nlohmann::json centres_json = nlohmann::json::array();
    std::ostringstream csv;
    csv << "frame,u,v,nx,ny,width,peak,segment\n";
    long found = 0, crossings = 0, covered = 0, false_centres = 0, segments = 0;
    cv::Size size;
    std::vector<std::string> skipped;
    for (size_t i = 0; i < files.size(); ++i) {
      cv::Mat img;
      try {
        img = readImage(files[i], cfg.channel >= 0 ? cv::IMREAD_COLOR : cv::IMREAD_GRAYSCALE);
      } catch (const std::exception& e) {
        std::cerr << "warning: " << e.what() << ": skipped\n";
        skipped.push_back(files[i]);
        continue;
      }
      if (size.area() == 0) size = img.size();
      if (img.size() != size) {
        std::cerr << "error: " << files[i] << " is " << img.cols << "x" << img.rows << " but the first frame is "
                  << size.width << "x" << size.height << ": one camera's frames only\n";
        return 2;
      }
      if (cfg.channel >= 0) cv::cvtColor(img, img, cv::COLOR_BGR2RGB);
      LineExtractionStats st;
      const auto pts = extractLine(img, cfg, &st);
      found += st.found;
      segments += st.segments;
      const std::string name = fs::path(files[i]).filename().string();
      nlohmann::json fj = {{"file", files[i]}, {"centres", st.found}, {"segments", st.segments},
                           {"background", st.background}, {"too_wide", st.too_wide}, {"ambiguous", st.ambiguous},
                           {"saturated", st.saturated}};
      cv::Mat reference, missed;
      if (reference_contrast > 0) {
        cv::Mat mono;
        if (img.channels() == 3) cv::extractChannel(img, mono, cfg.channel);
        else mono = img;
        const LineCoverage cov = lineCoverage(mono, pts, rule);
        crossings += cov.crossings;
        covered += cov.covered;
        false_centres += cov.false_centres;
        fj["crossings"] = cov.crossings;
        fj["coverage"] = cov.coverage();
        fj["false_share"] = cov.falseShare();
        reference = cov.mask;
        missed = cov.missed;
      }
      per_frame.push_back(fj);
      if (!centres_path.empty()) {
        for (const auto& p : pts) {
          char line[200];
          std::snprintf(line, sizeof line, "%zu,%.4f,%.4f,%.4f,%.4f,%.3f,%.1f,%d\n", i, p.u, p.v, p.nx, p.ny, p.width,
                        p.peak, p.segment);
          csv << line;
          centres_json.push_back({{"frame", i}, {"u", p.u}, {"v", p.v}, {"nx", p.nx}, {"ny", p.ny},
                                  {"width", p.width}, {"peak", p.peak}, {"segment", p.segment}});
        }
      }
      if (static_cast<int>(i) == overlay_index && !overlay.empty()) {
        cv::imwrite(overlay, overlayOf(img, cfg.channel, pts, reference, missed));
      }
      if (!overlay_dir.empty()) {
        cv::imwrite((fs::path(overlay_dir) / fs::path(name).replace_extension(".png")).string(),
                    overlayOf(img, cfg.channel, pts, reference, missed));
      }
    }
    if (per_frame.empty()) {
      std::cerr << "error: none of the " << files.size() << " images could be read\n";
      return 2;
    }
    nlohmann::json out = {{"frames", per_frame.size()}, {"skipped", skipped}, {"channel", channel},
                          {"estimator", estimator}, {"centres", found}, {"segments", segments},
                          {"per_frame", per_frame}};
    if (cfg.estimator != LineExtractionConfig::Estimator::kRidge) out["lines_along"] = along;
    std::cout << "frames " << per_frame.size() << " (" << skipped.size() << " unreadable), centres " << found
              << " (" << found / static_cast<long>(per_frame.size()) << " per frame) in " << segments << " segments\n";
    if (reference_contrast > 0) {
      const double cov = crossings ? double(covered) / double(crossings) : 0.0;
      const double fls = found ? double(false_centres) / double(found) : 0.0;
      out["reference"] = {{"min_contrast", rule.min_contrast}, {"max_width", rule.max_width},
                          {"skip_lit_areas", rule.skip_lit_areas},
                          {"tolerance_px", rule.tolerance_px}, {"crossings", crossings}, {"coverage", cov},
                          {"false_share", fls}};
      std::printf("visible line (contrast >= %.0f): %ld row/column crossings, %.1f %% with a centre; %.2f %% of the "
                  "centres where no line is visible\n",
                  reference_contrast, crossings, 100 * cov, 100 * fls);
    }
    if (!centres_path.empty()) {
      if (fs::path(centres_path).extension() == ".json") writeFileAtomic(centres_path, centres_json.dump(1) + "\n");
      else writeFileAtomic(centres_path, csv.str());
    }
    if (!json.empty()) writeFileAtomic(json, out.dump(2) + "\n");
    return 0;
  });
}
