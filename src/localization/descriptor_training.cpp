// Training of the learned descriptor: siamese pairs (two views of a part, or a view and the
// whole model as the matcher holds it) with known correspondences, contrastive loss with the
// hardest negative in the batch, Adam, resumable checkpoints written atomically. The second
// translation unit that includes libtorch.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <numeric>
#include <random>

#include "cellsight/localization/descriptor_training.hpp"
#include "cellsight/localization/model_library.hpp"
#include "learned_descriptor_impl.hpp"

namespace cellsight {
namespace {

using Clock = std::chrono::steady_clock;

struct Sample {
  LaserView view;
  descriptor_detail::Structure structure;
};

Sample prepare(LaserView v, const DescriptorNetConfig& c) {
  Sample s;
  std::vector<Eigen::Vector3f> p, n;
  const float k = static_cast<float>(1.0 / c.unit);
  for (size_t i = 0; i < v.cloud.size(); ++i) {
    p.push_back(v.cloud.points[i] * k);
    n.push_back(v.cloud.normals[i]);
  }
  s.structure = descriptor_detail::buildStructure(p, n, c);
  s.view = std::move(v);
  return s;
}

Eigen::Isometry3d randomPose(std::mt19937_64& rng) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  std::normal_distribution<double> N(0, 1);
  Eigen::Quaterniond q(N(rng), N(rng), N(rng), N(rng));
  T.linear() = q.normalized().toRotationMatrix();
  return T;
}

void atomicSave(torch::serialize::OutputArchive& a, const std::string& path) {
  const std::string tmp = path + ".tmp";
  a.save_to(tmp);
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw std::runtime_error("train descriptor: cannot write " + path);
  }
}

bool fileExists(const std::string& p) { return static_cast<bool>(std::ifstream(p)); }

}  // namespace

