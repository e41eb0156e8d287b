// The `descriptors` verb of cellsight_evaluate_localization: FPFH against the learned descriptor
// (local reference frames; rotation augmentation alone and with multi-rotation) in the same
// correspondence search → RANSAC → ICP, on held-out laser views of our parts and on the real
// UWA / PCL scenes. docs/learned_descriptors.md.
#pragma once
#include <string>
#include <vector>

namespace cellsight_tools {

struct DescriptorEvalOptions {
  std::string root = ".";                ///< the package folder (config/)
  std::string data;                      ///< real data folder [default: <root>/../shared/data/pointclouds]
  std::vector<std::string> parts = {"housing", "flanged_shaft", "bracket", "blade", "holder"};
  std::vector<std::string> unseen = {"blade", "holder"};  ///< parts the shipped models never saw
  int views = 12;                        ///< held-out views per part
  uint64_t first_seed = 300000000;       ///< far from the trainer's seeds
  std::string learned = "config/descriptors/learned_k16.pt";          ///< lrf model (relative: to root)
  std::string augment = "config/descriptors/learned_k16_augment.pt";  ///< augmentation model
  int rotations = 8;                     ///< turns of the multi-rotation method
  int max_iterations = 20000;            ///< RANSAC hypotheses, the same for every method
  std::string sampling = "guided";       ///< RANSAC sampling (MatchingConfig::ransac_sampling), every method and case
  bool real = true;                      ///< the real scenes too (skipped when the data is absent)
  std::string json, png;
  double limit_recall_margin = -1;       ///< exit 4 unless learned recall ≥ FPFH's + this (< 0: no check)
};

int runDescriptorEvaluation(const DescriptorEvalOptions& o);

}  // namespace cellsight_tools
