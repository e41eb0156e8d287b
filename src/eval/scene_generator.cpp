#include "cellsight/eval/scene_generator.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <random>
#include <sstream>
#include <stdexcept>

#include "cellsight/common/file_io.hpp"
#include "cellsight/common/model_info.hpp"
#include "cellsight/common/polygon.hpp"
#include "cellsight/common/yaml_reader.hpp"

namespace cellsight {

namespace {

using Vec2 = Eigen::Vector2d;

struct Placed {
  Eigen::Vector2d centre;
  double radius = 0;
};

/// The part's footprint after `R`: the centre of its xy bounds, its radius about that centre,
/// and how far its lowest point lies below the origin.
void footprint(const TriangleMesh& mesh, const Eigen::Matrix3d& R, Eigen::Vector2d* centre, double* radius,
               double* min_z, double* height) {
  Eigen::AlignedBox3d box;
  for (const auto& v : mesh.vertices) box.extend(R * v.cast<double>());
  *centre = box.center().head<2>();
  double r = 0;
  for (const auto& v : mesh.vertices) r = std::max(r, ((R * v.cast<double>()).head<2>() - *centre).norm());
  *radius = r;
  *min_z = box.min().z();
  *height = box.sizes().z();
}

void emitObject(YAML::Emitter& out, const std::string& name, const std::string& model, const Eigen::Isometry3d& pose,
                double reflectivity) {
  out << YAML::Flow << YAML::BeginMap << YAML::Key << "name" << YAML::Value << name << YAML::Key << "model"
      << YAML::Value << model << YAML::Key << "pose" << YAML::Value;
  emitPose(out, pose);
  out << YAML::Key << "reflectivity" << YAML::Value << reflectivity << YAML::EndMap;
}

}  // namespace

std::vector<Eigen::Matrix3d> stableRestRotations(const TriangleMesh& mesh) {
  // flat sides: face normals (quantised) with their total area
  std::map<std::tuple<long, long, long>, std::pair<Eigen::Vector3d, double>> sides;
  double total = 0;
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3d a = mesh.vertices[f[0]].cast<double>(), b = mesh.vertices[f[1]].cast<double>(),
                          c = mesh.vertices[f[2]].cast<double>();
    const Eigen::Vector3d n2 = (b - a).cross(c - a);
    const double area = 0.5 * n2.norm();
    if (area <= 0) continue;
    total += area;
    const Eigen::Vector3d n = n2.normalized();
    const auto key = std::make_tuple(std::lround(n.x() * 50), std::lround(n.y() * 50), std::lround(n.z() * 50));
    auto& s = sides.try_emplace(key, Eigen::Vector3d::Zero(), 0.0).first->second;  // Eigen leaves a default vector unset
    s.first += n * area;
    s.second += area;
  }
  const Eigen::Vector3d centroid = mesh.surfaceCentroid();
  std::vector<std::pair<double, Eigen::Matrix3d>> found;  // (priority, rotation)
  for (const auto& [key, side] : sides) {
    if (side.second < 0.03 * total) continue;
    const Eigen::Vector3d n = side.first.normalized();
    // the side must be the part's extreme along n (a face on the outside, not a pocket floor)
    double extreme = -1e9;
    for (const auto& v : mesh.vertices) extreme = std::max(extreme, n.dot(v.cast<double>()));
    const Eigen::Matrix3d R = rotationBetween(n, -Eigen::Vector3d::UnitZ());
    std::vector<Vec2> support;
    for (const auto& v : mesh.vertices)
      if (n.dot(v.cast<double>()) > extreme - 1e-5) support.push_back((R * v.cast<double>()).head<2>());
    const std::vector<Vec2> hull = convexHull2d(support);
    if (!insideBy(hull, (R * centroid).head<2>(), 1e-3)) continue;
    const double priority = side.second;  // larger sides first
    found.emplace_back(priority, R);
  }
  std::sort(found.begin(), found.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  // the part as modelled stands on its z-min (the scenes' convention): always the first rest, even
  // when that side is not one flat face (a blade's curved underside, a sphere)
  std::vector<Eigen::Matrix3d> out{Eigen::Matrix3d::Identity()};
  for (const auto& f : found)
    if (!f.second.isIdentity(1e-6)) out.push_back(f.second);
  return out;
}

GeneratedScene generateScene(const std::string& base_scene_file, const std::string& models_dir, uint64_t seed,
                             const SceneGeneratorOptions& options, const std::string& out_dir) {
  namespace fs = std::filesystem;
  if (options.min_parts < 1 || options.max_parts < options.min_parts)
    throw std::invalid_argument("scene generator: need 1 <= min_parts <= max_parts");
  SceneLoadOptions base_options;
  base_options.model_paths = {models_dir};
  const Scene base = loadScene(base_scene_file, base_options);
  std::vector<std::string> ids = options.models;
  if (ids.empty()) {
    for (const auto& e : fs::directory_iterator(models_dir))
      if (fs::exists(e.path() / "model.yaml")) ids.push_back(e.path().filename().string());
    std::sort(ids.begin(), ids.end());
  }
  if (ids.empty()) throw std::runtime_error(models_dir + ": no models to place");
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0, 1);
  const Eigen::AlignedBox3d& ws = base.workspace;
  const double table_z = base.table.z;
  std::vector<Placed> placed;
  YAML::Emitter objects;
  objects << YAML::BeginSeq;
  GeneratedScene out;

