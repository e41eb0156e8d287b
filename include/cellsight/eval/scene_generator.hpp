// Random cells for evaluation (scenes the parameters were not chosen on): parts of the model
// library at random positions and yaws on the table, some lying on another stable face, some
// touching a neighbour, and a few distractors (simple shapes that are not in the library), all
// inside the scanner's workspace and not interpenetrating. Seeded: one seed, one scene.
#pragma once
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "cellsight/common/mesh.hpp"
#include "cellsight/sim/scene.hpp"

namespace cellsight {

struct SceneGeneratorOptions {
  std::vector<std::string> models;  ///< ids to draw from (empty: every model of the library folder)
  int min_parts = 4, max_parts = 6;
  double lying_share = 0.3;     ///< parts resting on a stable face other than their base
  double touching_share = 0.3;  ///< parts placed against a neighbour (footprints touching)
  int max_distractors = 2;      ///< boxes / cylinders not in the library
  double margin = 0.004;        ///< m between footprints (and to the workspace's edge)
};

/// The resting orientations of a mesh on a plane: first the mesh as modelled (standing on its
/// z-min, the scenes' convention), then, for each flat side (area >= 3 % of the surface) whose
/// support polygon holds the centroid's projection, the rotation that puts that side face down.
std::vector<Eigen::Matrix3d> stableRestRotations(const TriangleMesh& mesh);

struct GeneratedScene {
  Scene scene;
  std::string file;  ///< <out_dir>/scenes/scene_<seed>.yaml (loads with loadScene's default model path)
  std::string yaml;  ///< its text
  std::vector<std::string> distractors;  ///< object names that are not library models
};

/// Generates the scene from `base_scene_file` (cameras, laser, table, workspace, noise kept;
/// objects replaced) and writes it to <out_dir>/scenes/scene_<seed>.yaml. Library models come from
/// `models_dir` (linked into <out_dir>/models); distractor meshes and their model.yaml are written
/// there too. Throws when fewer than min_parts parts fit.
GeneratedScene generateScene(const std::string& base_scene_file, const std::string& models_dir, uint64_t seed,
                             const SceneGeneratorOptions& options, const std::string& out_dir);

}  // namespace cellsight
