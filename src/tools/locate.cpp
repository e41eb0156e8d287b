// cellsight_locate: find one part in a whole scan from files, as a user with a part and a scan
// would. The part is a mesh (PLY, STL, OBJ, glTF, OFF, …) or a point cloud (PCD, or a PLY without
// faces, float or double coordinates); units by --model-scale / --scene-scale (0.001 for mm).
// Without --matching the settings are the shipped defaults scaled to the part's size and the
// scan's resolution. Prints the pose, optionally writes JSON and an overlay PNG; with --truth
// (a 4x4 matrix, row-major, model → scene) it reports the error. Files too big for --memory-mb
// are downsampled with a warning, or refused before anything is read when even reading would not
// fit. Exit 0 found, 3 not found, 1 error, CLI11's codes for bad options.
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <unordered_set>

#include "cellsight/common/errors.hpp"
#include "cellsight/common/file_io.hpp"
#include "cellsight/common/mesh.hpp"
#include "cellsight/common/scan_cloud.hpp"
#include "cellsight/eval/overlay.hpp"
#include "cellsight/localization/model_library.hpp"
#include "cellsight/localization/model_matching.hpp"
#include "cli_args.hpp"

using namespace cellsight;
using json = nlohmann::json;

namespace {

// Peak memory per scene point of reading + locating, measured on the PCL milk scene (313 k
// points) with /usr/bin/time; kept generous.
constexpr double kBytesPerPoint = 600.0;
constexpr double kBytesToRead = 64.0;  // the file in memory and the cloud arrays

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), ::tolower);
  return s;
}

/// Point count from the file's header (PLY: element vertex, PCD: POINTS / WIDTH x HEIGHT), before
/// any of it is loaded; other formats: an upper bound from the file size.
double pointsInFile(const std::string& path) {
  const std::string ext = lower(std::filesystem::path(path).extension().string());
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ConfigError(path + ": cannot open the file");
  std::string line;
  double points = -1, width = -1, height = 1;
  for (int n = 0; n < 200 && std::getline(in, line); ++n) {
    std::istringstream ls(line);
    std::string w1, w2;
    ls >> w1;
    if (ext == ".ply" && w1 == "element" && (ls >> w2) && w2 == "vertex") ls >> points;
    if (ext == ".pcd" && w1 == "POINTS") ls >> points;
    if (ext == ".pcd" && w1 == "WIDTH") ls >> width;
    if (ext == ".pcd" && w1 == "HEIGHT") ls >> height;
    if (w1 == "end_header" || w1 == "DATA") break;
  }
  if (points < 0 && width >= 0) points = width * height;
  if (points < 0 || !std::isfinite(points)) points = static_cast<double>(std::filesystem::file_size(path)) / 12.0;
  return points;
}

/// Mesh, or cloud in `cloud` (faces empty) — by extension; PLY without faces is a cloud.
TriangleMesh loadModelOrCloud(const std::string& path, double scale, ScanCloud* cloud) {
  const std::string ext = lower(std::filesystem::path(path).extension().string());
  if (ext == ".pcd") {
    *cloud = loadCloud(path);
    for (auto& p : cloud->points) p *= static_cast<float>(scale);
    return {};
  }
  TriangleMesh mesh = loadMesh(path, scale);  // PLY: own reader (float or double); others: assimp
  if (mesh.faces.empty()) {
    for (const auto& v : mesh.vertices) cloud->append(v, 0.f);
    mesh.vertices.clear();
  }
  return mesh;
}

ScanCloud loadScene(const std::string& path, double scale) {
  ScanCloud scene;
  const TriangleMesh mesh = loadModelOrCloud(path, scale, &scene);
  for (const auto& v : mesh.vertices) scene.append(v, 0.f);  // a mesh as the scene: its vertices
  scene.normals.clear();
  return scene;
}

/// One point per cell of a grid coarse enough to keep at most `target` points.
ScanCloud downsample(const ScanCloud& in, size_t target) {
  double leaf = std::max(1e-6, medianPointSpacing(in) * std::sqrt(static_cast<double>(in.size()) / target));
  for (int round = 0; round < 20; ++round, leaf *= 1.3) {
    std::unordered_set<uint64_t> seen;
    ScanCloud out;
    for (size_t i = 0; i < in.size(); ++i) {
      const Eigen::Vector3f g = in.points[i] / static_cast<float>(leaf);
      const uint64_t key = (static_cast<uint64_t>(static_cast<int64_t>(std::floor(g.x())) & 0x1FFFFF) << 42) |
                           (static_cast<uint64_t>(static_cast<int64_t>(std::floor(g.y())) & 0x1FFFFF) << 21) |
                           (static_cast<uint64_t>(static_cast<int64_t>(std::floor(g.z())) & 0x1FFFFF));
      if (seen.insert(key).second) out.append(in.points[i], in.intensity.empty() ? 0.f : in.intensity[i]);
    }
    if (out.size() <= target) return out;
  }
  throw std::runtime_error("could not downsample the scene below " + std::to_string(target) + " points");
}

