// ModelMatcher::locate over clusters, models and instances (rounds of (cluster, model) pairs,
// then the found parts' second looks), refine() on a second scan, and the merge of two passes.
#include <algorithm>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

#include "matching_internal.hpp"

namespace cellsight {
namespace matching_detail {
namespace {

/// Fragments (unclustered scan points) farther than this from every cluster's box are not
/// evidence for any pose (m): beyond the largest part a cell holds.
constexpr float kFragmentReach = 0.25f;

/// The settings of one locate() or refine() call (its viewpoint, when given), its statistics cleared.
MatchingConfig callSettings(const MatchingConfig& config, const Eigen::Vector3f* viewpoint, MatchStats& st) {
  MatchingConfig cfg = config;
  if (viewpoint) cfg.viewpoint = *viewpoint;
  st = MatchStats();
  return cfg;
}

using Indices = std::vector<std::shared_ptr<const ModelMatcher::ModelIndex>>;

/// One cluster in a round of locate(): what is left of its points, its prepared scene and each
/// model's detection on it.
struct Work {
  int cluster;
  std::vector<Vec3> points;
  std::unique_ptr<SceneData> scene;
  double scene_seconds = 0, descriptor_seconds = 0;
  std::string warning;  // of its scene preparation
  double min_coverage = 1e9;  // asked of a detection here: the config's, less on a second look
  int found = 0;              // detections its cluster has given so far (max_instances bounds them)
  std::vector<PartDetection> per_model;
};

/// The first round: each cluster's finite points (at least 3), thinned to max_cluster_points.
std::vector<Work> firstRound(const std::vector<ScanCloud>& clusters, const MatchingConfig& cfg, MatchStats& st) {
  std::vector<Work> round;
  for (size_t c = 0; c < clusters.size(); ++c) {
    Work w;
    w.cluster = static_cast<int>(c);
    for (const auto& p : clusters[c].points) {
      if (p.allFinite()) w.points.push_back(p);
    }
    if (w.points.size() < 3) {
      st.warnings.push_back("cluster " + std::to_string(c) + ": " + std::to_string(w.points.size()) +
                            " finite points, nothing to match");
      continue;
    }
    const size_t cap = static_cast<size_t>(std::max(1000.0, cfg.max_cluster_points));
    if (w.points.size() > cap) {
      const size_t before = w.points.size();
      w.points = capPoints(w.points, cfg.icp_spacing, cap);
      st.warnings.push_back("cluster " + std::to_string(c) + ": " + std::to_string(before) +
                            " points, above max_cluster_points " + std::to_string(cap) + ": thinned to " +
                            std::to_string(w.points.size()) + " (crop the scene or raise the limit)");
    }
    round.push_back(std::move(w));
  }
  return round;
}

/// The scan the fitness test sees: *scan, every cluster's points and the fragments near them
/// (*scan_cluster: their cluster, -1 for a fragment), and its grid (empty: fitness_whole_scan
/// off, or one cluster and no fragments).
PointGrid wholeScan(const std::vector<Work>& round, const std::vector<Eigen::Vector3f>* fragments,
                    const MatchingConfig& cfg, std::vector<Vec3>* scan, std::vector<int>* scan_cluster) {
  // the fitness test sees every cluster's points: a part that clustering split between two
  // clusters is matched in one and explains its model's points in both; and the fragments, the
  // pieces of scanned surface too small to be clusters (the top of a standing bracket's foot)
  // (only those near the clusters: evidence matters where a pose can lie, and a stray point
  // far away would only stretch the grid)
  std::vector<Vec3> pieces;
  if (fragments && !round.empty()) {
    Eigen::AlignedBox3f near;
    for (const auto& w : round)
      for (const auto& p : w.points) near.extend(p);
    near.min().array() -= kFragmentReach;
    near.max().array() += kFragmentReach;
    for (const auto& p : *fragments)
      if (p.allFinite() && near.contains(p)) pieces.push_back(p);
  }
  *scan = pieces;
  scan_cluster->assign(pieces.size(), -1);
  for (const auto& w : round) {
    scan->insert(scan->end(), w.points.begin(), w.points.end());
    scan_cluster->insert(scan_cluster->end(), w.points.size(), w.cluster);
  }
  PointGrid whole;
  if (cfg.fitness_whole_scan && !round.empty() && (round.size() > 1 || !pieces.empty()))
    whole = PointGrid(*scan, static_cast<float>(cfg.fitness_radius));
  return whole;
}

/// Each cluster's scene (its learned descriptors with `learned`), in parallel; their times and
/// warnings into st.
void prepareScenes(std::vector<Work>& round, const MatchingConfig& cfg, const SupportSeen& seen, const LightSweep* light,
                   const PointGrid& whole, const LearnedDescriptor* learned, MatchStats& st) {
  parallelFor(round.size(), cfg.threads, [&](size_t i) {
    const auto t = Clock::now();
    round[i].scene = prepareScene(round[i].points, cfg);
    round[i].scene->support_seen = &seen;
    if (light && cfg.check_illumination && !light->empty()) round[i].scene->light = light;
    if (whole.size() > 0) round[i].scene->whole = &whole;
    if (learned && cfg.descriptor == "learned" && round[i].scene->coarse.size() >= 3) {
      const auto td = Clock::now();
      SceneData& sd = *round[i].scene;
      try {
        sd.learned = learned->compute(sd.coarse.points, sd.coarse.normals, cfg.learned_scale);
      } catch (const std::invalid_argument& e) {  // a cluster too large for the network: no matches
        round[i].warning = "cluster " + std::to_string(round[i].cluster) + ": " + e.what();
      }
      round[i].descriptor_seconds = seconds(td);
    }
    round[i].scene_seconds = seconds(t);
  });
  for (const auto& w : round) {
    st.scene_seconds += w.scene_seconds;
    st.descriptor_seconds += w.descriptor_seconds;
    if (!w.warning.empty()) st.warnings.push_back(w.warning);
  }
}

/// Matches every (cluster, model) pair of the round worth trying, in parallel, into each
/// cluster's per_model; each cluster's settings (its coverage asked) are returned.
std::vector<MatchingConfig> matchRound(std::vector<Work>& round, const Indices& idx, const std::vector<std::string>& models,
                                       const MatchingConfig& cfg, const Eigen::Vector4f* support_plane, int instance,
                                       MatchStats& st) {
  std::vector<std::pair<size_t, size_t>> pairs;
  // a cluster larger than every model holds several parts (touching ones that clustering
  // could not split): every model is tried on it and coverage is not asked of the first
  // found; what it leaves is searched again
  std::vector<MatchingConfig> wcfg(round.size(), cfg);
  for (size_t w = 0; w < round.size(); ++w) {
    round[w].per_model.assign(models.size(), PartDetection());
    std::vector<size_t> fit;
    for (size_t m = 0; m < models.size(); ++m) {
      const bool too_big = cfg.min_coverage > 0 &&
                           round[w].scene->diameter > 1.15f * idx[m]->diameter + 2 * static_cast<float>(cfg.voxel);
      if (!too_big) fit.push_back(m);
    }
    if (fit.empty() && cfg.min_coverage > 0 && cfg.max_instances > 1) round[w].min_coverage = 0;
    if (round[w].min_coverage < cfg.min_coverage) {
      fit.resize(models.size());
      std::iota(fit.begin(), fit.end(), size_t{0});
    } else {
      st.pairs_skipped_by_size += models.size() - fit.size();
    }
    wcfg[w].min_coverage = std::min(cfg.min_coverage, round[w].min_coverage);
    for (size_t m : fit) pairs.emplace_back(w, m);
  }
  st.pairs += pairs.size();
  parallelFor(pairs.size(), cfg.threads, [&](size_t k) {
    const auto [w, m] = pairs[k];
    if (round[w].scene->coarse.size() < 3) return;
    const uint64_t seed = cfg.seed + 7919 * static_cast<uint64_t>(round[w].cluster) + 104729 * m + 15485863ull * instance;
    round[w].per_model[m] = matchPair(*round[w].scene, *idx[m], wcfg[w], support_plane, seed);
    round[w].per_model[m].cluster = round[w].cluster;
  });
  return wcfg;
}

/// Per cluster of a round: its best part and that part's pose.
struct Choice {
  std::vector<int> best_of;           // the model whose accepted pose scores highest (-1: none)
  std::vector<PartDetection> chosen;  // its pose, turned where that fits closer
  std::vector<char> turned;           // whether it was turned
};

Choice chooseParts(const std::vector<Work>& round, const Indices& idx, const std::vector<std::string>& models,
                   const std::vector<MatchingConfig>& wcfg, const MatchingConfig& cfg,
                   const Eigen::Vector4f* support_plane, MatchStats& st) {
  // each cluster's best part (the model whose accepted pose scores highest), and that pose
  // turned about the support's normal where that fits closer
  std::vector<int> best_of(round.size(), -1);
  for (size_t wi = 0; wi < round.size(); ++wi)
    for (size_t m = 0; m < models.size(); ++m) {
      const PartDetection& d = round[wi].per_model[m];
      if (accepted(d, wcfg[wi]) && (best_of[wi] < 0 || d.score > round[wi].per_model[best_of[wi]].score))
        best_of[wi] = static_cast<int>(m);
    }
  std::vector<PartDetection> chosen(round.size());
  for (size_t wi = 0; wi < round.size(); ++wi)
    if (best_of[wi] >= 0) chosen[wi] = round[wi].per_model[best_of[wi]];
  std::vector<char> turned(round.size(), 0);
  if (cfg.turned_poses) {
    const auto t_turn = Clock::now();
    parallelFor(round.size(), cfg.threads, [&](size_t wi) {
      if (best_of[wi] < 0) return;
      bool t = false;
      chosen[wi] = turnedPose(*round[wi].scene, *idx[best_of[wi]], wcfg[wi], support_plane, chosen[wi], &t);
      turned[wi] = t;
    });
    st.refine_seconds += seconds(t_turn);
  }
  return {std::move(best_of), std::move(chosen), std::move(turned)};
}

/// The round's tally: every pair's times, refused poses into st.rejected, each cluster's part
/// into `out`; what the next round searches is returned (a cluster's leftover points, or a
/// cluster nothing explained, asked half the coverage once).
std::vector<Work> nextRound(std::vector<Work>& round, const Indices& idx, const std::vector<std::string>& models,
                            const std::vector<MatchingConfig>& wcfg, const MatchingConfig& cfg, const Choice& choice,
                            MatchStats& st, std::vector<PartDetection>& out) {
  const std::vector<int>& best_of = choice.best_of;
  const std::vector<PartDetection>& chosen = choice.chosen;
  const std::vector<char>& turned = choice.turned;
  std::vector<Work> next;
  for (size_t wi = 0; wi < round.size(); ++wi) {
    Work& w = round[wi];
    for (size_t m = 0; m < models.size(); ++m) {
      const PartDetection& d = w.per_model[m];
      st.coarse_seconds += d.coarse_seconds;
      st.refine_seconds += d.refine_seconds;
      if (!d.model.empty() && !accepted(d, wcfg[wi])) {
        st.rejected.push_back(d);
        st.rejected.back().refused_by = refusalReasons(d, wcfg[wi]);
      }
    }
    const PartDetection* best = best_of[wi] < 0 ? nullptr : &chosen[wi];
    const size_t best_m = best_of[wi] < 0 ? 0 : static_cast<size_t>(best_of[wi]);
    st.turned_poses += turned[wi];
    if (!best) {
      // nothing explains enough of the cluster: it may hold two touching parts that
      // clustering could not split; searched once more asking half the coverage (the part
      // found then leaves the rest to the next round at the full coverage)
      if (cfg.min_coverage > 0 && w.min_coverage >= cfg.min_coverage && cfg.max_instances > 1) {
        Work again;
        again.cluster = w.cluster;
        again.points = std::move(w.points);
        again.min_coverage = 0.5 * cfg.min_coverage;
        again.found = w.found;
        next.push_back(std::move(again));
      }
      continue;
    }
    PartDetection d = *best;
    // leftover points (another part touching this one) get another search
    const ModelMatcher::ModelIndex& mi = *idx[best_m];
    const Eigen::Isometry3f Ti = d.pose.cast<float>().inverse();
    const float r2 = static_cast<float>(4 * cfg.fitness_radius * cfg.fitness_radius);
    Work rest;
    rest.cluster = w.cluster;
    rest.found = w.found + 1;
    for (const auto& p : w.points) {
      const Vec3 q = Ti * p;
      const int j = mi.field.lookup(q);
      if (j < 0 || (q - mi.fine->points[j]).squaredNorm() > r2) rest.points.push_back(p);
    }
    carryTurns(mi, d.pose, &d);
    d.pose = canonicalPose(mi.info, mi.centroid, d.pose);
    out.push_back(d);
    if (cfg.min_coverage > 0 && rest.found < cfg.max_instances &&
        static_cast<int>(rest.points.size()) >= cfg.min_instance_points) {
      next.push_back(std::move(rest));
    }
  }
  return next;
}

/// The detections in `out` but those of one model found again at about the same place (the
/// better explained one kept).
std::vector<PartDetection> dropFoundTwice(const std::vector<PartDetection>& out, const Indices& idx,
                                          const std::vector<std::string>& models, MatchStats& st) {
  // a part that clustering split is found in each piece at about the same pose: the better
  // explained one stays (two parts of one model cannot share their centre)
  std::vector<size_t> order(out.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return out[a].fitness > out[b].fitness; });
  std::vector<bool> drop(out.size(), false);
  for (size_t i = 0; i < order.size(); ++i) {
    const PartDetection& d = out[order[i]];
    const auto& mi = indexOf(idx, models, d.model);
    for (size_t j = 0; j < i && !drop[order[i]]; ++j) {
      const PartDetection& k = out[order[j]];
      if (drop[order[j]] || k.model != d.model) continue;
      if ((k.pose * mi.centroid - d.pose * mi.centroid).norm() < 0.25 * mi.diameter) {
        drop[order[i]] = true;
        st.warnings.push_back(d.model + " found twice at one place (cluster " + std::to_string(d.cluster) + " and " +
                              std::to_string(k.cluster) + ": pieces of a part that clustering split): the better explained kept");
      }
    }
  }
  std::vector<PartDetection> kept;
  for (size_t i = 0; i < out.size(); ++i)
    if (!drop[i]) kept.push_back(out[i]);
  return kept;
}

}  // namespace
}  // namespace matching_detail

