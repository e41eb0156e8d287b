// Renders simulated scanner frames of a scene without ROS: one PNG per pose of a trajectory
// (or the robot's home pose), plus the fixture camera view.
// Usage: cellsight_render_frame <scene.yaml> <out folder> [trajectories.yaml <name>] [--no-noise]
//        (--help for details; bad or unknown options are reported by CLI11 with a non-zero exit,
//        failures at run time print "error: ..." and exit 1)
#include <chrono>
#include <cstdio>
#include <iostream>
#include <opencv2/imgcodecs.hpp>

#include "cellsight/common/file_io.hpp"
#include "cellsight/sim/renderer.hpp"
#include "cellsight/common/trajectory.hpp"
#include "cli_args.hpp"

int main(int argc, char** argv) {
  std::vector<std::string> args(4);  // scene, out folder, trajectories file, trajectory name
  bool no_noise = false;
  CLI::App app("Renders simulated scanner frames of a scene without ROS: one PNG per pose of a trajectory (or the "
               "robot's home pose), plus the fixture camera view.",
               "cellsight_render_frame");
  app.add_option("scene", args[0], "scene YAML")->required()->check(CLI::ExistingFile);
  app.add_option("out", args[1], "output folder (created when missing)")->required();
  CLI::Option* traj_file = app.add_option("trajectories", args[2], "trajectories YAML")->check(CLI::ExistingFile);
  CLI::Option* traj_name = app.add_option("name", args[3], "trajectory name in it");
  traj_file->needs(traj_name);
  traj_name->needs(traj_file);
  app.add_flag("--no-noise", no_noise, "render without the noise model");
  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  const bool noise = !no_noise;
  const bool with_trajectory = traj_file->count() > 0;
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
    if (with_trajectory) traj = cellsight::loadTrajectories(args[2]).at(args[3]);
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
