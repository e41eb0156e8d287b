// libFuzzer target: what a robot controller can send the bridge. The input is split into lines
// as the server splits it; each line goes through the request parser and, for the pose
// conventions, through parseRobotPose and back through formatRobotPose. A clean rejection is a
// false return or std::invalid_argument; anything else (a crash, a sanitizer report, a parsed
// pose that does not format back to finite numbers) is a finding. The fixture registry's
// YAML is fuzzed as well (first byte 'R').
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <stdexcept>
#include <string>

#include "cellsight/bridge/robot_bridge.hpp"
#include "cellsight/fixtures/fixture_registry.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string input(reinterpret_cast<const char*>(data), size);
  if (!input.empty() && input[0] == 'R') {
    const std::string path = cellsight_fuzz::writeInput(data + 1, size - 1, "fixtures.yaml");
    try {
      cellsight::loadFixtureRegistry(path);
    } catch (const std::exception&) {
    }
    return 0;
  }
  size_t start = 0;
  while (start <= input.size()) {
    size_t end = input.find('\n', start);
    if (end == std::string::npos) end = input.size();
    std::string line = input.substr(start, end - start);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    cellsight::BridgeRequest request;
    std::string error;
    if (!cellsight::parseBridgeRequest(line, request, error) && error.empty()) std::abort();
    for (auto c : {cellsight::PoseConvention::kKuka, cellsight::PoseConvention::kAbb, cellsight::PoseConvention::kFanuc,
                   cellsight::PoseConvention::kRep103}) {
      try {
        const Eigen::Isometry3d T = cellsight::parseRobotPose(line, c);
        const std::string back = cellsight::formatRobotPose(T, c);
        if (back.find("nan") != std::string::npos || back.find("inf") != std::string::npos) std::abort();
      } catch (const std::invalid_argument&) {
      }
    }
    start = end + 1;
  }
  return 0;
}