  // one part (or distractor) of `mesh`: a rest, a yaw, a place; false when none was found
  auto place = [&](const TriangleMesh& mesh, bool lying, bool touching, const std::string& name, const std::string& model,
                   double reflectivity) {
    const auto rests = stableRestRotations(mesh);
    const Eigen::Matrix3d rest = lying && rests.size() > 1 ? rests[1 + static_cast<size_t>(U(rng) * (rests.size() - 1)) % (rests.size() - 1)]
                                                           : rests.front();
    for (int attempt = 0; attempt < 300; ++attempt) {
      const double yaw = 2 * M_PI * U(rng);
      const Eigen::Matrix3d R = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() * rest;
      Eigen::Vector2d c0;
      double r = 0, min_z = 0, height = 0;
      footprint(mesh, R, &c0, &r, &min_z, &height);
      if (table_z + height > ws.max().z()) return false;  // too tall for the scanner's volume in this rest
      Eigen::Vector2d c;
      int neighbour = -1;
      if (touching && !placed.empty()) {
        neighbour = static_cast<int>(U(rng) * placed.size()) % static_cast<int>(placed.size());
        const double th = 2 * M_PI * U(rng);
        c = placed[neighbour].centre + (placed[neighbour].radius + r + 5e-4) * Eigen::Vector2d(std::cos(th), std::sin(th));
      } else {
        c = Eigen::Vector2d(ws.min().x() + U(rng) * ws.sizes().x(), ws.min().y() + U(rng) * ws.sizes().y());
      }
      const double m = options.margin;
      if (c.x() - r < ws.min().x() + m || c.x() + r > ws.max().x() - m || c.y() - r < ws.min().y() + m ||
          c.y() + r > ws.max().y() - m)
        continue;
      bool clear = true;
      for (size_t j = 0; j < placed.size() && clear; ++j) {
        const double gap = static_cast<int>(j) == neighbour ? 0.0 : m;
        clear = (placed[j].centre - c).norm() >= placed[j].radius + r + gap;
      }
      if (!clear) continue;
      Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
      T.linear() = R;
      T.translation() << c.x() - c0.x(), c.y() - c0.y(), table_z - min_z;
      placed.push_back({c, r});
      emitObject(objects, name, model, T, reflectivity);
      return true;
    }
    return false;
  };

  const int n = options.min_parts + static_cast<int>(U(rng) * (options.max_parts - options.min_parts + 1));
  std::vector<std::string> pool;
  int parts = 0;
  // models are drawn until n parts stand in the workspace: one that does not fit as drawn
  // (lying too tall, touching with no room) tries standing and free, then gives its turn away
  for (int draw = 0; parts < n && draw < n + 2 * static_cast<int>(ids.size()); ++draw) {
    if (pool.empty()) {
      pool = ids;
      std::shuffle(pool.begin(), pool.end(), rng);
    }
    const std::string id = pool.back();
    pool.pop_back();
    const ModelInfo info = loadModelInfo(models_dir + "/" + id + "/model.yaml");
    const TriangleMesh mesh = loadMesh(info.mesh_file);
    const bool lying = U(rng) < options.lying_share, touching = U(rng) < options.touching_share;
    const double reflectivity = 0.45 + 0.2 * U(rng);
    const std::string name = id + "_" + std::to_string(parts);
    if (place(mesh, lying, touching, name, id, reflectivity) || place(mesh, false, false, name, id, reflectivity)) ++parts;
  }
  if (parts < options.min_parts)
    throw std::runtime_error("scene generator: only " + std::to_string(parts) + " parts fit into the workspace (seed " +
                             std::to_string(seed) + ", at least " + std::to_string(options.min_parts) + " asked)");
  const int distractors = static_cast<int>(U(rng) * (options.max_distractors + 1));
  for (int k = 0; k < distractors; ++k) {
    const std::string id = "distractor_" + std::to_string(seed) + "_" + std::to_string(k);
    const TriangleMesh mesh = U(rng) < 0.5 ? makeBox({0.02 + 0.03 * U(rng), 0.02 + 0.03 * U(rng), 0.015 + 0.03 * U(rng)})
                                           : makeCylinder(0.01 + 0.015 * U(rng), 0.015 + 0.035 * U(rng));
    const std::string dir = out_dir + "/models/" + id;
    makeDirs(dir);
    saveMeshPly(dir + "/mesh.ply", mesh);
    writeFileAtomic(dir + "/model.yaml", "# not in the part library: a distractor\nid: " + id + "\nmesh: mesh.ply\n");
    if (place(mesh, false, false, id, id, 0.5)) out.distractors.push_back(id);
  }
  objects << YAML::EndSeq;

  YAML::Node doc = loadYamlFile(base_scene_file);
  doc["name"] = "generated_" + std::to_string(seed);
  doc["objects"] = YAML::Load(objects.c_str());
  YAML::Emitter e;
  e << doc;
  out.yaml = std::string("# generated by cellsight's scene generator, seed ") + std::to_string(seed) + " (base: " +
             base_scene_file + ")\n" + e.c_str() + "\n";
  // <out_dir>/scenes/scene_<seed>.yaml finds its models in <out_dir>/models (the loader's default
  // ../models): the distractors written there, the library's models linked in
  makeDirs(out_dir + "/scenes");
  makeDirs(out_dir + "/models");
  for (const auto& id : ids) {
    const fs::path link = fs::path(out_dir) / "models" / id;
    std::error_code ec;
    if (!fs::exists(fs::symlink_status(link, ec))) fs::create_directory_symlink(fs::absolute(fs::path(models_dir) / id), link, ec);
    if (ec) throw std::runtime_error(link.string() + ": cannot link the model folder: " + ec.message());
  }
  out.file = out_dir + "/scenes/scene_" + std::to_string(seed) + ".yaml";
  writeFileAtomic(out.file, out.yaml);
  out.scene = loadScene(out.file);
  return out;
}

}  // namespace cellsight
