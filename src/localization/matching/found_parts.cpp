// The parts found, after the (cluster, model) pairs: scan points handed to the nearest part,
// parts that clustering split polished on every piece, second looks at refused poses, and
// detections that would share space.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <numeric>
#include <string>
#include <vector>

#include "matching_internal.hpp"

namespace cellsight {
namespace matching_detail {
namespace {

/// polishSplitParts: a part needs this many points of other clusters or fragments near its model
/// to be polished again on them; at most this many rounds; a round moving a model point less
/// than this ends it (m)
constexpr size_t kSplitMinPoints = 30;
constexpr int kSplitRounds = 3;
constexpr double kSplitSettled = 0.0005;

}  // namespace

/// A scan point's distance to a model (Ti: the inverse of its pose); infinite beyond `radius`.
float modelDistance(const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& Ti, const Vec3& p, float radius) {
  const Vec3 q = Ti * p;
  if (m.has_mesh) {
    const ClosestPoint c = meshClosest(m, q, radius);
    return c.found ? (q - c.point).norm() : std::numeric_limits<float>::infinity();
  }
  const int j = m.field.lookup(q);
  const float d = j < 0 ? std::numeric_limits<float>::infinity() : (q - m.fine->points[j]).norm();
  return d <= radius ? d : std::numeric_limits<float>::infinity();
}

FoundParts::FoundParts(const std::vector<PartDetection>& parts, std::vector<const ModelMatcher::ModelIndex*> models,
                       float r)
    : model(std::move(models)), Tinv(parts.size()), centre(parts.size()), reach(parts.size()), radius(r) {
  for (size_t i = 0; i < parts.size(); ++i) {
    const Eigen::Isometry3f T = parts[i].pose.cast<float>();
    Tinv[i] = T.inverse();
    centre[i] = T * model[i]->centroid.cast<float>();
    reach[i] = model[i]->diameter + radius;
  }
}

float FoundParts::distance(size_t i, const Vec3& p) const {
  if ((p - centre[i]).norm() > reach[i]) return std::numeric_limits<float>::infinity();
  return modelDistance(*model[i], Tinv[i], p, radius);
}

int FoundParts::owner(const Vec3& p) const {
  int best_i = -1;
  float best = std::numeric_limits<float>::infinity();
  for (size_t i = 0; i < centre.size(); ++i) {
    const float d = distance(i, p);
    if (d < best) {
      best = d;
      best_i = static_cast<int>(i);
    }
  }
  return best_i;
}

bool FoundParts::nearerOther(size_t i, const Vec3& p, float d) const {
  for (size_t j = 0; j < centre.size(); ++j)
    if (j != i && distance(j, p) < d) return true;
  return false;
}

/// How far a model point moves from pose a to pose b, the part's symmetry taken out: its
/// centroid's move plus the turn's arc at the part's radius (m).
double modelMove(const ModelMatcher::ModelIndex& m, const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  const PoseError e = poseError(m.info, m.centroid, b, a);
  return e.translation + e.rotation * 0.5 * m.diameter;
}

/// A detection whose pose moved from `before` to d->pose (polished on more points, on a second
/// scan): the turns it cannot be told from move with it, each put in the model's canonical form.
void carryTurns(const ModelMatcher::ModelIndex& m, const Eigen::Isometry3d& before, PartDetection* d) {
  const Eigen::Isometry3d move = d->pose * before.inverse();
  for (auto& a : d->ambiguous_poses) a = canonicalPose(m.info, m.centroid, move * a);
}

/// The index of model `id` among the call's `models` (idx[i] indexes models[i]; id is one of them).
const ModelMatcher::ModelIndex& indexOf(const std::vector<std::shared_ptr<const ModelMatcher::ModelIndex>>& idx,
                                        const std::vector<std::string>& models, const std::string& id) {
  return *idx[std::find(models.begin(), models.end(), id) - models.begin()];
}

/// A part that clustering split (a blade lying flat: its root block's top apart from the blade's)
/// was polished on the piece it was found in, and a flat piece leaves it free to slide: along a
/// tapered blade the scanner's edge loss lets it slide millimetres (tuning cell 3044: 5.4 mm).
/// Each found part with at least kSplitMinPoints points of other clusters or fragments within
/// refine_radius of its model is polished again, on every scan point within refine_radius of its
/// model that lies nearer it than any other found part's, up to kSplitRounds times while it moves
/// by more than kSplitSettled; a pose is kept when it is accepted and explains more of the
/// model's visible surface (fitness: the whole scan's). Coverage stays the matched cluster's.
void polishSplitParts(std::vector<PartDetection>& parts, const std::vector<std::shared_ptr<const ModelMatcher::ModelIndex>>& idx,
                      const std::vector<std::string>& models, const std::vector<Vec3>& scan,
                      const std::vector<int>& scan_cluster, const PointGrid& whole, const SupportSeen& seen,
                      const LightSweep* light, const Eigen::Vector4f* support_plane, const MatchingConfig& cfg,
                      MatchStats& st) {
  std::vector<const ModelMatcher::ModelIndex*> mi(parts.size());
  for (size_t i = 0; i < parts.size(); ++i)
    mi[i] = &indexOf(idx, models, parts[i].model);
  const FoundParts found(parts, mi, static_cast<float>(cfg.refine_radius));
  std::vector<double> moves(parts.size(), -1.0);
  parallelFor(parts.size(), cfg.threads, [&](size_t i) {
    const ModelMatcher::ModelIndex& m = *mi[i];
    PartDetection cur = parts[i];
    double moved = 0;
    int rounds = 0;  // polished and kept
    for (int round = 0; round < kSplitRounds; ++round) {
      // the points within the radius of its model where it now lies, nearer it than any other
      // part's (the others where they were found)
      const FoundParts here({cur}, {&m}, found.radius);
      std::vector<Vec3> pts;
      size_t foreign = 0;
      for (size_t k = 0; k < scan.size(); ++k) {
        const float d = here.distance(0, scan[k]);
        if (!std::isfinite(d) || found.nearerOther(i, scan[k], d)) continue;
        pts.push_back(scan[k]);
        foreign += scan_cluster[k] != cur.cluster;
      }
      if (round == 0 && foreign < kSplitMinPoints) return;
      PartDetection r;
      if (!polishOn(std::move(pts), m, cfg, support_plane, cur, cur.pose.cast<float>(), &whole, &seen, light, &r) ||
          !accepted(r, cfg) || r.fitness <= cur.fitness)
        break;
      r.coverage = cur.coverage;
      r.score = r.fitness * (cfg.min_coverage > 0 ? r.coverage : 1.0);
      const double step = modelMove(m, cur.pose, r.pose);
      moved += step;
      ++rounds;
      cur = r;
      if (step < kSplitSettled) break;
    }
    if (rounds == 0) return;
    carryTurns(m, parts[i].pose, &cur);
    cur.pose = canonicalPose(m.info, m.centroid, cur.pose);
    parts[i] = cur;
    moves[i] = moved;
  });
  for (double d : moves) {
    if (d < 0) continue;
    ++st.split_parts_polished;
    st.split_polish_moved += d;
  }
}

namespace {

/// A refused pose lies clear of every part in `kept`: its centre farther from theirs than a
/// quarter of the two sizes (a wrong pose of a found part's points, or the same part found from
/// another piece, is not).
bool clearOfFound(const PartDetection& d, const std::vector<PartDetection>& kept,
                  const std::vector<std::shared_ptr<const ModelMatcher::ModelIndex>>& idx, const std::vector<std::string>& models) {
  const ModelMatcher::ModelIndex& m = indexOf(idx, models, d.model);
  const Eigen::Vector3d c = d.pose * m.centroid;
  for (const auto& k : kept) {
    const ModelMatcher::ModelIndex& o = indexOf(idx, models, k.model);
    if ((k.pose * o.centroid - c).norm() < 0.25 * (m.diameter + o.diameter)) return false;
  }
  return true;
}

/// Share of b's model surface (its fine points, at most ~4 000 of them evenly) that lies deeper
/// than `depth` inside a's mesh. A point counts only where its closest point on a's mesh lies
/// inside a triangle, straight along its normal: beside an edge the closest triangle's normal
/// does not tell inside from outside (a point level with a thin blade's edge).
double interpenetration(const PartDetection& a, const ModelMatcher::ModelIndex& ma, const PartDetection& b,
                        const ModelMatcher::ModelIndex& mb, float depth) {
  if (!ma.has_mesh || !mb.fine || mb.fine->points.empty()) return 0;
  const Eigen::Isometry3f Tab = (a.pose.inverse() * b.pose).cast<float>();
  const size_t step = std::max<size_t>(1, mb.fine->points.size() / 4000);
  size_t inside = 0, n = 0;
  for (size_t i = 0; i < mb.fine->points.size(); i += step, ++n) {
    const Vec3 q = Tab * mb.fine->points[i];
    const ClosestPoint c = ma.caster.closestPoint(q, ma.diameter);
    if (!c.found) continue;
    const float along = -(q - c.point).dot(c.normal);
    if (along > depth && along >= 0.99f * (q - c.point).norm()) ++inside;
  }
  return n ? static_cast<double>(inside) / static_cast<double>(n) : 0.0;
}

}  // namespace

/// The share of space two detections would hold together: the larger of the two interpenetration
/// shares, 0 when their centroids lie farther apart than half the two diameters.
double sharedSpace(const PartDetection& a, const ModelMatcher::ModelIndex& ma, const PartDetection& b,
                   const ModelMatcher::ModelIndex& mb, float depth) {
  if ((a.pose * ma.centroid - b.pose * mb.centroid).norm() > 0.5 * (ma.diameter + mb.diameter)) return 0;
  return std::max(interpenetration(a, ma, b, mb, depth), interpenetration(b, mb, a, ma, depth));
}

/// Drops every detection that shares space with a better explained one (max_interpenetration).
void dropInterpenetrating(std::vector<PartDetection>& kept, const std::vector<std::shared_ptr<const ModelMatcher::ModelIndex>>& idx,
                          const std::vector<std::string>& models, const MatchingConfig& cfg, MatchStats& st) {
  if (cfg.max_interpenetration >= 1 || kept.size() < 2) return;
  std::vector<size_t> order(kept.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return kept[a].fitness > kept[b].fitness; });
  std::vector<bool> drop(kept.size(), false);
  const float depth = static_cast<float>(cfg.interpenetration_depth);
  for (size_t i = 1; i < order.size(); ++i) {
    const PartDetection& d = kept[order[i]];
    const ModelMatcher::ModelIndex& md = indexOf(idx, models, d.model);
    for (size_t j = 0; j < i && !drop[order[i]]; ++j) {
      if (drop[order[j]]) continue;
      const PartDetection& k = kept[order[j]];
      const ModelMatcher::ModelIndex& mk = indexOf(idx, models, k.model);
      const double share = sharedSpace(k, mk, d, md, depth);
      if (share <= cfg.max_interpenetration) continue;
      drop[order[i]] = true;
      ++st.interpenetrating;
      char why[96];
      std::snprintf(why, sizeof(why), "%.1f %% of a surface deeper than %.1f mm inside the other", 100 * share, depth * 1e3);
      st.warnings.push_back(d.model + " (cluster " + std::to_string(d.cluster) + ", fitness " + std::to_string(d.fitness) +
                            ") and " + k.model + " (cluster " + std::to_string(k.cluster) + ", fitness " + std::to_string(k.fitness) +
                            ") would share space (" + why + "): the better explained kept");
    }
  }
  std::vector<PartDetection> out;
  for (size_t i = 0; i < kept.size(); ++i)
    if (!drop[i]) out.push_back(std::move(kept[i]));
  kept = std::move(out);
}

namespace {

/// A cluster's finite points, thinned to max_cluster_points as locate() thins them.
std::vector<Vec3> clusterPoints(const ScanCloud& cluster, const MatchingConfig& cfg) {
  std::vector<Vec3> points;
  for (const auto& p : cluster.points)
    if (p.allFinite()) points.push_back(p);
  const size_t cap = static_cast<size_t>(std::max(1000.0, cfg.max_cluster_points));
  if (points.size() > cap) points = capPoints(points, cfg.icp_spacing, cap);
  return points;
}

/// Refused poses a second look accepts: each goes, in canonical form, into `kept` at once (the
/// looks after it must lie clear of it) and out of MatchStats::rejected when the look ends.
struct SecondLook {
  std::vector<PartDetection>& kept;
  MatchStats& st;
  std::vector<size_t> taken;  // indices into st.rejected
  void take(size_t i, PartDetection d, const ModelMatcher::ModelIndex& m) {
    d.pose = canonicalPose(m.info, m.centroid, d.pose);
    kept.push_back(d);
    taken.push_back(i);
  }
  /// removes the taken poses from st.rejected; how many were taken
  size_t finish() {
    std::sort(taken.rbegin(), taken.rend());
    for (size_t i : taken) st.rejected.erase(st.rejected.begin() + static_cast<long>(i));
    return taken.size();
  }
};

}  // namespace

/// A second look at refused poses: per cluster, the best pose refused for unseen surface or
/// fitness alone (the fitness at half its floor at least) that lies clear of every part found is
/// tested again with those parts as occluders (what they hide from the camera or shade from the
/// sheet leaves the fitness; their meshes stop the unseen test's rays), and accepted if it
/// passes then.
/// The unseen test counts a model point the scan would have measured, with nothing the scan saw
/// on its camera ray or its beam; a part beside it whose side towards it was not measured (too
/// steep for the camera) still shades it, and only its model, once found, shows that.
void unseenSecondLook(std::vector<PartDetection>& kept, const std::vector<std::shared_ptr<const ModelMatcher::ModelIndex>>& idx,
                      const std::vector<std::string>& models, const std::vector<ScanCloud>& clusters, const PointGrid& whole,
                      const SupportSeen& seen, const LightSweep* light, const MatchingConfig& cfg, MatchStats& st) {
  std::vector<std::pair<const ModelMatcher::ModelIndex*, Eigen::Isometry3f>> found;
  for (const auto& k : kept) found.emplace_back(&indexOf(idx, models, k.model), k.pose.cast<float>().inverse());
  auto clear = [&](const PartDetection& d) { return clearOfFound(d, kept, idx, models); };
  // per cluster, its best refused pose that passes every test but the unseen and fitness ones,
  // the fitness at half its floor at least
  std::map<int, size_t> best;
  for (size_t i = 0; i < st.rejected.size(); ++i) {
    const PartDetection& d = st.rejected[i];
    if (d.cluster < 0 || static_cast<size_t>(d.cluster) >= clusters.size()) continue;
    PartDetection seen_all = d;
    seen_all.unseen = 0;
    if (!accepted(seen_all, cfg, 0.5 * cfg.min_fitness) || !clear(d)) continue;
    const auto it = best.find(d.cluster);
    if (it == best.end() || d.score > st.rejected[it->second].score) best[d.cluster] = i;
  }
  SecondLook look{kept, st, {}};
  for (const auto& [cluster, i] : best) {
    const PartDetection& d = st.rejected[i];
    const ModelMatcher::ModelIndex& m = indexOf(idx, models, d.model);
    if (!clear(d)) continue;  // a part this second look accepted lies there
    const std::vector<Vec3> points = clusterPoints(clusters[cluster], cfg);
    if (points.size() < 3) continue;
    const std::unique_ptr<SceneData> sd = prepareScene(points, cfg);
    if (whole.size() > 0) sd->whole = &whole;
    sd->support_seen = &seen;
    sd->light = light;
    sd->found = &found;
    double unseen = 0;
    const double fitness = visibleFitness(*sd, m, d.pose.cast<float>(), cfg, nullptr, &unseen);
    // (what a found part hides or shades leaves the fitness: it may only rise)
    if (unseen > cfg.max_unseen || std::max(fitness, d.fitness) < cfg.min_fitness) continue;
    PartDetection a = d;
    a.unseen = unseen;
    a.fitness = std::max(fitness, d.fitness);
    a.score = a.fitness * (cfg.min_coverage > 0 ? a.coverage : 1.0);
    look.take(i, a, m);
  }
  st.unseen_second_look += look.finish();
}

/// A second look at refused pieces of split parts: a part that clustering split between a large
/// piece and a small one may get no acceptable pose from either alone (the large piece's voting
/// goes astray; the small piece's pose, near the truth, is millimetres off, for it holds too
/// little of the part to pin it). Per cluster, the best refused pose that explains the cluster
/// (min_coverage) and half the fitness asked (min_fitness / 2), clear of every part found,
/// whose model at that pose lies near at least kSplitMinPoints points of other clusters or
/// fragments (none nearer a found part) is polished on every scan point within refine_radius of
/// its model that no found part lies nearer, up to kSplitRounds times while a round explains more
/// of the model's visible surface and moves it by kSplitSettled or more, and accepted if it
/// passes every test then, its coverage measured on its own cluster. Tried best score first; a
/// pose accepted here makes the others near it not clear.
void splitSecondLook(std::vector<PartDetection>& kept, const std::vector<std::shared_ptr<const ModelMatcher::ModelIndex>>& idx,
                     const std::vector<std::string>& models, const std::vector<ScanCloud>& clusters,
                     const std::vector<Vec3>& scan, const std::vector<int>& scan_cluster, const PointGrid& whole,
                     const SupportSeen& seen, const LightSweep* light, const Eigen::Vector4f* support_plane,
                     const MatchingConfig& cfg, MatchStats& st) {
  auto clear = [&](const PartDetection& d) { return clearOfFound(d, kept, idx, models); };
  std::vector<const ModelMatcher::ModelIndex*> mi;
  for (const auto& k : kept) mi.push_back(&indexOf(idx, models, k.model));
  const FoundParts found(kept, mi, static_cast<float>(cfg.refine_radius));
  // the scan points within the radius of d's model, none nearer a found part; *foreign: how many
  // lie outside d's cluster
  auto near = [&](const PartDetection& d, const ModelMatcher::ModelIndex& m, size_t* foreign) {
    const FoundParts here({d}, {&m}, found.radius);
    std::vector<Vec3> pts;
    *foreign = 0;
    for (size_t k = 0; k < scan.size(); ++k) {
      const float dist = here.distance(0, scan[k]);
      if (!std::isfinite(dist) || found.owner(scan[k]) >= 0) continue;
      pts.push_back(scan[k]);
      *foreign += scan_cluster[k] != d.cluster;
    }
    return pts;
  };
  // per cluster, its best refused pose with foreign points near it, and the scan points near it
  std::map<int, std::pair<size_t, std::vector<Vec3>>> best;
  for (size_t i = 0; i < st.rejected.size(); ++i) {
    const PartDetection& d = st.rejected[i];
    // a piece of a part: the pose explains its own cluster and half the visible surface F asks
    if (d.cluster < 0 || static_cast<size_t>(d.cluster) >= clusters.size() || d.coverage < cfg.min_coverage ||
        d.fitness < 0.5 * cfg.min_fitness || !clear(d))
      continue;
    const auto it = best.find(d.cluster);
    if (it != best.end() && d.score <= st.rejected[it->second.first].score) continue;
    size_t foreign = 0;
    std::vector<Vec3> pts = near(d, indexOf(idx, models, d.model), &foreign);
    if (foreign >= kSplitMinPoints) best[d.cluster] = {i, std::move(pts)};
  }
  std::vector<std::pair<size_t, std::vector<Vec3>>*> order;
  for (auto& [cluster, b] : best) order.push_back(&b);
  std::sort(order.begin(), order.end(), [&](const auto* a, const auto* b) { return st.rejected[a->first].score > st.rejected[b->first].score; });
  SecondLook look{kept, st, {}};
  for (auto* b : order) {
    const size_t i = b->first;
    const PartDetection& d = st.rejected[i];
    if (!clear(d)) continue;  // a part this second look accepted lies there
    const ModelMatcher::ModelIndex& m = indexOf(idx, models, d.model);
    const std::vector<Vec3> own = clusterPoints(clusters[static_cast<size_t>(d.cluster)], cfg);
    if (own.size() < 3) continue;
    const std::unique_ptr<SceneData> cluster_scene = prepareScene(own, cfg);
    cluster_scene->whole = &whole;
    cluster_scene->support_seen = &seen;
    if (light && cfg.check_illumination && !light->empty()) cluster_scene->light = light;
    PartDetection cur = d;
    for (int round = 0; round < kSplitRounds; ++round) {
      size_t foreign = 0;
      std::vector<Vec3> pts = round == 0 ? std::move(b->second) : near(cur, m, &foreign);  // the first: gathered above
      PartDetection r;
      if (pts.size() < 3 || !polishOn(std::move(pts), m, cfg, support_plane, cur, cur.pose.cast<float>(), &whole, &seen, light, &r) ||
          r.fitness <= cur.fitness)
        break;
      r.coverage = coverage(*cluster_scene, m, r.pose.cast<float>(), cfg.fitness_radius);
      r.score = r.fitness * (cfg.min_coverage > 0 ? r.coverage : 1.0);
      const double step = modelMove(m, cur.pose, r.pose);
      cur = r;
      if (step < kSplitSettled) break;
    }
    // polished on points gathered near the model: its traced tests are taken again with its own
    // cluster (on the gathered points they were traced only if those passed)
    if (cur.pose.matrix() != d.pose.matrix()) traceSurfaceTests(*cluster_scene, m, cur.pose.cast<float>(), cfg, support_plane, &cur);
    if (accepted(cur, cfg) && clear(cur)) look.take(i, cur, m);
  }
  st.split_second_look += look.finish();
}

}  // namespace matching_detail
}  // namespace cellsight
