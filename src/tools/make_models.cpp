// Generates the meshes of cellsight's own demo parts (config/models/<id>/mesh.ply) from
// primitives. The model.yaml metadata beside each mesh is written by hand.
// Usage: cellsight_make_models <config/models folder>   (--help for details)
// Bad or unknown options are reported by CLI11 (non-zero exit); failures print "error: ..." and exit 1.
#include <cmath>
#include <iostream>

#include "cellsight/common/file_io.hpp"
#include "cellsight/common/mesh.hpp"
#include "cli_args.hpp"

using cellsight::TriangleMesh;
using Eigen::Isometry3d;
using Eigen::Vector2d;
using Eigen::Vector3d;

namespace {
constexpr double mm = 1e-3;

Isometry3d at(double x, double y, double z) {
  return Isometry3d(Eigen::Translation3d(x * mm, y * mm, z * mm));
}

std::vector<Vector2d> polyMm(std::initializer_list<std::pair<double, double>> pts) {
  std::vector<Vector2d> out;
  for (const auto& p : pts) out.emplace_back(p.first * mm, p.second * mm);
  return out;
}

// Model frames: origin at the centre of the face the part rests on, z up.
TriangleMesh bracket() {
  // L-profile in the x-z plane, 40 mm wide along y, with a boss on the base plate.
  TriangleMesh profile = cellsight::makeExtrusion(
      polyMm({{-30, 0}, {30, 0}, {30, 5}, {-25, 5}, {-25, 40}, {-30, 40}}), 40 * mm);
  Isometry3d T = Isometry3d::Identity();
  T.translate(Vector3d(0, 20 * mm, 0));
  T.rotate(Eigen::AngleAxisd(M_PI / 2, Vector3d::UnitX()));
  TriangleMesh m;
  m.append(profile, T);
  m.append(cellsight::makeCylinder(7 * mm, 8 * mm), at(12, -8, 4.5));
  m.append(cellsight::makeBox(Vector3d(5, 10, 20) * mm), at(-22.5, 12, 15));  // gusset-like rib
  return m;
}

TriangleMesh housing() {
  TriangleMesh m = cellsight::makeBox(Vector3d(70, 50, 30) * mm);
  m.transform(at(0, 0, 15));
  m.append(cellsight::makeTube(12 * mm, 7 * mm, 12 * mm), at(15, 8, 29.5));
  m.append(cellsight::makeBox(Vector3d(14, 20, 8) * mm), at(-30, -10, 33.5));
  return m;
}

TriangleMesh flangedShaft() {
  TriangleMesh m = cellsight::makeCylinder(25 * mm, 8 * mm, 64);
  m.append(cellsight::makeCylinder(9 * mm, 55 * mm, 48), at(0, 0, 7.5));
  return m;
}

TriangleMesh blade() {
  // Tapered planform, 6 mm thick, with a root block.
  TriangleMesh m = cellsight::makeExtrusion(
      polyMm({{-10, -14}, {75, -6}, {82, 0}, {75, 5}, {-10, 14}}), 6 * mm);
  m.append(cellsight::makeBox(Vector3d(22, 32, 16) * mm), at(-18, 0, 7.5));
  return m;
}

TriangleMesh holder() {
  // U-profile opening upwards, 30 mm deep.
  TriangleMesh u = cellsight::makeExtrusion(
      polyMm({{-25, 0}, {25, 0}, {25, 32}, {16, 32}, {16, 9}, {-16, 9}, {-16, 32}, {-25, 32}}),
      30 * mm);
  Isometry3d T = Isometry3d::Identity();
  T.translate(Vector3d(0, 15 * mm, 0));
  T.rotate(Eigen::AngleAxisd(M_PI / 2, Vector3d::UnitX()));
  TriangleMesh m;
  m.append(u, T);
  return m;
}

TriangleMesh sphere25() {
  TriangleMesh m = cellsight::makeSphere(12.5 * mm, 5);
  m.transform(at(0, 0, 12.5));
  return m;
}
}  // namespace

int main(int argc, char** argv) {
  std::string root;
  CLI::App app("Generates the meshes of cellsight's demo parts (<folder>/<id>/mesh.ply) from primitives; the "
               "model.yaml beside each mesh is written by hand.",
               "cellsight_make_models");
  app.add_option("folder", root, "the models folder (config/models); created when missing")->required();
  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  return cellsight_tools::runTool([&] {
    const std::vector<std::pair<std::string, TriangleMesh>> parts = {
        {"bracket", bracket()},  {"housing", housing()}, {"flanged_shaft", flangedShaft()},
        {"blade", blade()},      {"holder", holder()},   {"sphere25", sphere25()}};
    for (const auto& p : parts) {
      const auto check = cellsight::checkMesh(p.second);
      if (!check.ok()) {
        std::cerr << p.first << ": generated mesh is invalid: " << check.describe() << "\n";
        return 1;
      }
      cellsight::makeDirs(root + "/" + p.first);
      cellsight::saveMeshPly(root + "/" + p.first + "/mesh.ply", p.second);
      const auto b = p.second.bounds();
      std::cout << p.first << ": " << p.second.vertices.size() << " vertices, "
                << p.second.faces.size() << " faces, size " << b.sizes().transpose() / mm
                << " mm\n";
    }
    return 0;
  });
}
