// cellsight_simulate_captures: what a user records to calibrate the scanner, on the simulated
// cell as built (sim/calibration_captures): chessboard views, the board on the table with its
// frame taught by the robot's pointer, laser-line views on the bare table and over a gauge
// block. The files feed `cellsight_calibrate` exactly as a real cell's would; the printed JSON
// names them and the board.
#include <iostream>
#include <nlohmann/json.hpp>

#include "cellsight/sim/calibration_captures.hpp"
#include "cli_args.hpp"

using namespace cellsight;

int main(int argc, char** argv) {
  std::string scene_file, out;
  bool perfect = false;
  CalibrationCaptureConfig c;
  CLI::App app("Simulated calibration captures of a scene's cell as built, in the formats cellsight_calibrate reads.",
               "cellsight_simulate_captures");
  app.add_option("--scene", scene_file, "scene YAML")->required()->check(CLI::ExistingFile);
  app.add_option("--out", out, "output folder (intrinsics/, extrinsics/, laser/, laser_three_point/)")->required();
  app.add_flag("--perfect", perfect, "the ideal cell of the drawing (exact robot) instead of the scene's as_built cell");
  app.add_option("--views", c.intrinsic_views, "chessboard views for the intrinsics")
      ->check(cellsight_tools::positiveInt())
      ->capture_default_str();
  app.add_option("--laser-views", c.laser_views, "laser-line views on the bare table")
      ->check(cellsight_tools::positiveInt())
      ->capture_default_str();
  app.add_option("--seed", c.seed, "board placements and image noise")->capture_default_str();
  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  return cellsight_tools::runTool([&] {
    Scene scene = loadScene(scene_file);
    if (perfect) makePerfect(scene);
    const CalibrationCaptureFiles f = writeCalibrationCaptures(scene, out, c);
    std::cout << nlohmann::json({{"intrinsics_images", f.intrinsics_dir},
                                 {"pattern_image", f.pattern_image},
                                 {"taught", f.taught},
                                 {"laser_observations", f.laser_obs},
                                 {"three_point_observations", f.three_point_obs},
                                 {"fixture_intrinsics_images", f.fixture_intrinsics_dir},
                                 {"fixture_pattern_image", f.fixture_pattern_image},
                                 {"fixture_taught", f.fixture_taught},
                                 {"fixture_square", f.fixture_square},
                                 {"board", f.board},
                                 {"square", f.square},
                                 {"cell", scene.as_built.perfect ? "perfect" : "as built"}})
                     .dump(2)
              << "\n";
    return 0;
  });
}
