// Line extraction on recorded frames: per frame and overall share of columns (or rows) with a
// line centre, and an overlay PNG (centres drawn in green over the frame).
// Usage: cellsight_extract_line --images <dir or files...> [--channel red|green|blue|mono]
//          [--along rows|columns] [--estimator centroid|gaussian3|run_centre]
//          [--overlay out.png [--overlay-index N]] [--json out.json]     (--help for details)
// Bad or unknown options are reported by CLI11 (non-zero exit); no image found: exit 2.
#include <algorithm>
#include <iostream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "cellsight/scanner/calibrate.hpp"
#include "cellsight/common/file_io.hpp"
#include "cellsight/common/image_io.hpp"
#include "cellsight/scanner/line_extraction.hpp"
#include "cli_args.hpp"

using namespace cellsight;

int main(int argc, char** argv) {
  std::vector<std::string> inputs;
  std::string channel = "mono", along = "rows", estimator = "centroid", overlay, json;
  int overlay_index = -1;
  CLI::App app("Line extraction on recorded frames: per frame and overall share of columns (or rows) with a line "
               "centre, and an overlay PNG (centres in green over the frame).",
               "cellsight_extract_line");
  app.add_option("--images", inputs, "image folders (*.png, *.jpg, *.jpeg, sorted) and/or image files")
      ->required()
      ->check(CLI::ExistingPath);
  app.add_option("--channel", channel, "colour channel with the laser, or mono (grey)")
      ->check(CLI::IsMember({"red", "green", "blue", "mono"}))
      ->capture_default_str();
  app.add_option("--along", along, "rows: the line runs along rows (one centre per column); columns: one per row")
      ->check(CLI::IsMember({"rows", "columns"}))
      ->capture_default_str();
  app.add_option("--estimator", estimator, "line-centre estimator")
      ->check(cellsight_tools::parsedBy([](const std::string& e) { LineExtractionConfig::parseEstimator(e); },
                                        "{centroid,gaussian3,run_centre}"))
      ->capture_default_str();
  app.add_option("--overlay", overlay, "write the overlay of one frame to this PNG");
  app.add_option("--overlay-index", overlay_index, "frame of the overlay (0-based; negative: the middle frame)")
      ->capture_default_str();
  app.add_option("--json", json, "write the figures to this JSON file");
  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  return cellsight_tools::runTool([&] {
    const std::vector<std::string> files = listImages(inputs);
    if (files.empty()) {
      std::cerr << "error: no images (use --images <dir or files>)\n";
      return 2;
    }
    LineExtractionConfig cfg;
    cfg.estimator = LineExtractionConfig::parseEstimator(estimator);  // checked by the parser
    cfg.line_along_rows = along != "columns";
    cfg.channel = channel == "red" ? 0 : channel == "green" ? 1 : channel == "blue" ? 2 : -1;
    if (overlay_index < 0) overlay_index = static_cast<int>(files.size() / 2);
    nlohmann::json per_frame = nlohmann::json::array();
    long scanned = 0, found = 0;
    for (size_t i = 0; i < files.size(); ++i) {
      cv::Mat img;
      try {
        img = readImage(files[i], cfg.channel >= 0 ? cv::IMREAD_COLOR : cv::IMREAD_GRAYSCALE);
      } catch (const std::exception& e) {
        std::cerr << "warning: " << e.what() << ": skipped\n";
        continue;
      }
      if (cfg.channel >= 0) cv::cvtColor(img, img, cv::COLOR_BGR2RGB);
      LineExtractionStats st;
      const auto pts = extractLine(img, cfg, &st);
      scanned += st.scanned;
      found += st.found;
      per_frame.push_back({{"file", files[i]}, {"share", double(st.found) / std::max(1, st.scanned)},
                           {"ambiguous", st.ambiguous}, {"too_wide", st.too_wide}, {"background", st.background}});
      if (static_cast<int>(i) == overlay_index && !overlay.empty()) {
        cv::Mat vis;
        if (img.channels() == 3) cv::cvtColor(img, vis, cv::COLOR_RGB2BGR); else cv::cvtColor(img, vis, cv::COLOR_GRAY2BGR);
        vis *= 2.0;  // the frames are dark: brighten for the eye
        for (const auto& p : pts) cv::circle(vis, cv::Point2f(p.u, p.v), 1, cv::Scalar(0, 255, 0), cv::FILLED);
        cv::imwrite(overlay, vis);
      }
    }
    nlohmann::json out = {{"frames", per_frame.size()}, {"lines_along", along}, {"channel", channel},
                          {"estimator", estimator}, {"share_with_line", double(found) / std::max(1L, scanned)},
                          {"per_frame", per_frame}};
    std::cout << "frames " << per_frame.size() << ", share of " << (cfg.line_along_rows ? "columns" : "rows")
              << " with a line: " << double(found) / std::max(1L, scanned) << "\n";
    if (!json.empty()) writeFileAtomic(json, out.dump(2) + "\n");
    return 0;
  });
}
