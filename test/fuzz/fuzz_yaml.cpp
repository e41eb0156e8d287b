// libFuzzer target: every YAML the project reads, through its strict loader. The first byte
// picks the loader; the rest is the file. A clean rejection is any std::exception (the loaders
// throw ConfigError naming the file and key).
#include <cstddef>
#include <cstdint>
#include <exception>
#include <filesystem>

#include "cellsight/common/calibration.hpp"
#include "cellsight/common/camera_model.hpp"
#include "cellsight/common/model_info.hpp"
#include "cellsight/common/trajectory.hpp"
#include "cellsight/localization/clustering.hpp"
#include "cellsight/localization/model_matching.hpp"
#include "cellsight/scanner/calibrate.hpp"
#include "cellsight/scanner/scanner_config.hpp"
#include "cellsight/sim/scene.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const uint8_t kind = data[0] % 10;
  if (kind == 9) {  // a calibration folder holding this one file
    const std::string dir = cellsight_fuzz::scratchDir() + "/calibration";
    std::filesystem::create_directories(dir);
    cellsight_fuzz::writeInput(data + 1, size - 1, "calibration/laser.yaml");
    try {
      cellsight::loadCalibrationFolder(dir);
    } catch (const std::exception&) {
    }
    return 0;
  }
  const std::string path = cellsight_fuzz::writeInput(data + 1, size - 1, "config.yaml");
  try {
    switch (kind) {
      case 0: cellsight::loadScene(path); break;
      case 1: cellsight::loadTrajectories(path); break;
      case 2: cellsight::loadCameraInfoYaml(path); break;
      case 3: cellsight::loadTransformCalibration(path); break;
      case 4: cellsight::loadClusteringConfig(path); break;
      case 5: cellsight::loadMatchingConfig(path); break;
      case 6: cellsight::loadScannerSettings(path); break;
      case 7: cellsight::loadModelInfo(path); break;
      default: cellsight::loadLaserObservations(path);
    }
  } catch (const std::exception&) {
  }
  return 0;
}
