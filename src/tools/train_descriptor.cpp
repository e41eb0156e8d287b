// cellsight_train_descriptor: trains the learned per-point descriptor (PointNet++ on libtorch,
// CPU) on laser-line views of our parts and of generated meshes, and writes the model file the
// matcher loads (descriptor: learned in config/matching.yaml). Resumable (--resume), seeded,
// checkpoints written atomically. `make train` runs it with the settings of the shipped model.
#include <cstdio>
#include <iostream>

#include "cellsight/localization/descriptor_training.hpp"
#include "cli_args.hpp"

using namespace cellsight;

int main(int argc, char** argv) {
  CLI::App app("Trains the learned per-point descriptor that can replace FPFH (docs/learned_descriptors.md).",
               "cellsight_train_descriptor");
  DescriptorTrainingConfig c;
  c.model_meshes.clear();
  app.add_option("--output", c.output, "model file to write (the best validation figure so far)")->capture_default_str();
  app.add_option("--checkpoint", c.checkpoint, "resumable state (default: <output>.ckpt)");
  app.add_flag("--resume", c.resume, "continue from the checkpoint when there is one");
  app.add_option("--mesh", c.model_meshes, "a part's mesh to train on (repeat); the rest are generated");
  app.add_option("--generated", c.generated_meshes, "generated meshes (unions of boxes, cylinders, tubes)")
      ->check(cellsight_tools::nonNegativeInt())->capture_default_str();
  app.add_option("--freeform", c.freeform_meshes, "generated freeform meshes (smooth blobs, bent and joined)")
      ->check(cellsight_tools::nonNegativeInt())->capture_default_str();
  app.add_option("--noise-max", c.noise_max, "depth noise drawn per view from 30 um to this (m; 0: the laser scanner's)")
      ->check(cellsight_tools::nonNegative())->capture_default_str();
  app.add_option("--init", c.init_model, "start from this model file's weights (fine-tuning)")->check(CLI::ExistingFile);
  app.add_option("--steps", c.steps, "optimiser steps, one pair of views each")->check(cellsight_tools::positiveInt())
      ->capture_default_str();
  app.add_option("--time-limit", c.time_limit_s, "stop and save after this many seconds (0: none)")
      ->check(cellsight_tools::nonNegative())->capture_default_str();
  app.add_option("--dims", c.net.dims, "K, features per point")->check(CLI::IsMember({16, 32}))->capture_default_str();
  app.add_option("--rotation", c.net.rotation, "lrf (local reference frames) | augment (turned copies)")
      ->check(CLI::IsMember({"lrf", "augment"}))->capture_default_str();
  app.add_option("--width", c.net.width, "channels of the first layers")->check(cellsight_tools::positiveInt())
      ->capture_default_str();
  // a third level (32 centres, balls of 15 / 30 mm) can be added; the default is two
  c.net.centres.push_back(32);
  c.net.radius_small.push_back(1.5);
  c.net.radius_large.push_back(3.0);
  c.net.samples_small.push_back(16);
  c.net.samples_large.push_back(32);
  int levels = 2;
  app.add_option("--levels", levels, "set-abstraction levels (of 512, 128, 32 centres; more: a wider context)")
      ->check(CLI::Range(1, 3))->capture_default_str();
  app.add_option("--centre-spacing", c.net.centre_spacing,
                 "per level: sample centres until every point is this close to one (units; default: fixed counts)")
      ->delimiter(',');
  app.add_option("--fpfh-radius", c.net.fpfh_radius, "> 0: every point's FPFH over this radius (units) is an input too")
      ->check(cellsight_tools::nonNegative())->capture_default_str();
  app.add_option("--point-radius", c.net.point_radius, "neighbourhood of the per-point encoder (network units)")
      ->check(cellsight_tools::positive())->capture_default_str();
  app.add_option("--point-samples", c.net.point_samples, "neighbours of the per-point encoder")
      ->check(cellsight_tools::positiveInt())->capture_default_str();
  app.add_option("--negative-radius", c.negative_radius, "a negative lies farther than this from the positive (m)")
      ->check(cellsight_tools::positive())->capture_default_str();
  app.add_option("--negative-pool", c.negative_pool, "random points of each side the hardest negative is taken from")
      ->check(cellsight_tools::positiveInt())->capture_default_str();
  app.add_option("--loss", c.loss, "contrastive | triplet")->check(CLI::IsMember({"contrastive", "triplet"}))
      ->capture_default_str();
  app.add_option("--margin", c.margin, "hinge margin on descriptor distance")->check(cellsight_tools::positive())
      ->capture_default_str();
  app.add_option("--lr", c.learning_rate, "Adam learning rate")->check(cellsight_tools::positive())->capture_default_str();
  app.add_option("--anchors", c.anchors, "correspondences per pair in the loss")->check(cellsight_tools::positiveInt())
      ->capture_default_str();
  app.add_option("--model-pair-share", c.model_pair_share, "share of pairs that are (view, whole model)")
      ->check(cellsight_tools::fraction())->capture_default_str();
  app.add_option("--validate-every", c.validate_every, "steps between validations and checkpoints")
      ->check(cellsight_tools::positiveInt())->capture_default_str();
  app.add_option("--threads", c.threads, "libtorch threads")->check(cellsight_tools::positiveInt())->capture_default_str();
  app.add_option("--seed", c.seed, "seed of weights and data")->capture_default_str();
  std::string resample;
  app.add_option("--resample", resample,
                 "no training: write this model file's weights with --centre-spacing (or the fixed counts) to --output")
      ->check(CLI::ExistingFile);
  bool quiet = false;
  app.add_flag("--quiet", quiet, "no progress bar");
  if (auto code = cellsight_tools::parse(app, argc, argv)) return *code;
  c.progress = !quiet;
  c.net.centres.resize(levels);
  c.net.radius_small.resize(levels);
  c.net.radius_large.resize(levels);
  c.net.samples_small.resize(levels);
  c.net.samples_large.resize(levels);
  return cellsight_tools::runTool([&] {
    if (!resample.empty()) {
      const LearnedDescriptor in = LearnedDescriptor::load(resample);
      DescriptorNetConfig resampled = in.config();
      resampled.centre_spacing = c.net.centre_spacing;
      in.withConfig(resampled).save(c.output);
      std::printf("%s: centres %s; written to %s\n", resample.c_str(),
                  c.net.centre_spacing.empty() ? "fixed counts" : "sampled down to a spacing", c.output.c_str());
      return 0;
    }
    const auto r = trainDescriptor(c, [](const std::string& s) { std::cout << s << std::endl; });
    std::printf("trained %d steps in %.0f s; %zu parameters; best validation feature-match recall %.3f; model %s\n", r.steps,
                r.seconds, r.parameters, r.best_validation_recall, c.output.c_str());
    return 0;
  });
}
