#include "cellsight/sim/scene.hpp"

#include <sys/stat.h>

#include <cmath>
#include <random>
#include <set>

#include "cellsight/common/file_io.hpp"
#include "cellsight/common/yaml_reader.hpp"

namespace cellsight {

namespace {

bool fileExists(const std::string& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0;
}

double positive(const YamlMap& m, const std::string& key, double def) {
  const double v = m.getDouble(key, def);
  if (!(v > 0)) m.fail(key, "must be > 0 (got " + std::to_string(v) + ")");
  return v;
}

double inRange(const YamlMap& m, const std::string& key, double def, double lo, double hi) {
  const double v = m.getDouble(key, def);
  if (v < lo || v > hi) {
    m.fail(key, "must lie in [" + std::to_string(lo) + ", " + std::to_string(hi) + "] (got " +
                    std::to_string(v) + ")");
  }
  return v;
}

CameraConfig parseCamera(const YamlMap& m, const std::string& default_name) {
  CameraConfig c;
  c.intrinsics.camera_name = m.getString("name", default_name);
  c.frame_id = m.getString("frame_id", default_name + "_optical");
  auto res = m.getDoubles("resolution", 2);
  for (double r : res) {  // checked before the cast: a double beyond int is undefined there
    if (!(r >= 1 && r <= kMaxImageSide && r == std::floor(r)))
      m.fail("resolution", "must be two whole numbers of pixels in [1, " + std::to_string(kMaxImageSide) +
                               "] (got " + std::to_string(r) + ")");
  }
  c.intrinsics.width = static_cast<int>(res[0]);
  c.intrinsics.height = static_cast<int>(res[1]);
  auto f = m.getDoubles("focal_px", 2);
  c.intrinsics.fx = f[0];
  c.intrinsics.fy = f[1];
  if (m.has("principal_point")) {
    auto pp = m.getDoubles("principal_point", 2);
    c.intrinsics.cx = pp[0];
    c.intrinsics.cy = pp[1];
  } else {
    c.intrinsics.cx = (c.intrinsics.width - 1) / 2.0;
    c.intrinsics.cy = (c.intrinsics.height - 1) / 2.0;
  }
  if (m.has("distortion")) {
    auto d = m.getDoubles("distortion", 5);
    for (int i = 0; i < 5; ++i) c.intrinsics.dist[i] = d[i];
  }
  c.T_base_camera = m.getPose("pose");
  c.encoding = m.getString("encoding", "mono8");
  if (c.encoding != "mono8" && c.encoding != "rgb8") {
    m.fail("encoding", "must be mono8 or rgb8 (got '" + c.encoding + "')");
  }
  c.frame_rate = m.getDouble("frame_rate", 0.0);
  if (c.frame_rate < 0) m.fail("frame_rate", "must be >= 0 (0 = hardware trigger)");
  c.blur_sigma_px = m.getDouble("blur_sigma_px", 0.0);
  if (c.blur_sigma_px < 0) m.fail("blur_sigma_px", "must be >= 0");
  c.intrinsics.validate(m.where("resolution/focal_px"));
  m.finish();
  return c;
}

void checkSeesWorkspace(const CameraConfig& c, const Eigen::AlignedBox3d& ws,
                        const std::string& where) {
  // The camera must see at least a part of the workspace: sample the box on a grid.
  int seen = 0;
  const Eigen::Isometry3d T_camera_base = c.T_base_camera.inverse();
  for (int i = 0; i <= 4; ++i) {
    for (int j = 0; j <= 4; ++j) {
      for (int k = 0; k <= 1; ++k) {
        Eigen::Vector3d p = ws.min() + Eigen::Vector3d(i / 4.0, j / 4.0, k).cwiseProduct(ws.sizes());
        Eigen::Vector3d pc = T_camera_base * p;
        if (pc.z() <= 1e-6) continue;
        Eigen::Vector2d uv = c.intrinsics.project(pc);
        if (uv.x() >= 0 && uv.y() >= 0 && uv.x() < c.intrinsics.width &&
            uv.y() < c.intrinsics.height)
          ++seen;
      }
    }
  }
  if (seen == 0) {
    throw ConfigError(where + ": the camera sees none of the workspace (check its pose: the "
                              "optical frame looks along +z, x right, y down)");
  }
}

}  // namespace


Scene loadScene(const std::string& path, const SceneLoadOptions& options) {
  YamlMap m(loadYamlFile(path), path);
  Scene s;
  s.file = path;
  s.name = m.getString("name", "scene");
  if (m.has("frames")) {
    YamlMap f = m.getMap("frames");
    s.base_frame = f.getString("base", s.base_frame);
    s.flange_frame = f.getString("flange", s.flange_frame);
    s.laser_frame = f.getString("laser", s.laser_frame);
    f.finish();
  }
  {
    YamlMap w = m.getMap("workspace");
    Eigen::Vector3d lo = w.getVector3("min"), hi = w.getVector3("max");
    if ((hi.array() <= lo.array()).any()) w.fail("max", "must exceed min on every axis");
    s.workspace = Eigen::AlignedBox3d(lo, hi);
    w.finish();
  }
  if (m.has("table")) {
    YamlMap t = m.getMap("table");
    s.table.z = t.getDouble("z", 0.0);
    auto c = t.getDoubles("center", 2);
    s.table.center = {c[0], c[1]};
    auto sz = t.getDoubles("size", 2);
    s.table.size = {sz[0], sz[1]};
    if (sz[0] <= 0 || sz[1] <= 0) t.fail("size", "must be positive");
    s.table.reflectivity = inRange(t, "reflectivity", 0.35, 0.0, 1.0);
    t.finish();
  }
  std::vector<std::string> model_paths = options.model_paths;
  if (model_paths.empty()) model_paths.push_back(parentDir(path) + "/../models");
  std::set<std::string> names;
  if (m.has("objects")) {
    for (const YamlMap& o : m.getMapList("objects")) {
      SceneObject obj;
      obj.model = o.getString("model");
      obj.name = o.getString("name", obj.model);
      if (!names.insert(obj.name).second) o.fail("name", "'" + obj.name + "' is used twice");
      std::string model_yaml;
      for (const auto& dir : model_paths) {
        const std::string candidate = dir + "/" + obj.model + "/model.yaml";
        if (fileExists(candidate)) {
          model_yaml = candidate;
          break;
        }
      }
      if (model_yaml.empty()) {
        o.fail("model", "no model '" + obj.model + "' (looked for <dir>/" + obj.model +
                            "/model.yaml in " + model_paths.front() + ")");
      }
      obj.info = loadModelInfo(model_yaml);
      obj.T_base_object = o.getPose("pose");
      obj.reflectivity = inRange(o, "reflectivity", 0.6, 0.0, 1.0);
      obj.shininess = inRange(o, "shininess", 0.0, 0.0, 1.0);
      o.finish();
      s.objects.push_back(obj);
    }
  }
  if (m.has("fixtures")) {
    for (const YamlMap& f : m.getMapList("fixtures")) {
      QrFixture q;
      q.id = f.getString("id");
      if (!names.insert(q.id).second) f.fail("id", "'" + q.id + "' is used twice");
      q.payload = f.getString("payload");
      if (q.payload.empty()) f.fail("payload", "must not be empty");
      q.code_size = positive(f, "code_size", 0.04);
      q.plate_size = f.getDouble("plate_size", q.code_size * 1.5);
      if (q.plate_size < q.code_size) f.fail("plate_size", "must be >= code_size");
      q.T_base_fixture = f.getPose("pose");
      f.finish();
      s.fixtures.push_back(q);
    }
  }
  s.scanner_camera = parseCamera(m.getMap("scanner_camera"), "scanner_camera");
  checkSeesWorkspace(s.scanner_camera, s.workspace, m.where("scanner_camera.pose"));
  if (m.has("fixture_camera")) {
    s.fixture_camera = parseCamera(m.getMap("fixture_camera"), "fixture_camera");
    checkSeesWorkspace(s.fixture_camera, s.workspace, m.where("fixture_camera.pose"));
  } else {
    s.fixture_camera = s.scanner_camera;
    s.fixture_camera.intrinsics.camera_name = "fixture_camera";
    s.fixture_camera.frame_id = "fixture_camera_optical";
  }
  {
    YamlMap l = m.getMap("laser");
    s.laser.T_flange_laser = l.getPose("pose_in_flange");
    s.laser.fan_angle = inRange(l, "fan_angle", 1.0, 0.01, 3.0);
    s.laser.line_width = positive(l, "line_width", 0.5e-3);
    s.laser.brightness = inRange(l, "brightness", 220.0, 1.0, 255.0);
    s.laser.colour = l.getString("colour", "red");
    if (s.laser.colour != "red" && s.laser.colour != "green" && s.laser.colour != "blue") {
      l.fail("colour", "must be red, green or blue");
    }
    l.finish();
  }
  if (m.has("noise")) {
    YamlMap n = m.getMap("noise");
    s.noise.enabled = n.getBool("enabled", true);
    s.noise.sensor_sigma = inRange(n, "sensor_sigma", s.noise.sensor_sigma, 0, 100);
    s.noise.ambient = inRange(n, "ambient", s.noise.ambient, 0, 255);
    s.noise.speckle = inRange(n, "speckle", s.noise.speckle, 0, 1);
    s.noise.dropout_probability = inRange(n, "dropout_probability", s.noise.dropout_probability, 0, 1);
    s.noise.stray_gain = inRange(n, "stray_gain", s.noise.stray_gain, 0, 1);
    s.noise.seed = static_cast<uint64_t>(n.getInt("seed", 1));
    n.finish();
  }
  if (m.has("robot")) {
    YamlMap r = m.getMap("robot");
    s.robot.home = r.getPose("home", s.robot.home);
    s.robot.linear_speed = positive(r, "linear_speed", s.robot.linear_speed);
    s.robot.angular_speed = positive(r, "angular_speed", s.robot.angular_speed);
    s.robot.settle_time = inRange(r, "settle_time", s.robot.settle_time, 0, 10);
    if (r.has("reach")) {
      YamlMap reach = r.getMap("reach");
      s.robot.reach = Eigen::AlignedBox3d(reach.getVector3("min"), reach.getVector3("max"));
      reach.finish();
    }
    r.finish();
  }
  s.as_built.drawn_scanner_camera = s.scanner_camera.T_base_camera;
  s.as_built.drawn_fixture_camera = s.fixture_camera.T_base_camera;
  s.as_built.drawn_laser = s.laser.T_flange_laser;
  if (m.has("as_built")) {
    YamlMap a = m.getMap("as_built");
    AsBuiltConfig& c = s.as_built;
    c.perfect = a.getBool("perfect", false);
    c.seed = static_cast<uint64_t>(a.getInt("seed", 1));
    auto mount = [&](const std::string& key, double& t_mm, double& r_deg) {
      if (!a.has(key)) return;
      YamlMap k = a.getMap(key);
      t_mm = inRange(k, "translation_mm", 0.0, 0.0, 50.0);
      r_deg = inRange(k, "rotation_deg", 0.0, 0.0, 10.0);
      k.finish();
    };
    mount("camera_mount", c.camera_translation_mm, c.camera_rotation_deg);
    mount("laser_mount", c.laser_translation_mm, c.laser_rotation_deg);
    if (a.has("robot")) {
      YamlMap r = a.getMap("robot");
      c.robot.joint_offset_deg = inRange(r, "joint_offset_deg", c.robot.joint_offset_deg, 0.0, 1.0);
      c.robot.link_mm = inRange(r, "link_mm", c.robot.link_mm, 0.0, 10.0);
      c.robot.twist_deg = inRange(r, "twist_deg", c.robot.twist_deg, 0.0, 1.0);
      c.robot.repeatability_mm = inRange(r, "repeatability_mm", c.robot.repeatability_mm, 0.0, 1.0);
      c.robot.repeatability_deg = inRange(r, "repeatability_deg", c.robot.repeatability_deg, 0.0, 1.0);
      r.finish();
    }
    a.finish();
    c.robot.enabled = !c.perfect;
    c.robot.seed = c.seed * 7919 + 17;
    if (!c.perfect) {
      // seeded mounting offsets: translation σ per axis, rotation σ per axis (small angles)
      std::mt19937_64 rng(c.seed);
      std::normal_distribution<double> n01(0.0, 1.0);
      auto perturb = [&](Eigen::Isometry3d& T, double t_mm, double r_deg) {
        const Eigen::Vector3d dt(n01(rng), n01(rng), n01(rng));
        const Eigen::Vector3d dr(n01(rng), n01(rng), n01(rng));
        const Eigen::Vector3d w = dr * r_deg * M_PI / 180.0;
        Eigen::Isometry3d D = Eigen::Isometry3d::Identity();
        if (w.norm() > 0) D.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
        D.translation() = dt * t_mm * 1e-3;
        T = T * D;  // offset in the mounted part's own frame
      };
      perturb(s.scanner_camera.T_base_camera, c.camera_translation_mm, c.camera_rotation_deg);
      perturb(s.fixture_camera.T_base_camera, c.camera_translation_mm, c.camera_rotation_deg);
      perturb(s.laser.T_flange_laser, c.laser_translation_mm, c.laser_rotation_deg);
    }
  }
  m.finish();
  // Meshes are loaded and validated by the renderer; check here that each is valid so that a
  // bad mesh fails at start-up with the scene's name attached.
  for (const auto& o : s.objects) {
    try {
      loadValidMesh(o.info.mesh_file);
    } catch (const ConfigError& e) {
      throw ConfigError(path + ": object '" + o.name + "': " + e.what());
    }
  }
  return s;
}

void makePerfect(Scene& scene) {
  scene.scanner_camera.T_base_camera = scene.as_built.drawn_scanner_camera;
  scene.fixture_camera.T_base_camera = scene.as_built.drawn_fixture_camera;
  scene.laser.T_flange_laser = scene.as_built.drawn_laser;
  scene.as_built.perfect = true;
  scene.as_built.robot.enabled = false;
}

}  // namespace cellsight