using namespace matching_detail;  // the stages and their data (matching_internal.hpp)

std::vector<PartDetection> ModelMatcher::locate(const std::vector<ScanCloud>& clusters,
                                            const std::vector<std::string>& models_in, MatchStats* stats,
                                            const Eigen::Vector3f* viewpoint, const Eigen::Vector4f* support_plane,
                                            const std::vector<Eigen::Vector3f>* support_points, const LightSweep* light,
                                            const std::vector<Eigen::Vector3f>* fragments) const {
  const auto t0 = Clock::now();
  MatchStats local;
  MatchStats& st = stats ? *stats : local;
  const MatchingConfig cfg = callSettings(config_, viewpoint, st);
  if (!fallback_warning_.empty()) st.warnings.push_back(fallback_warning_);
  std::vector<std::string> models = models_in.empty() ? library_->ids() : models_in;
  for (const auto& id : models) library_->model(id);  // unknown id: throws before any work
  std::vector<std::shared_ptr<const ModelIndex>> idx(models.size());
  parallelFor(models.size(), cfg.threads, [&](size_t i) { idx[i] = index(models[i]); });
  SupportSeen seen;
  // the see-through test reads where the table was seen; the unseen test, where the table is
  if (support_plane && support_points && (cfg.max_see_through < 1 || cfg.max_unseen < 1))
    seen = buildSupportSeen(*support_points, *support_plane, static_cast<float>(cfg.voxel));
  std::vector<PartDetection> out;
  std::vector<Work> round = firstRound(clusters, cfg, st);
  std::vector<Vec3> scan;         // every cluster's points and the fragments near them
  std::vector<int> scan_cluster;  // ... their cluster (-1: a fragment)
  PointGrid whole = wholeScan(round, fragments, cfg, &scan, &scan_cluster);
  // a round searches what is left of each cluster; a second look takes a round but finds no
  // more parts than max_instances, so the rounds are bounded by twice that
  for (int instance = 0; instance < 2 * std::max(1, cfg.max_instances) && !round.empty(); ++instance) {
    prepareScenes(round, cfg, seen, light, whole, learned_.get(), st);
    const std::vector<MatchingConfig> wcfg = matchRound(round, idx, models, cfg, support_plane, instance, st);
    const Choice choice = chooseParts(round, idx, models, wcfg, cfg, support_plane, st);
    round = nextRound(round, idx, models, wcfg, cfg, choice, st, out);
  }
  std::vector<PartDetection> kept = dropFoundTwice(out, idx, models, st);
  if (cfg.polish_split_parts && whole.size() > 0) {
    const auto t_split = Clock::now();
    polishSplitParts(kept, idx, models, scan, scan_cluster, whole, seen, light, support_plane, cfg, st);
    st.refine_seconds += seconds(t_split);
  }
  if (cfg.split_second_look && whole.size() > 0) {
    const auto t_look = Clock::now();
    splitSecondLook(kept, idx, models, clusters, scan, scan_cluster, whole, seen, light, support_plane, cfg, st);
    st.refine_seconds += seconds(t_look);
  }
  if (cfg.unseen_second_look && light && cfg.check_illumination && cfg.check_visibility && !light->empty() && cfg.max_unseen < 1 &&
      !kept.empty()) {
    const auto t_look = Clock::now();
    unseenSecondLook(kept, idx, models, clusters, whole, seen, light, cfg, st);
    st.refine_seconds += seconds(t_look);
  }
  dropInterpenetrating(kept, idx, models, cfg, st);
  st.seconds = seconds(t0);
  return kept;
}

