// Renders simulated scanner frames of a scene without ROS: one PNG per pose of a trajectory
// (or the robot's home pose), plus the fixture camera view.
// Usage: cellsight_render_frame <scene.yaml> <out folder> [trajectories.yaml <name>] [--no-noise]
#include <chrono>
#include <cstring>
#include <iostream>
#include <opencv2/imgcodecs.hpp>

#include "cellsight/ground_truth.hpp"
#include "cellsight/renderer.hpp"
#include "cellsight/trajectory.hpp"

int main(int argc, char** argv) {
  std::vector<std::string> args;
  bool noise = true;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--no-noise") == 0) {
      noise = false;
    } else {
      args.emplace_back(argv[i]);
    }
  }
  if (args.size() != 2 && args.size() != 4) {
    std::cerr << "usage: cellsight_render_frame <scene.yaml> <out folder> "
                 "[trajectories.yaml <name>] [--no-noise]\n";
    return 2;
  }
  try {
    cellsight::Scene scene = cellsight::loadScene(args[0]);
    scene.noise.enabled = noise;
    cellsight::makeDirs(args[1]);
    auto t0 = std::chrono::steady_clock::now();
    auto geometry = std::make_shared<cellsight::CellGeometry>(scene);
    cellsight::ScannerRenderer scanner(geometry);
    cellsight::FixtureRenderer fixture(geometry);
    std::cout << "scene ready in "
              << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()
              << " s; " << scanner.pixelsWithSurface() << " scanner pixels see a surface\n";
    cellsight::Trajectory traj;
    traj.poses.push_back(scene.robot.home);
    if (args.size() == 4) traj = cellsight::loadTrajectories(args[2]).at(args[3]);
    cv::imwrite(args[1] + "/fixture_camera.png", fixture.render(1));
    for (size_t i = 0; i < traj.poses.size(); ++i) {
      t0 = std::chrono::steady_clock::now();
      const cv::Mat img = scanner.render(traj.poses[i], i);
      const double ms =
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      char name[64];
      std::snprintf(name, sizeof(name), "/frame_%04zu.png", i);
      cv::imwrite(args[1] + name, img);
      std::cout << name + 1 << ": " << ms << " ms\n";
    }
  } catch (const std::out_of_range&) {
    std::cerr << "trajectory '" << args[3] << "' not found in " << args[2] << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
