// The learned descriptor's network (PointNet++ segmentation variant, multi-scale grouping) and
// its inference, load and save; the network's input geometry is built in
// learned_descriptor_structure.cpp. One of the translation units that include libtorch.
#include <dlfcn.h>
#include <malloc.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <memory>
#include <random>

#include <Eigen/Geometry>
#include <sstream>

#include "cellsight/common/file_io.hpp"
#include "learned_descriptor_impl.hpp"

namespace cellsight {
namespace descriptor_detail {

MlpImpl::MlpImpl(int64_t in, const std::vector<int64_t>& out) {
  for (size_t i = 0; i < out.size(); ++i) {
    layers.push_back(register_module("fc" + std::to_string(i), torch::nn::Linear(in, out[i])));
    in = out[i];
  }
}

torch::Tensor MlpImpl::forward(torch::Tensor x) {
  for (auto& l : layers) x = torch::relu(l->forward(x));
  return x;
}

NetImpl::NetImpl(const DescriptorNetConfig& c) : config(c) {
  const int64_t w = c.width;
  point = register_module("point", Mlp(kPointInputs, std::vector<int64_t>{w, w}));
  // channels per level of each scale: w, 2w, 4w, 4w (concatenated: twice that)
  std::vector<int64_t> ch{w};  // level 0: the per-point encoder
  for (size_t l = 0; l < c.centres.size(); ++l) {
    const int64_t o = w << std::min<size_t>(l, 2);
    small.push_back(register_module("sa" + std::to_string(l + 1) + "_small", Mlp(kGroupInputs + ch.back(), std::vector<int64_t>{o, o})));
    large.push_back(register_module("sa" + std::to_string(l + 1) + "_large", Mlp(kGroupInputs + ch.back(), std::vector<int64_t>{o, o})));
    ch.push_back(2 * o);
  }
  // propagation from the top: level l+1's (propagated) features onto level l, with its own
  int64_t carried = ch.back();
  up.assign(c.centres.size(), Mlp(nullptr));
  for (int l = static_cast<int>(c.centres.size()) - 1; l >= 0; --l) {
    const int64_t o = l == 0 ? 2 * w : std::min<int64_t>(ch[l], 4 * w);
    up[l] = register_module("fp" + std::to_string(l), Mlp(carried + ch[l], std::vector<int64_t>{o, o}));
    carried = o;
  }
  head = register_module("head", torch::nn::Linear(carried, c.dims));
  if (c.fpfh_radius > 0) {
    fpfh = register_module("fpfh", Mlp(33, std::vector<int64_t>{2 * w, 2 * w}));
    fpfh_head = register_module("fpfh_head", torch::nn::Linear(torch::nn::LinearOptions(2 * w, c.dims).bias(false)));
    torch::NoGradGuard ng;
    fpfh_head->weight.zero_();
  }
}

torch::Tensor NetImpl::forward(const Structure& s) {
  std::vector<torch::Tensor> f;
  f.push_back(std::get<0>(point->forward(s.x0).max(1)));  // [n, w]
  for (size_t l = 0; l < s.levels.size(); ++l) {
    const auto& L = s.levels[l];
    auto group = [&](const torch::Tensor& idx, const torch::Tensor& rel, Mlp& mlp) {
      const auto g = f.back().index_select(0, idx).view({L.m, rel.size(1), -1});
      return std::get<0>(mlp->forward(torch::cat({rel, g}, 2)).max(1));
    };
    f.push_back(torch::cat({group(L.idx_small, L.rel_small, small[l]), group(L.idx_large, L.rel_large, large[l])}, 1));
  }
  torch::Tensor g = f.back();
  for (int l = static_cast<int>(s.levels.size()) - 1; l >= 0; --l) {
    const auto& L = s.levels[l];
    const int64_t p = f[l].size(0);
    const auto interp = (g.index_select(0, L.up_idx).view({p, 3, -1}) * L.up_w).sum(1);
    g = up[l]->forward(torch::cat({interp, f[l]}, 1));
  }
  torch::Tensor out = head->forward(g);
  if (fpfh) out = out + fpfh_head->forward(fpfh->forward(s.fpfh));
  return torch::nn::functional::normalize(out, torch::nn::functional::NormalizeFuncOptions().dim(1));
}

}  // namespace descriptor_detail

void checkDescriptorNetConfig(const DescriptorNetConfig& c) {
  auto bad = [](const std::string& what) { throw DescriptorModelError("learned descriptor: " + what); };
  if (c.dims < 1 || c.dims > 1024) bad("dims must be in [1, 1024], got " + std::to_string(c.dims));
  if (c.rotation != "lrf" && c.rotation != "augment") bad("rotation must be lrf or augment, got '" + c.rotation + "'");
  if (!(c.unit > 0) || !std::isfinite(c.unit)) bad("unit must be a positive length in metres");
  if (c.width < 1 || c.width > 1024) bad("width must be in [1, 1024]");
  const size_t L = c.centres.size();
  if (L == 0 || c.radius_small.size() != L || c.radius_large.size() != L || c.samples_small.size() != L ||
      c.samples_large.size() != L)
    bad("centres, radius_small, radius_large, samples_small and samples_large need one entry per level");
  for (size_t l = 0; l < L; ++l) {
    if (c.centres[l] < 1 || c.samples_small[l] < 1 || c.samples_large[l] < 1) bad("centre and sample counts must be ≥ 1");
    if (!(c.radius_small[l] > 0) || !(c.radius_large[l] >= c.radius_small[l])) bad("radii must be > 0, large ≥ small");
  }
  if (!c.centre_spacing.empty() && c.centre_spacing.size() != L) bad("centre_spacing needs one entry per level, or none");
  for (double d : c.centre_spacing)
    if (!(d > 0) || !std::isfinite(d)) bad("centre_spacing must be > 0");
  if (!(c.fpfh_radius >= 0) || !std::isfinite(c.fpfh_radius)) bad("fpfh_radius must be ≥ 0");
  if (!(c.point_radius > 0) || c.point_samples < 1) bad("point_radius must be > 0 and point_samples ≥ 1");
}

LearnedDescriptor::LearnedDescriptor(const DescriptorNetConfig& config, uint64_t seed) {
  checkDescriptorNetConfig(config);
  static const bool blas_single = [] {
    using SetThreads = void (*)(int);
    if (auto f = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"))) f(1);
    // libtorch allocates fresh buffers of a few MB in every forward pass; glibc maps blocks above
    // its mmap threshold afresh and returns freed ones to the system, so every pass page-faults
    // them in again (on the project's virtual machine about half of a 4 096-point pass). Freed
    // blocks up to 256 MB are kept for reuse instead, and the heap grows 64 MB at a time: the
    // same peak memory, 72 -> 34 ms for that pass (bench_descriptor, ab3a9c4).
    mallopt(M_MMAP_THRESHOLD, 256 << 20);
    mallopt(M_TRIM_THRESHOLD, 512 << 20);
    mallopt(M_TOP_PAD, 64 << 20);
    return true;
  }();
  (void)blas_single;
  torch::manual_seed(seed);
  impl_ = std::make_unique<Impl>(config);
}

LearnedDescriptor LearnedDescriptor::withConfig(const DescriptorNetConfig& c) const {
  const DescriptorNetConfig& o = config();
  if (c.dims != o.dims || c.rotation != o.rotation || c.unit != o.unit || c.width != o.width ||
      c.centres.size() != o.centres.size() || c.radius_small != o.radius_small || c.radius_large != o.radius_large ||
      c.samples_small != o.samples_small || c.samples_large != o.samples_large || c.point_radius != o.point_radius ||
      c.point_samples != o.point_samples)
    throw DescriptorModelError("learned descriptor: only the centres' sampling and the FPFH input may change; the "
                               "network (K, rotation, unit, width, levels, radii, group sizes) must stay the same");
  LearnedDescriptor out(c);
  torch::NoGradGuard no_grad;
  const auto src = impl_->net->named_parameters();
  auto dst = out.impl_->net->named_parameters();
  for (const auto& p : src)
    if (!dst.contains(p.key())) throw DescriptorModelError("learned descriptor: the new settings drop tensor " + p.key());
  for (auto& p : dst) {
    const torch::Tensor* t = src.find(p.key());
    if (!t && p.key().rfind("fpfh", 0) == 0) continue;  // an FPFH input added: its branch starts at zero
    p.value().copy_(*t);  // every other tensor has the same name and shape in the same network
  }
  return out;
}

LearnedDescriptor::~LearnedDescriptor() = default;
LearnedDescriptor::LearnedDescriptor(LearnedDescriptor&&) noexcept = default;
LearnedDescriptor& LearnedDescriptor::operator=(LearnedDescriptor&&) noexcept = default;

const DescriptorNetConfig& LearnedDescriptor::config() const { return impl_->net->config; }

size_t LearnedDescriptor::parameterCount() const {
  size_t n = 0;
  for (const auto& p : impl_->net->parameters()) n += static_cast<size_t>(p.numel());
  return n;
}

void LearnedDescriptor::setThreads(int threads) {
  torch::set_num_threads(std::max(1, threads));
  // OpenBLAS (Debian's libblas.so.3 alternative) runs a thread pool of its own under libtorch's
  // matrix products; on these small products it only spins (training took 2x the time). One
  // thread; looked up at run time so that any BLAS works.
  using SetThreads = void (*)(int);
  if (auto f = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"))) f(1);
}

namespace {
std::vector<int64_t> toInt64(const std::vector<int>& v) { return {v.begin(), v.end()}; }
std::vector<int> toInt(const std::vector<int64_t>& v) { return {v.begin(), v.end()}; }
}  // namespace

void LearnedDescriptor::save(const std::string& path) const {
  const auto& c = config();
  torch::serialize::OutputArchive a;
  a.write("meta.format", c10::IValue(std::string("cellsight-learned-descriptor-1")));
  a.write("meta.dims", c10::IValue(static_cast<int64_t>(c.dims)));
  a.write("meta.rotation", c10::IValue(c.rotation));
  a.write("meta.unit", c10::IValue(c.unit));
  a.write("meta.width", c10::IValue(static_cast<int64_t>(c.width)));
  a.write("meta.centres", c10::IValue(toInt64(c.centres)));
  if (!c.centre_spacing.empty()) a.write("meta.centre_spacing", c10::IValue(c.centre_spacing));
  a.write("meta.radius_small", c10::IValue(c.radius_small));
  a.write("meta.radius_large", c10::IValue(c.radius_large));
  a.write("meta.samples_small", c10::IValue(toInt64(c.samples_small)));
  a.write("meta.samples_large", c10::IValue(toInt64(c.samples_large)));
  if (c.fpfh_radius > 0) a.write("meta.fpfh_radius", c10::IValue(c.fpfh_radius));
  a.write("meta.point_radius", c10::IValue(c.point_radius));
  a.write("meta.point_samples", c10::IValue(static_cast<int64_t>(c.point_samples)));
  for (const auto& p : impl_->net->named_parameters()) a.write(p.key(), p.value().detach(), /*is_buffer=*/false);
  const std::string tmp = path + ".tmp";
  a.save_to(tmp);
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw std::runtime_error("learned descriptor: cannot write " + path);
  }
}

LearnedDescriptor LearnedDescriptor::load(const std::string& path, int expected_dims) {
  const std::string who = "learned descriptor model " + path + ": ";
  {
    std::ifstream f(path, std::ios::binary);
    if (!f) throw DescriptorModelError(who + "cannot be opened (missing? make train writes it)");
  }
  torch::serialize::InputArchive a;
  try {
    a.load_from(path);
  } catch (const std::exception& e) {
    std::string what = e.what();
    what = what.substr(0, what.find('\n'));
    throw DescriptorModelError(who + "not a readable model file (truncated or not written by save()): " + what);
  }
  DescriptorNetConfig c;
  try {
    c10::IValue v;
    a.read("meta.format", v);
    if (!v.isString() || v.toStringRef() != "cellsight-learned-descriptor-1")
      throw DescriptorModelError(who + "unknown format");
    a.read("meta.dims", v);
    c.dims = static_cast<int>(v.toInt());
    a.read("meta.rotation", v);
    c.rotation = v.toStringRef();
    a.read("meta.unit", v);
    c.unit = v.toDouble();
    a.read("meta.width", v);
    c.width = static_cast<int>(v.toInt());
    a.read("meta.centres", v);
    c.centres = toInt(v.toIntVector());
    if (a.try_read("meta.centre_spacing", v)) c.centre_spacing = v.toDoubleVector();  // absent: fixed counts
    a.read("meta.radius_small", v);
    c.radius_small = v.toDoubleVector();
    a.read("meta.radius_large", v);
    c.radius_large = v.toDoubleVector();
    a.read("meta.samples_small", v);
    c.samples_small = toInt(v.toIntVector());
    a.read("meta.samples_large", v);
    c.samples_large = toInt(v.toIntVector());
    if (a.try_read("meta.fpfh_radius", v)) c.fpfh_radius = v.toDouble();  // absent: no FPFH input
    a.read("meta.point_radius", v);
    c.point_radius = v.toDouble();
    a.read("meta.point_samples", v);
    c.point_samples = static_cast<int>(v.toInt());
  } catch (const DescriptorModelError&) {
    throw;
  } catch (const std::exception& e) {
    std::string what = e.what();
    throw DescriptorModelError(who + "architecture record missing or malformed: " + what.substr(0, what.find('\n')));
  }
  checkDescriptorNetConfig(c);
  if (expected_dims > 0 && c.dims != expected_dims)
    throw DescriptorModelError(who + "has K = " + std::to_string(c.dims) + " features per point, the configuration asks for " +
                               std::to_string(expected_dims));
  LearnedDescriptor d(c);
  torch::NoGradGuard no_grad;
  for (auto& p : d.impl_->net->named_parameters()) {
    torch::Tensor t;
    try {
      a.read(p.key(), t);
    } catch (const std::exception&) {
      throw DescriptorModelError(who + "tensor '" + p.key() + "' missing");
    }
    if (t.sizes() != p.value().sizes()) {
      std::ostringstream os;
      os << who << "tensor '" << p.key() << "' has shape " << t.sizes() << ", the network needs " << p.value().sizes();
      throw DescriptorModelError(os.str());
    }
    if (!torch::isfinite(t).all().item<bool>()) throw DescriptorModelError(who + "tensor '" + p.key() + "' holds NaN or Inf");
    p.value().copy_(t);
  }
  d.impl_->net->eval();
  return d;
}

Eigen::MatrixXf LearnedDescriptor::compute(const std::vector<Eigen::Vector3f>& points,
                                           const std::vector<Eigen::Vector3f>& normals, double scale,
                                           DescriptorTiming* timing) const {
  if (points.size() != normals.size())
    throw std::invalid_argument("learned descriptor: " + std::to_string(points.size()) + " points but " +
                                std::to_string(normals.size()) + " normals");
  if (points.size() > max_points)
    throw std::invalid_argument("learned descriptor: " + std::to_string(points.size()) + " points, at most " +
                                std::to_string(max_points) + " (thin the cloud to the matching voxel first)");
  if (!(scale > 0) || !std::isfinite(scale)) throw std::invalid_argument("learned descriptor: scale must be > 0");
  const auto& c = config();
  const float k = static_cast<float>(scale / c.unit);
  std::vector<Eigen::Vector3f> p, n;
  std::vector<int> row;
  for (size_t i = 0; i < points.size(); ++i) {
    if (!points[i].allFinite()) continue;
    p.push_back(points[i] * k);
    const bool ok = normals[i].allFinite() && normals[i].norm() > 0.5f;
    n.push_back(ok ? Eigen::Vector3f(normals[i].normalized()) : Eigen::Vector3f::Zero());
    row.push_back(static_cast<int>(i));
  }
  if (p.size() < 2) throw std::invalid_argument("learned descriptor: fewer than 2 finite points");
  const auto t0 = std::chrono::steady_clock::now();
  const descriptor_detail::Structure s = descriptor_detail::buildStructure(p, n, c);
  const auto t1 = std::chrono::steady_clock::now();
  torch::InferenceMode guard;
  const torch::Tensor out = impl_->net->forward(s).contiguous();
  const auto t2 = std::chrono::steady_clock::now();
  if (timing) {
    timing->structure_seconds = std::chrono::duration<double>(t1 - t0).count();
    timing->network_seconds = std::chrono::duration<double>(t2 - t1).count();
  }
  Eigen::MatrixXf d = Eigen::MatrixXf::Zero(static_cast<Eigen::Index>(points.size()), c.dims);
  const float* o = out.data_ptr<float>();
  for (size_t i = 0; i < row.size(); ++i)
    for (int j = 0; j < c.dims; ++j) d(row[i], j) = o[i * c.dims + j];
  return d;
}

std::vector<Eigen::Matrix3f> descriptorTurns(int n) {
  std::mt19937_64 rng(12345);
  std::normal_distribution<double> N(0, 1);
  std::vector<Eigen::Matrix3f> out;
  for (int turn = 0; turn < n; ++turn) {
    Eigen::Matrix3f R = Eigen::Matrix3f::Identity();
    if (turn > 0) R = Eigen::Quaterniond(N(rng), N(rng), N(rng), N(rng)).normalized().toRotationMatrix().cast<float>();
    out.push_back(R);
  }
  return out;
}

std::vector<std::pair<int, int>> matchDescriptors(const Eigen::MatrixXf& a, const Eigen::MatrixXf& b, bool mutual,
                                                  int min_mutual) {
  std::vector<std::pair<int, int>> one_way, both;
  if (a.rows() == 0 || b.rows() == 0 || a.cols() != b.cols()) return one_way;
  // squared distances from one matrix product: |a|² + |b|² − 2 a·b
  const Eigen::MatrixXf dot = a * b.transpose();
  const Eigen::VectorXf na = a.rowwise().squaredNorm(), nb = b.rowwise().squaredNorm();
  std::vector<int> best_a(a.rows(), -1), best_b(b.rows(), -1);
  std::vector<float> sa(a.rows(), std::numeric_limits<float>::max()), sb(b.rows(), std::numeric_limits<float>::max());
  for (Eigen::Index j = 0; j < b.rows(); ++j) {
    if (nb(j) <= 0) continue;
    for (Eigen::Index i = 0; i < a.rows(); ++i) {
      if (na(i) <= 0) continue;
      const float d = na(i) + nb(j) - 2 * dot(i, j);
      if (d < sa[i]) sa[i] = d, best_a[i] = static_cast<int>(j);
      if (d < sb[j]) sb[j] = d, best_b[j] = static_cast<int>(i);
    }
  }
  for (Eigen::Index i = 0; i < a.rows(); ++i) {
    if (best_a[i] < 0) continue;
    one_way.emplace_back(static_cast<int>(i), best_a[i]);
    if (best_b[best_a[i]] == i) both.emplace_back(static_cast<int>(i), best_a[i]);
  }
  if (mutual && static_cast<int>(both.size()) >= min_mutual) return both;
  return one_way;
}

std::vector<std::pair<int, int>> nearestDescriptors(const Eigen::MatrixXf& a, const Eigen::MatrixXf& b, int k) {
  std::vector<std::pair<int, int>> out;
  if (a.rows() == 0 || b.rows() == 0 || a.cols() != b.cols() || k < 1) return out;
  const Eigen::VectorXf na = a.rowwise().squaredNorm(), nb = b.rowwise().squaredNorm();
  std::vector<int> usable;  // rows with a descriptor (NaN ones have none: they would break the sort)
  for (Eigen::Index j = 0; j < b.rows(); ++j)
    if (nb(j) > 0 && std::isfinite(nb(j))) usable.push_back(static_cast<int>(j));
  const size_t kk = std::min<size_t>(static_cast<size_t>(k), usable.size());
  if (kk == 0) return out;
  out.reserve(a.rows() * kk);
  // a block of rows of a at a time: one matrix product each, the memory bounded
  constexpr Eigen::Index kBlock = 1024;
  std::vector<std::pair<float, int>> d(usable.size());
  for (Eigen::Index i0 = 0; i0 < a.rows(); i0 += kBlock) {
    const Eigen::Index n = std::min(kBlock, a.rows() - i0);
    const Eigen::MatrixXf dot = a.middleRows(i0, n) * b.transpose();
    for (Eigen::Index i = 0; i < n; ++i) {
      if (!(na(i0 + i) > 0) || !std::isfinite(na(i0 + i))) continue;
      for (size_t u = 0; u < usable.size(); ++u) d[u] = {na(i0 + i) + nb(usable[u]) - 2 * dot(i, usable[u]), usable[u]};
      std::partial_sort(d.begin(), d.begin() + kk, d.end());
      for (size_t u = 0; u < kk; ++u) out.emplace_back(static_cast<int>(i0 + i), d[u].second);
    }
  }
  return out;
}

}  // namespace cellsight