std::vector<PartDetection> ModelMatcher::refine(const ScanCloud& scan, const std::vector<PartDetection>& parts,
                                               MatchStats* stats, const Eigen::Vector3f* viewpoint,
                                               const Eigen::Vector4f* support_plane) const {
  const auto t0 = Clock::now();
  MatchStats local;
  MatchStats& st = stats ? *stats : local;
  const MatchingConfig cfg = callSettings(config_, viewpoint, st);
  std::vector<std::shared_ptr<const ModelIndex>> idx(parts.size());
  for (size_t i = 0; i < parts.size(); ++i) library_->model(parts[i].model);  // unknown id: throws first
  parallelFor(parts.size(), cfg.threads, [&](size_t i) { idx[i] = index(parts[i].model); });
  std::vector<const ModelIndex*> mi(parts.size());
  for (size_t i = 0; i < parts.size(); ++i) mi[i] = idx[i].get();
  const FoundParts found(parts, mi, static_cast<float>(cfg.refine_radius));
  // each scan point goes to the nearest part within the radius
  std::vector<int> owner(scan.points.size(), -1);
  parallelFor(scan.points.size(), cfg.threads, [&](size_t k) {
    if (scan.points[k].allFinite()) owner[k] = found.owner(scan.points[k]);
  });
  std::vector<std::vector<Vec3>> points(parts.size());
  for (size_t k = 0; k < scan.points.size(); ++k) {
    if (owner[k] >= 0) points[static_cast<size_t>(owner[k])].push_back(scan.points[k]);
  }
  std::vector<PartDetection> out = parts;
  std::vector<std::string> why(parts.size());
  parallelFor(parts.size(), cfg.threads, [&](size_t i) {
    const ModelIndex& m = *idx[i];
    const std::string name = "part " + std::to_string(i) + " (" + parts[i].model + ")";
    if (static_cast<int>(points[i].size()) < cfg.refine_min_points) {
      why[i] = name + ": " + std::to_string(points[i].size()) + " points of the second scan within refine_radius, below refine_min_points " +
               std::to_string(cfg.refine_min_points) + ": pose kept";
      return;
    }
    const auto t = Clock::now();
    PartDetection r;
    if (!polishOn(std::move(points[i]), m, cfg, support_plane, parts[i], parts[i].pose.cast<float>(), nullptr, nullptr,
                  nullptr, &r) ||
        !accepted(r, cfg)) {
      why[i] = name + ": the second scan's pose failed validation (fitness " + std::to_string(r.fitness) + ", coverage " +
               std::to_string(r.coverage) + ", rmse " + std::to_string(r.rmse * 1e3) + " mm, see-through " +
               std::to_string(r.see_through) + "): pose kept";
      return;
    }
    const double shift = modelMove(m, parts[i].pose, r.pose);
    if (shift > cfg.refine_max_shift) {
      why[i] = name + ": the second scan moves it " + std::to_string(shift * 1e3) + " mm, above refine_max_shift: pose kept";
      return;
    }
    carryTurns(m, parts[i].pose, &r);
    r.pose = canonicalPose(m.info, m.centroid, r.pose);
    r.refined = true;
    r.refine_seconds = parts[i].refine_seconds + seconds(t);
    out[i] = r;
  });
  for (const auto& w : why) {
    if (!w.empty()) st.warnings.push_back(w);
  }
  st.seconds = seconds(t0);
  return out;
}