DescriptorTrainingReport trainDescriptor(const DescriptorTrainingConfig& cfg,
                                         const std::function<void(const std::string&)>& log) {
  checkDescriptorNetConfig(cfg.net);
  if (cfg.loss != "contrastive" && cfg.loss != "triplet")
    throw std::invalid_argument("train descriptor: loss must be contrastive or triplet, got '" + cfg.loss + "'");
  if (cfg.model_meshes.empty() && cfg.generated_meshes <= 0)
    throw std::invalid_argument("train descriptor: no meshes (model_meshes empty and generated_meshes 0)");
  LearnedDescriptor::setThreads(cfg.threads);
  const auto t_start = Clock::now();
  auto say = [&](const std::string& s) {
    if (log) log(s);
  };
  std::vector<TriangleMesh> meshes;
  for (const auto& path : cfg.model_meshes) meshes.push_back(loadValidMesh(path));
  for (int i = 0; i < cfg.generated_meshes; ++i) meshes.push_back(randomPartMesh(cfg.seed * 1000 + static_cast<uint64_t>(i)));
  for (int i = 0; i < cfg.freeform_meshes; ++i)
    meshes.push_back(randomFreeformMesh(cfg.seed * 1000 + static_cast<uint64_t>(i)));
  std::map<size_t, LaserView> model_clouds;
  std::map<size_t, ScanCloud> dense;  // each mesh's surface samples, shared by its views
  auto view = [&](size_t m, const Eigen::Isometry3d& pose, uint64_t vseed) {
    auto it = dense.find(m);
    if (it == dense.end()) it = dense.emplace(m, sampleMesh(meshes[m], LaserViewSetup().sample_spacing, m + 1)).first;
    LaserViewSetup setup = randomLaserSetup(vseed);
    if (cfg.noise_max > 0) {
      std::mt19937_64 nrng(vseed ^ 0x5eedull);
      const double lo = std::log(3e-5), hi = std::log(std::max(3e-5, cfg.noise_max));
      setup.noise = std::exp(lo + (hi - lo) * std::uniform_real_distribution<double>(0, 1)(nrng));
    }
    return laserView(meshes[m], pose, setup, vseed, &it->second);
  };
  auto wholeModel = [&](size_t m) -> const LaserView& {
    auto it = model_clouds.find(m);
    if (it == model_clouds.end()) it = model_clouds.emplace(m, modelCloud(meshes[m], 0.002, 0.005, 1)).first;
    return it->second;
  };

  const std::string ckpt = cfg.checkpoint.empty() ? cfg.output + ".ckpt" : cfg.checkpoint;
  LearnedDescriptor net(cfg.net, cfg.seed);
  if (!cfg.init_model.empty() && !(cfg.resume && fileExists(ckpt))) {
    net = LearnedDescriptor::load(cfg.init_model, cfg.net.dims).withConfig(cfg.net);
    say("weights from " + cfg.init_model);
  }
  auto& module = net.impl().net;
  torch::optim::Adam adam(module->parameters(), torch::optim::AdamOptions(cfg.learning_rate));
  DescriptorTrainingReport rep;
  rep.parameters = net.parameterCount();
  int start = 0;
  if (cfg.resume && fileExists(ckpt)) {
    torch::serialize::InputArchive a;
    a.load_from(ckpt);
    torch::NoGradGuard ng;
    for (auto& p : module->named_parameters()) {
      torch::Tensor t;
      a.read("net." + p.key(), t);
      if (t.sizes() != p.value().sizes())
        throw DescriptorModelError("checkpoint " + ckpt + ": tensor " + p.key() + " does not fit this network");
      p.value().copy_(t);
    }
    torch::serialize::InputArchive oa;
    a.read("optimizer", oa);
    adam.load(oa);
    c10::IValue v;
    a.read("step", v);
    start = static_cast<int>(v.toInt());
    a.read("best", v);
    rep.best_validation_recall = v.toDouble();
    say("resumed at step " + std::to_string(start) + " from " + ckpt);
  }

  // validation: fixed pairs (a view and the whole model) from viewpoints training never draws
  std::vector<std::pair<Sample, const LaserView*>> validation;
  for (int v = 0; v < cfg.validation_pairs; ++v) {
    const size_t m = static_cast<size_t>(v) * meshes.size() / std::max(1, cfg.validation_pairs);
    std::mt19937_64 rng(900000000ull + static_cast<uint64_t>(v));
    LaserView view = laserView(meshes[m], randomPose(rng), randomLaserSetup(900000000ull + v), 900000000ull + v);
    if (view.cloud.size() < 30) continue;
    validation.emplace_back(prepare(std::move(view), cfg.net), &wholeModel(m));
  }
  {
    // the reference: FPFH (10 mm support, as the matcher's ransac / fgr paths) on the same pairs
    int hit = 0;
    double ratio = 0;
    for (const auto& [s, model] : validation) {
      const PairMatchFigures f =
          pairMatchFigures(s.view, fpfhRows(s.view.cloud, 0.010), *model, fpfhRows(model->cloud, 0.010), 0.004);
      hit += f.matched();
      ratio += f.inlier_ratio;
    }
    const double n = std::max<size_t>(1, validation.size());
    char line[160];
    std::snprintf(line, sizeof line, "validation pairs: %zu; FPFH on them: feature-match recall %.3f, inlier ratio %.3f",
                  validation.size(), hit / n, ratio / n);
    say(line);
  }
  std::map<const LaserView*, Sample> prepared_models;
  auto validate = [&]() {
    torch::NoGradGuard ng;
    module->eval();
    int hit = 0;
    double ratio = 0;
    for (auto& [s, model] : validation) {
      auto it = prepared_models.find(model);
      if (it == prepared_models.end()) it = prepared_models.emplace(model, prepare(*model, cfg.net)).first;
      auto toEigen = [&](const torch::Tensor& t) {
        const auto c = t.contiguous();
        return Eigen::MatrixXf(Eigen::Map<const Eigen::Matrix<float, -1, -1, Eigen::RowMajor>>(c.data_ptr<float>(), t.size(0), t.size(1)));
      };
      const Eigen::MatrixXf da = toEigen(module->forward(s.structure));
      const Eigen::MatrixXf db = toEigen(module->forward(it->second.structure));
      const PairMatchFigures f = pairMatchFigures(s.view, da, it->second.view, db, 0.004);
      hit += f.matched();
      ratio += f.inlier_ratio;
    }
    module->train();
    const double n = std::max<size_t>(1, validation.size());
    return std::make_pair(hit / n, ratio / n);
  };
  auto saveCheckpoint = [&](int step) {
    torch::serialize::OutputArchive a;
    for (const auto& p : module->named_parameters()) a.write("net." + p.key(), p.value().detach());
    torch::serialize::OutputArchive oa;
    adam.save(oa);
    a.write("optimizer", oa);
    a.write("step", c10::IValue(static_cast<int64_t>(step)));
    a.write("best", c10::IValue(rep.best_validation_recall));
    atomicSave(a, ckpt);
  };

  module->train();
  double loss_avg = 0;
  int step = start;
  const float margin = static_cast<float>(cfg.margin);
  for (; step < cfg.steps; ++step) {
    if (cfg.time_limit_s > 0 && std::chrono::duration<double>(Clock::now() - t_start).count() > cfg.time_limit_s) {
      say("time limit reached at step " + std::to_string(step));
      break;
    }
    // every step draws from its own seed: a resumed run sees what an uninterrupted one would
    std::mt19937_64 rng(cfg.seed * 7777777ull + static_cast<uint64_t>(step));
    const size_t m = std::uniform_int_distribution<size_t>(0, meshes.size() - 1)(rng);
    const uint64_t vseed = cfg.seed * 100000ull + static_cast<uint64_t>(step) * 2;
    LaserView a = view(m, randomPose(rng), vseed);
    const bool with_model = std::uniform_real_distribution<double>(0, 1)(rng) < cfg.model_pair_share;
    LaserView b = with_model ? wholeModel(m) : view(m, randomPose(rng), vseed + 1);
    if (with_model && cfg.net.rotation == "augment") {
      // the whole model turned as well: the network must not learn the model frame
      const Eigen::Isometry3f R = randomPose(rng).cast<float>();
      for (size_t i = 0; i < b.cloud.size(); ++i) {
        b.cloud.points[i] = R * b.cloud.points[i];
        b.cloud.normals[i] = R.linear() * b.cloud.normals[i];
      }
    }
    if (a.cloud.size() < 40 || b.cloud.size() < 40) continue;
    auto corr = trueCorrespondences(a, b, cfg.positive_radius);
    if (corr.size() < 16) continue;
    std::shuffle(corr.begin(), corr.end(), rng);
    if (corr.size() > static_cast<size_t>(cfg.anchors)) corr.resize(cfg.anchors);
    const int64_t M = static_cast<int64_t>(corr.size());
    std::vector<int64_t> ia, ib;
    for (const auto& [i, j] : corr) {
      ia.push_back(i);
      ib.push_back(j);
    }
    // negatives: the hardest among a pool of each side's points (any point, not only those
    // with a counterpart: a view's match competes with the whole model, its hidden side too)
    // lying farther than negative_radius from the positive
    const int64_t pool = std::min<int64_t>(cfg.negative_pool, static_cast<int64_t>(std::min(a.cloud.size(), b.cloud.size())));
    std::vector<int64_t> pa(pool), pb(pool);
    for (int64_t k = 0; k < pool; ++k) {
      pa[k] = std::uniform_int_distribution<int64_t>(0, static_cast<int64_t>(a.cloud.size()) - 1)(rng);
      pb[k] = std::uniform_int_distribution<int64_t>(0, static_cast<int64_t>(b.cloud.size()) - 1)(rng);
    }
    std::vector<float> far_b(static_cast<size_t>(M * pool)), far_a(static_cast<size_t>(M * pool));
    const float r2 = static_cast<float>(cfg.negative_radius * cfg.negative_radius);
    for (int64_t i = 0; i < M; ++i) {
      for (int64_t k = 0; k < pool; ++k) {
        far_b[i * pool + k] = (b.truth[ib[i]] - b.truth[pb[k]]).squaredNorm() > r2 ? 1.f : 0.f;
        far_a[i * pool + k] = (a.truth[ia[i]] - a.truth[pa[k]]).squaredNorm() > r2 ? 1.f : 0.f;
      }
    }
    const Sample sa = prepare(std::move(a), cfg.net), sb = prepare(std::move(b), cfg.net);
    const auto all_a = module->forward(sa.structure), all_b = module->forward(sb.structure);
    const auto fa = all_a.index_select(0, torch::tensor(ia)), fb = all_b.index_select(0, torch::tensor(ib));
    const auto pos = (fa - fb).norm(2, 1);
    auto hardest = [&](const torch::Tensor& f, const torch::Tensor& all, const std::vector<int64_t>& idx, std::vector<float>& far) {
      const auto D = torch::cdist(f, all.index_select(0, torch::tensor(idx)));  // [M, pool]
      const auto mask = torch::from_blob(far.data(), {M, pool}, torch::kFloat32);
      return std::get<0>((D + (1 - mask) * 10.f).min(1));  // not negatives: out of the minimum
    };
    const auto neg_row = hardest(fa, all_b, pb, far_b), neg_col = hardest(fb, all_a, pa, far_a);
    torch::Tensor loss;
    if (cfg.loss == "contrastive") {
      loss = pos.pow(2).mean() + 0.5 * (torch::relu(margin - neg_row).pow(2).mean() + torch::relu(margin - neg_col).pow(2).mean());
    } else {
      loss = 0.5 * (torch::relu(pos - neg_row + margin).mean() + torch::relu(pos - neg_col + margin).mean());
    }
    adam.zero_grad();
    loss.backward();
    adam.step();
    const double l = loss.item<double>();
    loss_avg = step == start ? l : 0.98 * loss_avg + 0.02 * l;
    rep.last_loss = loss_avg;
    const bool last = step + 1 == cfg.steps;
    if ((step + 1) % cfg.validate_every == 0 || last) {
      const auto [recall, ratio] = validate();
      rep.validation_recall = recall;
      char line[256];
      std::snprintf(line, sizeof line, "step %d loss %.4f validation: feature-match recall %.3f, inlier ratio %.3f (%.0f s)",
                    step + 1, loss_avg, recall, ratio, std::chrono::duration<double>(Clock::now() - t_start).count());
      if (recall >= rep.best_validation_recall) {
        rep.best_validation_recall = recall;
        net.save(cfg.output);
        std::strcat(line, " - saved");
      }
      saveCheckpoint(step + 1);
      if (cfg.progress) std::fprintf(stderr, "\n");
      say(line);
    }
    if (cfg.progress) {
      const double el = std::chrono::duration<double>(Clock::now() - t_start).count();
      const int done = step + 1 - start, todo = cfg.steps - start;
      const int w = 30, filled = static_cast<int>(w * static_cast<double>(step + 1) / cfg.steps);
      std::fprintf(stderr, "\r[%s%s] %d/%d loss %.4f val %.3f  %.0f s left   ", std::string(filled, '#').c_str(),
                   std::string(w - filled, '.').c_str(), step + 1, cfg.steps, loss_avg, rep.validation_recall,
                   el / std::max(1, done) * (todo - done));
    }
  }
  if (cfg.progress) std::fprintf(stderr, "\n");
  if (!fileExists(cfg.output)) net.save(cfg.output);
  saveCheckpoint(step);
  rep.steps = step;
  rep.seconds = std::chrono::duration<double>(Clock::now() - t_start).count();
  return rep;
}

}  // namespace cellsight
