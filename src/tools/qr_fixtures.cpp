// cellsight_qr_fixtures: the QR fixture chain from files.
//   detect  one image → decoded codes, their poses, the fixtures and user frames (JSON)
//   sim     a scene's fixture camera rendered N times → UCS error vs the simulator's truth
//   decode  a folder of photos with expected texts → byte-exact decode rate (all decoders, zbar alone)
#include <cmath>
#include <fstream>
#include <map>
#include <iostream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "cellsight/common/calibration.hpp"
#include "cellsight/common/file_io.hpp"
#include "cellsight/common/image_io.hpp"
#include "cellsight/eval/fixture_eval.hpp"
#include "cli_args.hpp"
#include "json_pose.hpp"
#include "gnuplot.hpp"

using namespace cellsight;
using nlohmann::json;

namespace {

// {xyz, quat [x, y, z, w]} as the project's JSON files write poses, and the heading of x
json ucsJson(const Eigen::Isometry3d& T) {
  const Eigen::Quaterniond q(T.linear());
  return {{"xyz", {T.translation().x(), T.translation().y(), T.translation().z()}},
          {"quat", {q.x(), q.y(), q.z(), q.w()}},
          {"yaw", std::atan2(T.linear()(1, 0), T.linear()(0, 0))}};
}

json adjustmentJson(const AdjustmentResult& r) {
  json codes = json::array();
  for (const auto& c : r.codes) {
    json j = {{"payload", c.detection.payload}, {"decoder", c.detection.decoder}, {"status", c.status},
              {"refined", c.detection.refined}, {"located", c.detection.located}, {"modules", c.detection.modules},
              {"edge_rms_px", c.detection.edge_rms_px}};
    json corners = json::array();
    for (const auto& p : c.detection.corners) corners.push_back({p.x, p.y});
    j["corners"] = corners;
    if (c.status == "ok") {
      j["free_rms_px"] = c.free_pose.rms_px;
      j["T_base_code"] = ucsJson(c.T_base_code);
    }
    codes.push_back(j);
  }
  json fixtures = json::array();
  for (const auto& f : r.fixtures) {
    fixtures.push_back({{"id", f.id}, {"type", f.type}, {"program", f.program}, {"markers", f.inliers},
                        {"ucs", ucsJson(f.T_base_ucs)}, {"ucs_free", ucsJson(f.T_base_ucs_free)},
                        {"fixture", ucsJson(f.T_base_fixture)}, {"rms_px", f.rms_px},
                        {"sigma_translation_mm", f.sigma_translation * 1000},
                        {"sigma_yaw_deg", f.sigma_yaw * 180 / M_PI}});
  }
  return {{"codes", codes}, {"fixtures", fixtures}, {"messages", r.messages}};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app("The QR fixture chain from files: detection, code poses, user frames, and their accuracy.",
               "cellsight_qr_fixtures");
  app.require_subcommand(1);
  std::string image, camera_file, pose_file, registry_file, scene_file, calibration, folder, json_out;
  std::string method = "visp";
  bool free_pose = false;
  int renders = 100;
  uint64_t seed = 1;

  CLI::App* det = app.add_subcommand("detect", "one image: codes, poses, fixtures and user frames as JSON");
  det->add_option("--image", image, "fixture camera image")->required()->check(CLI::ExistingFile);
  det->add_option("--camera", camera_file, "camera_info YAML of the fixture camera")->required()->check(CLI::ExistingFile);
  det->add_option("--camera-pose", pose_file, "calibration YAML base_link -> fixture camera optical frame")
      ->required()->check(CLI::ExistingFile);
  det->add_option("--registry", registry_file, "fixture registry (config/fixtures.yaml)")->required()->check(CLI::ExistingFile);

  CLI::App* sim = app.add_subcommand("sim", "render a scene's fixture camera N times and compare the user frames with the truth");
  sim->add_option("--scene", scene_file, "scene YAML")->required()->check(CLI::ExistingFile);
  sim->add_option("--registry", registry_file, "fixture registry")->required()->check(CLI::ExistingFile);
  sim->add_option("--calibration", calibration,
                  "folder with fixture_camera.yaml and fixture_camera_pose.yaml (a calibration of the cell, not its truth)")
      ->required()->check(CLI::ExistingDirectory);
  sim->add_option("--renders", renders, "renders (sensor noise redrawn each time)")
      ->check(cellsight_tools::positiveInt())->capture_default_str();
  sim->add_option("--seed", seed, "noise seed")->capture_default_str();
  std::string dump_misses;
  sim->add_option("--dump-misses", dump_misses, "write the renders in which a fixture was not reported here (PNG)");

  std::string node_file;
  CLI::App* cmp = app.add_subcommand("compare", "the user frames qr_frame_adjustment wrote (~output_file) vs the scene's truth");
  cmp->add_option("--fixtures", node_file, "the node's JSON (e.g. out/demo/fixtures_raw.json)")->required()->check(CLI::ExistingFile);
  cmp->add_option("--scene", scene_file, "scene YAML")->required()->check(CLI::ExistingFile);
  cmp->add_option("--registry", registry_file, "fixture registry")->required()->check(CLI::ExistingFile);

  std::string plot_png;
  HandEyeSweepConfig hc;
  CLI::App* sweep = app.add_subcommand("handeye-sweep",
                                       "fixture camera to robot calibration, every method on the same synthetic views, "
                                       "one noise factor swept at a time");
  sweep->add_option("--scene", scene_file, "scene YAML (its fixture camera)")->required()->check(CLI::ExistingFile);
  sweep->add_option("--views", hc.views, "flange poses per calibration")->check(cellsight_tools::positiveInt())->capture_default_str();
  sweep->add_option("--trials", hc.trials, "data sets per point")->check(cellsight_tools::positiveInt())->capture_default_str();
  sweep->add_option("--seed", hc.seed, "noise seed")->capture_default_str();
  sweep->add_option("--plot", plot_png, "PNG: table-point error per method over each factor (gnuplot; data and script beside it)");

  CLI::App* dec = app.add_subcommand("decode", "byte-exact decode rate on photos with <name>.txt beside each");
  dec->add_option("--images", folder, "folder (searched recursively)")->required()->check(CLI::ExistingDirectory);

  for (CLI::App* s : {det, sim}) {
    s->add_option("--method", method, "free 6-DoF pose: visp (DEMENTHON then VIRTUAL_VS) | ippe_square")
        ->check(CLI::IsMember({"visp", "ippe_square"}))->capture_default_str();
    s->add_flag("--free", free_pose, "report the free 6-DoF pose instead of the table-constrained one");
  }
  for (CLI::App* s : {det, sim, dec, cmp, sweep}) s->add_option("--json", json_out, "also write the JSON here (atomically)");
  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;

  return cellsight_tools::runTool([&] {
    FixtureAdjustmentConfig ac;
    ac.table_constrained = !free_pose;
    ac.free_method = parseCodePoseMethod(method);
    json out;
    if (*det) {
      const FixtureRegistry reg = loadFixtureRegistry(registry_file);
      const CameraIntrinsics cam = loadCameraInfoYaml(camera_file);
      const TransformCalibration pose = loadTransformCalibration(pose_file);
      const cv::Mat img = readImage(image, cv::IMREAD_GRAYSCALE);
      if (img.cols != cam.width || img.rows != cam.height) {
        throw std::runtime_error("image " + image + " is " + std::to_string(img.cols) + "x" + std::to_string(img.rows) +
                                 " but the camera file " + camera_file + " calibrates " + std::to_string(cam.width) +
                                 "x" + std::to_string(cam.height));
      }
      QrDetectorConfig dc;
      dc.expected_codes = 0;
      for (const auto& f : reg.fixtures) dc.expected_codes += static_cast<int>(f.codes.size());
      QrDetector detector(dc);
      out = adjustmentJson(adjustFixtures(detector.detect(img, &cam), reg, cam, pose.T_parent_child, ac));
    } else if (*sim) {
      const Scene scene = loadScene(scene_file);
      const FixtureRegistry reg = loadFixtureRegistry(registry_file);
      const CameraIntrinsics cam = loadCameraInfoYaml(calibration + "/fixture_camera.yaml");
      const TransformCalibration pose = loadTransformCalibration(calibration + "/fixture_camera_pose.yaml");
      FixtureSimConfig sc;
      sc.renders = renders;
      sc.seed = seed;
      sc.dump_misses = dump_misses;
      sc.adjustment = ac;
      const FixtureSimResult r = evaluateFixturesSim(scene, reg, cam, pose.T_parent_child, sc);
      json list = json::array();
      for (const auto& f : r.fixtures) {
        constexpr double mm = 1000, deg = 180 / M_PI;
        list.push_back({{"payload", f.type}, {"program", f.program}, {"markers", f.markers}, {"found", f.found},
                        {"t_err_mm", f.t_err.mean * mm}, {"t_sigma_mm", f.t_err.sigma * mm}, {"t_max_mm", f.t_err.max * mm},
                        {"r_err_deg", f.r_err.mean * deg}, {"r_sigma_deg", f.r_err.sigma * deg}, {"r_max_deg", f.r_err.max * deg},
                        {"free_t_err_mm", f.free_t_err.mean * mm}, {"free_t_sigma_mm", f.free_t_err.sigma * mm},
                        {"free_r_err_deg", f.free_r_err.mean * deg}, {"free_r_sigma_deg", f.free_r_err.sigma * deg},
                        {"single_code_free_t_err_mm", f.single_t_err.mean * mm},
                        {"single_code_free_r_err_deg", f.single_r_err.mean * deg},
                        {"reported_sigma_mm", f.reported_sigma.mean * mm}});
      }
      out = {{"renders", r.renders}, {"pose", free_pose ? "free 6-DoF (" + method + ")" : "table-constrained"},
             {"calibration", calibration}, {"fixtures", list}, {"false_fixtures", r.false_fixtures},
             {"detect_ms_median", r.detect_ms_median}, {"adjust_ms_median", r.adjust_ms_median},
             {"messages", r.messages}, {"decoders", r.decoders}};
    } else if (*sweep) {
      const Scene scene = loadScene(scene_file);
      const auto rows = handEyeSweep(scene, hc);
      json list = json::array();
      std::map<std::string, std::vector<const HandEyeSweepRow*>> by_factor;
      for (const auto& r : rows) {
        json methods = json::object();
        for (size_t k = 0; k < r.methods.size(); ++k) {
          methods[r.methods[k]] = {{"t_err_mm", std::isfinite(r.t_err_mm[k]) ? json(r.t_err_mm[k]) : json(nullptr)},
                                   {"r_err_deg", std::isfinite(r.r_err_deg[k]) ? json(r.r_err_deg[k]) : json(nullptr)},
                                   {"failures", r.failures[k]}};
        }
        list.push_back({{"factor", r.factor}, {"value", r.value}, {"methods", methods}});
        by_factor[r.factor].push_back(&r);
      }
      out = {{"views", hc.views}, {"trials", hc.trials},
             {"realistic", {{"corner_sigma_px", hc.corner_sigma_px}, {"repeatability_mm", hc.repeatability_mm},
                            {"flange_rotation_deg", hc.flange_rotation_deg}, {"pointer_sigma_mm", hc.pointer_sigma_mm}}},
             {"error", "t_err_mm: a table point under the camera as the calibrated camera places it; r_err_deg: the camera's rotation"},
             {"rows", list}};
      if (!plot_png.empty()) {
        for (const auto& [factor, rs] : by_factor) {
          std::vector<double> x;
          std::vector<std::pair<std::string, std::vector<double>>> series;
          for (size_t k = 0; k < rs.front()->methods.size(); ++k) series.push_back({rs.front()->methods[k], {}});
          for (const HandEyeSweepRow* r : rs) {
            x.push_back(r->value);
            for (size_t k = 0; k < r->methods.size(); ++k) series[k].second.push_back(r->t_err_mm[k]);
          }
          std::string png = plot_png;
          const auto dot = png.rfind(".png");
          png = (dot == std::string::npos ? png : png.substr(0, dot)) + "_" + factor + ".png";
          cellsight_tools::plotLines(png, "fixture camera calibration: error at the table vs " + factor, factor,
                                     {"table point error [mm]", false, true}, x, series);
        }
      }
    } else if (*cmp) {
      const Scene scene = loadScene(scene_file);
      const FixtureRegistry reg = loadFixtureRegistry(registry_file);
      std::ifstream in(node_file);
      const json node = json::parse(in);
      json list = json::array();
      int missing = 0;
      for (const FixtureTruth& t : fixtureTruth(scene, reg)) {
        json row = {{"payload", t.payloads.front()}, {"payloads", t.payloads}, {"type", t.type}, {"program", t.program}};
        const json* found = nullptr;
        for (const auto& f : node.at("fixtures")) {
          if (f.at("id") == t.type) found = &f;
        }
        if (!found) {
          row["status"] = "not found";
          ++missing;
        } else {
          const auto [dt, dr] = poseDifference(cellsight_tools::poseFromJson(found->at("ucs")), t.T_base_ucs);
          const auto [fdt, fdr] = poseDifference(cellsight_tools::poseFromJson(found->at("ucs_free")), t.T_base_ucs);
          row["status"] = found->at("stale").get<bool>() ? "stale" : "ok";
          row["markers"] = found->at("markers");
          row["t_err_mm"] = dt * 1000;
          row["r_err_deg"] = dr * 180 / M_PI;
          row["free_t_err_mm"] = fdt * 1000;
          row["free_r_err_deg"] = fdr * 180 / M_PI;
        }
        list.push_back(row);
      }
      out = list;
      if (missing) std::cerr << "compare: " << missing << " fixture(s) of the scene not reported by the node\n";
    } else {
      const DecodeRate r = evaluateDecodeRate(folder);
      out = {{"images", r.images}, {"decoded", r.decoded}, {"zbar_alone", r.decoded_zbar_only},
             {"wechat_alone", r.decoded_wechat_only}, {"missed", r.missed}};
    }
    const std::string text = out.dump(2) + "\n";
    std::cout << text;
    if (!json_out.empty()) writeFileAtomic(json_out, text);
    return 0;
  });
}