std::vector<PartDetection> ModelMatcher::mergePasses(const std::vector<PartDetection>& first,
                                                     const std::vector<PartDetection>& second, MatchStats* stats) const {
  MatchStats local;
  MatchStats& st = stats ? *stats : local;
  for (const auto* pass : {&first, &second})
    for (const auto& d : *pass) library_->model(d.model);  // unknown id: throws before any work
  std::vector<PartDetection> out = first;
  std::vector<std::shared_ptr<const ModelIndex>> idx;
  for (const auto& d : out) idx.push_back(index(d.model));
  const float depth = static_cast<float>(config_.interpenetration_depth);
  for (const auto& d : second) {
    const std::shared_ptr<const ModelIndex> md = index(d.model);
    const Eigen::Vector3d c = d.pose * md->centroid;
    bool taken = false;
    for (size_t k = 0; k < out.size() && !taken; ++k) {
      const ModelIndex& mk = *idx[k];
      // the same part, however turned (the quarter of clearOfFound), or one that would share its space
      taken = (out[k].model == d.model && (c - out[k].pose * mk.centroid).norm() < 0.25 * (md->diameter + mk.diameter)) ||
              (config_.max_interpenetration < 1 && sharedSpace(out[k], mk, d, *md, depth) > config_.max_interpenetration);
    }
    if (taken) {
      ++st.second_pass_taken;
      continue;
    }
    out.push_back(d);
    out.back().pass = 1;
    idx.push_back(md);
    ++st.second_pass_added;
  }
  return out;
}

}  // namespace cellsight