Eigen::Vector3f vec3(const std::vector<double>& v) { return Eigen::Vector3d(v[0], v[1], v[2]).cast<float>(); }

}  // namespace

int main(int argc, char** argv) {
  std::string model_file, scene_file, matching_file, truth_file, json_file, png_file;
  double model_scale = 1.0, scene_scale = 1.0, memory_mb = 4096;
  std::vector<double> model_sensor{0, 0, 0}, viewpoint{0, 0, 0};
  bool no_downsample = false;
  CLI::App app("Finds one part in a whole scan from files: prints its pose (model -> scene), fitness and RMSE; "
               "with --truth, the error.",
               "cellsight_locate");
  app.add_option("--model", model_file, "the part: mesh (.ply with faces, .stl, .obj, .gltf/.glb, .off, ...) or "
                                        "point cloud (.pcd, .ply without faces)")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--scene", scene_file, "the scan: point cloud (.pcd, .ply; float or double coordinates)")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--model-scale", model_scale, "multiplies the model's coordinates into metres (0.001: millimetres)")
      ->check(cellsight_tools::positive())
      ->capture_default_str();
  app.add_option("--scene-scale", scene_scale, "multiplies the scan's coordinates into metres")
      ->check(cellsight_tools::positive())
      ->capture_default_str();
  app.add_option("--matching", matching_file, "matching settings YAML; default: the shipped settings scaled to the "
                                              "part's size and the scan's resolution")
      ->check(CLI::ExistingFile);
  app.add_option("--model-sensor", model_sensor, "where a cloud model was seen from, model frame [m] (orients normals)")
      ->expected(3)
      ->capture_default_str();
  app.add_option("--viewpoint", viewpoint, "the scanner's position in the scan's frame [m] (visible-surface check)")
      ->expected(3)
      ->capture_default_str();
  app.add_option("--truth", truth_file, "true pose model -> scene: 16 numbers, a 4x4 matrix row by row (metres "
                                        "after scaling); turns on the error report")
      ->check(CLI::ExistingFile);
  app.add_option("--json", json_file, "write the result to this JSON file");
  app.add_option("--png", png_file, "write an overlay: the scan in grey, the located part in red");
  app.add_option("--memory-mb", memory_mb, "memory the scan may take; a bigger one is downsampled (with a warning)")
      ->check(cellsight_tools::positive())
      ->capture_default_str();
  app.add_flag("--no-downsample", no_downsample, "refuse a scan over --memory-mb instead of downsampling it");
  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  return cellsight_tools::runTool([&]() -> int {
    // memory: checked from the headers before anything is read
    const double budget = memory_mb * 1024 * 1024;
    const double scene_points = pointsInFile(scene_file);
    if (scene_points * kBytesToRead > budget || (no_downsample && scene_points * kBytesPerPoint > budget)) {
      std::ostringstream m;
      m << scene_file << ": " << static_cast<long long>(scene_points) << " points need about "
        << static_cast<long long>(scene_points * (no_downsample ? kBytesPerPoint : kBytesToRead) / 1048576)
        << " MB, over --memory-mb " << memory_mb << ": crop or downsample the file first, or raise the limit";
      throw std::runtime_error(m.str());
    }
    if (pointsInFile(model_file) * kBytesPerPoint > budget)
      throw std::runtime_error(model_file + ": the model is too big for --memory-mb " + std::to_string(memory_mb));
    ScanCloud model_cloud;
    const TriangleMesh mesh = loadModelOrCloud(model_file, model_scale, &model_cloud);
    ScanCloud scene = loadScene(scene_file, scene_scale);
    if (scene.size() < 10) throw std::runtime_error(scene_file + ": fewer than 10 finite points");
    const size_t fit = static_cast<size_t>(budget / kBytesPerPoint);
    if (scene.size() > fit) {
      const size_t before = scene.size();
      scene = downsample(scene, fit);
      std::fprintf(stderr, "warning: %s: %zu points downsampled to %zu to stay within --memory-mb %.0f\n",
                   scene_file.c_str(), before, scene.size(), memory_mb);
    }
    auto lib = std::make_shared<ModelLibrary>();
    if (!mesh.faces.empty()) {
      lib->addMeshModel("model", mesh);
    } else {
      lib->addCloudModel("model", model_cloud, vec3(model_sensor));
    }
    const double diagonal = lib->model("model").bounds.diagonal().norm();
    ScanFigures scan;
    MatchingConfig cfg = matching_file.empty() ? scaledMatchingConfig(MatchingConfig(), diagonal, scene, &scan)
                                               : loadMatchingConfig(matching_file);
    if (!matching_file.empty()) scan = {medianPointSpacing(scene), medianPlaneResidual(scene, cfg.voxel)};
    std::string settings = matching_file;
    if (matching_file.empty()) {
      char s[128];
      std::snprintf(s, sizeof s, "scaled defaults; max_rmse %.3f mm from the scan's scatter %.3f mm", cfg.max_rmse * 1e3,
                    scan.noise * 1e3);
      settings = s;
    }
    cfg.viewpoint = vec3(viewpoint);
    cfg.min_coverage = 0;  // a whole scan, not a cluster
    cfg.max_instances = 1;
    ModelMatcher matcher(lib, cfg);
    MatchStats st;
    const auto dets = matcher.locate({scene}, {}, &st);
    json j = {{"model", model_file},
              {"scene", scene_file},
              {"scene_points", scene.size()},
              {"model_diagonal_m", diagonal},
              {"scene_spacing_m", scan.spacing},
              {"scene_noise_m", scan.noise},
              {"settings", matching_file.empty() ? "defaults scaled to the part" : matching_file},
              {"voxel_m", cfg.voxel},
              {"max_rmse_m", cfg.max_rmse},
              {"locate_seconds", st.seconds},
              {"found", !dets.empty()}};
    for (const auto& w : st.warnings) j["warnings"].push_back(w);
    if (!dets.empty()) {
      const auto& d = dets[0];
      const Eigen::Vector3d t = d.pose.translation();
      const Eigen::Quaterniond q(d.pose.linear());
      j["pose"] = {{"xyz", {t.x(), t.y(), t.z()}}, {"quat", {q.x(), q.y(), q.z(), q.w()}}};
      j["fitness"] = d.fitness;
      j["rmse_mm"] = d.rmse * 1e3;
      std::printf("found: xyz %.6f %.6f %.6f m, quat (x y z w) %.6f %.6f %.6f %.6f; fitness %.3f, rmse %.3f mm, "
                  "%.2f s, voxel %.1f mm (%s)\n",
                  t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w(), d.fitness, d.rmse * 1e3, st.seconds, cfg.voxel * 1e3, settings.c_str());
    } else {
      std::printf("not found (%.2f s, voxel %.1f mm; %s)%s\n", st.seconds, cfg.voxel * 1e3, settings.c_str(),
                  st.rejected.empty() ? "" : "; the best poses refused, and why:");
      j["rejected"] = json::array();
      for (const auto& r : st.rejected) {
        std::printf("  fitness %.3f, coverage %.3f, rmse %.3f mm: %s\n", r.fitness, r.coverage, r.rmse * 1e3, r.refused_by.c_str());
        j["rejected"].push_back({{"fitness", r.fitness}, {"coverage", r.coverage}, {"rmse_mm", r.rmse * 1e3}, {"refused_by", r.refused_by}});
      }
    }
    if (!truth_file.empty()) {
      std::ifstream tf(truth_file);
      Eigen::Matrix4d M;
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c)
          if (!(tf >> M(r, c))) throw ConfigError(truth_file + ": expected 16 numbers (a 4x4 matrix, row by row)");
      const Eigen::Isometry3d truth(M);  // metres of the scene after --scene-scale
      if (!dets.empty()) {
        const PoseError e = poseError(lib->model("model").info, matcher.centroid("model"), dets[0].pose, truth);
        j["t_err_mm"] = e.translation * 1e3;
        j["r_err_deg"] = e.rotation * 180 / M_PI;
        std::printf("error vs %s: %.3f mm, %.3f deg\n", truth_file.c_str(), e.translation * 1e3, e.rotation * 180 / M_PI);
      }
    }
    if (!json_file.empty()) writeFileAtomic(json_file, j.dump(2) + "\n");
    if (!png_file.empty()) {
      const ScanCloud samples = mesh.faces.empty() ? model_cloud : sampleMesh(mesh, std::max(0.002, cfg.voxel), 3);
      const Eigen::Isometry3f T = dets.empty() ? Eigen::Isometry3f::Identity() : Eigen::Isometry3f(dets[0].pose.cast<float>());
      std::vector<uchar> buf;
      cv::imencode(".png", drawDetectionOverlay(scene, samples.points, dets.empty() ? nullptr : &T), buf);
      writeFileAtomic(png_file, std::string(buf.begin(), buf.end()));
    }
    return dets.empty() ? 3 : 0;
  });
}
