// Private to the libtorch translation units (learned_descriptor.cpp,
// learned_descriptor_structure.cpp, descriptor_training.cpp): the network module and the
// per-cloud structure (sampling, groups, reference frames) it runs on.
#pragma once
#include <torch/torch.h>

#include <Eigen/Core>
#include <vector>

#include "cellsight/localization/learned_descriptor.hpp"

namespace cellsight {
namespace descriptor_detail {

/// Inputs per group member: the offset in the centre's frame (3), its length, along the centre's
/// normal, the normals' agreement, the member's normal along the offset (4, rotation-invariant);
/// the per-point encoder adds the member's normal in the frame (3).
constexpr int64_t kGroupInputs = 7;
constexpr int64_t kPointInputs = 10;

/// The geometry of one cloud for the network, built without autograd: which points each layer
/// samples and groups, and the groups' coordinates in their centre's frame (units).
struct Structure {
  int64_t n = 0;          ///< input points
  torch::Tensor fpfh;     ///< [n, 33] FPFH / 100 (DescriptorNetConfig::fpfh_radius > 0)
  torch::Tensor x0;       ///< [n, k0, kPointInputs] per-point encoder input
  struct Level {
    int64_t m = 0;
    torch::Tensor idx_small, rel_small;  ///< [m*ks] into the previous level, [m, ks, kGroupInputs]
    torch::Tensor idx_large, rel_large;  ///< [m*kl], [m, kl, kGroupInputs]
    torch::Tensor up_idx, up_w;          ///< previous level's 3 nearest centres of this one: [p*3], [p, 3, 1]
  };
  std::vector<Level> levels;
};

/// Builds the structure of a cloud already in network units (finite points only). `rotate`:
/// the hinted frame per group (true: "lrf"), else the cloud's axes.
Structure buildStructure(const std::vector<Eigen::Vector3f>& p, const std::vector<Eigen::Vector3f>& n,
                         const DescriptorNetConfig& c);

struct MlpImpl : torch::nn::Module {
  MlpImpl(int64_t in, const std::vector<int64_t>& out);
  torch::Tensor forward(torch::Tensor x);  ///< ReLU after every layer
  std::vector<torch::nn::Linear> layers;
};
TORCH_MODULE(Mlp);

struct NetImpl : torch::nn::Module {
  explicit NetImpl(const DescriptorNetConfig& c);
  /// [n, K] unit rows
  torch::Tensor forward(const Structure& s);
  DescriptorNetConfig config;
  Mlp point{nullptr};
  std::vector<Mlp> small, large, up;
  torch::nn::Linear head{nullptr};
  Mlp fpfh{nullptr};                    ///< fpfh_radius > 0
  torch::nn::Linear fpfh_head{nullptr};
};
TORCH_MODULE(Net);

}  // namespace descriptor_detail

struct LearnedDescriptor::Impl {
  explicit Impl(const DescriptorNetConfig& c) : net(c) {}
  descriptor_detail::Net net;
};

}  // namespace cellsight
