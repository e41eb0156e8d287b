// cellsight_make_scene: random cells for evaluation (eval/scene_generator): for each seed,
// <out>/scenes/scene_<seed>.yaml with its models in <out>/models (distractors written, library
// models linked), loadable by cell_sim (demo.launch scene:=...) and the evaluation tools.
// config/heldout_seeds.yaml lists the seeds no setting was chosen on.
#include <cstdio>
#include <iostream>

#include "cellsight/eval/scene_generator.hpp"
#include "cli_args.hpp"

using namespace cellsight;

int main(int argc, char** argv) {
  std::string base = "config/scenes/demo.yaml", models = "config/models", out;
  std::vector<uint64_t> seeds;
  SceneGeneratorOptions o;
  CLI::App app("Generates random cells (parts of the library at random places, lying and touching; distractors) "
               "from a base scene, one per seed.",
               "cellsight_make_scene");
  app.add_option("--seeds", seeds, "one scene per seed")->required();
  app.add_option("--out", out, "output folder (scenes/, models/)")->required();
  app.add_option("--base", base, "scene whose cameras, laser, table and workspace are kept")
      ->check(CLI::ExistingFile)
      ->capture_default_str();
  app.add_option("--models", models, "part library")->check(CLI::ExistingDirectory)->capture_default_str();
  app.add_option("--min-parts", o.min_parts, "parts per scene, at least")->check(cellsight_tools::positiveInt())->capture_default_str();
  app.add_option("--max-parts", o.max_parts, "parts per scene, at most")->check(cellsight_tools::positiveInt())->capture_default_str();
  app.add_option("--lying", o.lying_share, "share of parts lying on another stable side")
      ->check(cellsight_tools::fraction())
      ->capture_default_str();
  app.add_option("--touching", o.touching_share, "share of parts placed against a neighbour")
      ->check(cellsight_tools::fraction())
      ->capture_default_str();
  app.add_option("--distractors", o.max_distractors, "distractors per scene, at most")
      ->check(cellsight_tools::nonNegativeInt())
      ->capture_default_str();
  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  return cellsight_tools::runTool([&] {
    for (const uint64_t seed : seeds) {
      const GeneratedScene g = generateScene(base, models, seed, o, out);
      std::printf("%s: %zu objects (%zu distractors)\n", g.file.c_str(), g.scene.objects.size(), g.distractors.size());
    }
    return 0;
  });
}
