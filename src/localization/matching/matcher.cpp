// ModelMatcher: the per-model index built once, one (cluster, model) pair from coarse stage to
// validated pose, and locate() over clusters, models and instances.
#include <algorithm>
#include <pcl/features/normal_3d.h>
#include <pcl/search/kdtree.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <map>
#include <numeric>
#include <stdexcept>

#include "cellsight/localization/fgr.hpp"
#include "matching_internal.hpp"

namespace cellsight {
namespace matching_detail {
namespace {

/// Screened candidates polished per (cluster, model) pair.
constexpr size_t kPolished = 2;
/// Turns of a pose within this of one another (rad, modulo the model's symmetry) are one pose.
constexpr double kSameTurn = 2 * M_PI / 180;
/// a turned pose that the polish brought within this of another (half the smallest turn tried)
/// came back to it: refinement scatter, not another pose
constexpr double kOtherTurn = 45 * M_PI / 180;
/// polishSplitParts: a part needs this many points of other clusters or fragments near its model
/// to be polished again on them; at most this many rounds; a round moving a model point less
/// than this ends it (m)
constexpr size_t kSplitMinPoints = 30;
constexpr int kSplitRounds = 3;
constexpr double kSplitSettled = 0.0005;

/// Fragments (unclustered scan points) farther than this from every cluster's box are not
/// evidence for any pose (m): beyond the largest part a cell holds.
constexpr float kFragmentReach = 0.25f;

/// Flat faces smaller than this are not laid onto planar clusters: 25 coarse cells.
float patchMinArea(const MatchingConfig& cfg) { return static_cast<float>(25 * cfg.voxel * cfg.voxel); }

/// The settings of one locate() or refine() call (its viewpoint, when given), its statistics cleared.
MatchingConfig callSettings(const MatchingConfig& config, const Eigen::Vector3f* viewpoint, MatchStats& st) {
  MatchingConfig cfg = config;
  if (viewpoint) cfg.viewpoint = *viewpoint;
  st = MatchStats();
  return cfg;
}

/// ICP from T0 (polished with exact neighbours when `polish`), scored into *c (a copy of `d`
/// with the pose and its figures); a polished pose good enough to report goes to the middle of
/// its slack, kept if it still is. False when the ICP diverged or the pose is off the support.
/// The unseen share and the surface carried on past the model's faces of d under T, traced (rays
/// through the scan) only for a pose that passes every other test, the fitness test at half its
/// floor, with a sweep (a refused pose reports them too, MatchStats::rejected); 0 otherwise.
void traceSurfaceTests(const SceneData& s, const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T,
                       const MatchingConfig& cfg, const Eigen::Vector4f* support, PartDetection* d) {
  d->unseen = d->continuation = 0;
  if (!s.light || !accepted(*d, cfg, 0.5 * cfg.min_fitness)) return;
  visibleFitness(s, m, T, cfg, nullptr, &d->unseen);
  d->continuation = continuation(s, m, T, cfg, support);
}

/// T laid into the model's stable rest nearest its tilt on the support, when that tilt is at
/// most max_angle and at least min_angle (less: what the scan says of the tilt is kept): turned
/// about the model's centroid so that the rest's facet faces the support. False: no such rest.
bool layIntoRest(const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T, const Eigen::Vector4f& support,
                 double min_angle, double max_angle, Eigen::Isometry3f* out) {
  const Eigen::Vector3d n = support.head<3>().cast<double>().normalized();
  const Eigen::Matrix3d R = T.linear().cast<double>();
  const Eigen::Vector3d up = R.transpose() * n;  // the support's normal in the model frame
  double best = max_angle;
  const RestPose* rest = nullptr;
  for (const RestPose& r : m.rests) {
    const double a = std::acos(std::clamp(r.R.row(2).dot(up), -1.0, 1.0));
    if (a <= best) best = a, rest = &r;
  }
  if (!rest || best < min_angle) return false;
  const Eigen::Matrix3d S = Eigen::Quaterniond::FromTwoVectors(R * rest->R.row(2).transpose(), n).toRotationMatrix();
  const Eigen::Vector3d c = T.cast<double>() * m.centroid;
  Eigen::Isometry3d Tr = Eigen::Isometry3d::Identity();
  Tr.linear() = S * R;
  Tr.translation() = c - Tr.linear() * m.centroid;
  *out = Tr.cast<float>();
  return true;
}

/// ICP from T0 (see finishPose), its tilt held about `up` when given, scored into *c and centred
/// in its slack. False when the ICP diverged or the pose is off the support.
bool polishAndCentre(const SceneData& s, const ModelMatcher::ModelIndex& m, const MatchingConfig& cfg,
                     const Eigen::Vector4f* support, const PartDetection& d, const Eigen::Isometry3f& T0,
                     size_t points, bool polish, const Eigen::Vector3d* up, PartDetection* c) {
  Refined r = icp(s, m, T0, cfg, points, polish, up);
  if (!r.T.matrix().allFinite()) return false;
  if (support && offSupport(m, r.T, *support, cfg)) return false;
  auto score = [&](const Eigen::Isometry3f& T, PartDetection* out) {
    *out = d;
    out->pose = T.cast<double>();
    out->rmse = r.rmse;
    out->coverage = coverage(s, m, T, cfg.fitness_radius);
    out->fitness = visibleFitness(s, m, T, cfg, &out->see_through, nullptr, &out->overhang);
    out->score = out->fitness * (cfg.min_coverage > 0 ? out->coverage : 1.0);
    traceSurfaceTests(s, m, T, cfg, support, out);
  };
  score(r.T, c);
  // the unseen share is not asked before centring: a pose left a millimetre off across a narrow
  // face claims surface past the face's scanned edge, and is measured again where it settles
  PartDetection before = *c;
  before.unseen = 0;
  before.continuation = 0;
  before.overhang = 0;
  if (polish && cfg.icp_centre_slack && !r.polished.empty() && accepted(before, cfg)) {
    Eigen::Vector3d up_model;
    if (up) up_model = (r.T.linear().cast<double>().transpose() * *up).normalized();
    const Eigen::Isometry3d D = centreInSlack(m, r.polished, r.polished_fresh, cfg, up ? &up_model : nullptr);
    const Eigen::Isometry3f T = (r.T.cast<double>() * D.inverse()).cast<float>();
    PartDetection centred;
    if (T.matrix().allFinite() && !(support && offSupport(m, T, *support, cfg))) {
      score(T, &centred);
      if (accepted(centred, cfg)) *c = centred;
    }
  }
  return true;
}

bool finishPose(const SceneData& s, const ModelMatcher::ModelIndex& m, const MatchingConfig& cfg,
                const Eigen::Vector4f* support, const PartDetection& d, const Eigen::Isometry3f& T0, size_t points,
                bool polish, PartDetection* c) {
  if (!polishAndCentre(s, m, cfg, support, d, T0, points, polish, nullptr, c)) return false;
  // A part lying on the support lies in one of its rests. A pose a little tilted from one is
  // laid into it and polished again with the tilt held; it replaces the free pose where it is
  // accepted and fits about as closely (the free pose refused: where it is accepted).
  Eigen::Isometry3f Tr;
  if (!polish || !support || !(cfg.rest_snap_angle > 0) ||
      !layIntoRest(m, c->pose.cast<float>(), *support, cfg.rest_snap_min_angle, cfg.rest_snap_angle, &Tr))
    return true;
  const Eigen::Vector3d up = support->head<3>().cast<double>().normalized();
  PartDetection rested;
  if (!polishAndCentre(s, m, cfg, support, d, Tr, points, true, &up, &rested)) return true;
  const bool keep = accepted(rested, cfg) && (!accepted(*c, cfg) || rested.rmse <= cfg.rest_snap_rmse_ratio * c->rmse);
  if (keep) *c = rested;
  return true;
}

/// A spherical model's pose from a scene view of it: the median of the points moved by the
/// model's radius against their normals (normals face the camera, out of a convex part).
bool sphereCentre(const SceneData& s, const ModelMatcher::ModelIndex& m, Eigen::Isometry3f* T) {
  const auto& fp = m.fine->points;
  const auto& sp = s.coarse.points;
  const auto& sn = s.coarse.normals;
  if (fp.empty() || sp.size() < 3 || sn.size() != sp.size()) return false;
  const Vec3 c = m.centroid.cast<float>();
  double r = 0;
  for (const auto& p : fp) r += (p - c).norm();
  r /= static_cast<double>(fp.size());
  std::array<std::vector<float>, 3> xyz;
  for (size_t i = 0; i < sp.size(); ++i) {
    if (!sp[i].allFinite() || !sn[i].allFinite()) continue;
    const Vec3 q = sp[i] - static_cast<float>(r) * sn[i];
    for (int k = 0; k < 3; ++k) xyz[k].push_back(q[k]);
  }
  if (xyz[0].size() < 3) return false;
  Vec3 centre;
  for (int k = 0; k < 3; ++k) {
    auto& v = xyz[k];
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    centre[k] = v[v.size() / 2];
  }
  *T = Eigen::Isometry3f::Identity();
  T->translation() = centre - c;
  return true;
}

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

/// Found parts at their poses, for handing scan points to them: a point belongs to the part
/// whose model lies nearest it, within `radius`.
struct FoundParts {
  std::vector<const ModelMatcher::ModelIndex*> model;  // per part
  std::vector<Eigen::Isometry3f> Tinv;
  std::vector<Vec3> centre;
  std::vector<float> reach;  // no point of part i lies farther from its centre (its centroid lies inside)
  float radius = 0;
  FoundParts(const std::vector<PartDetection>& parts, std::vector<const ModelMatcher::ModelIndex*> models, float r)
      : model(std::move(models)), Tinv(parts.size()), centre(parts.size()), reach(parts.size()), radius(r) {
    for (size_t i = 0; i < parts.size(); ++i) {
      const Eigen::Isometry3f T = parts[i].pose.cast<float>();
      Tinv[i] = T.inverse();
      centre[i] = T * model[i]->centroid.cast<float>();
      reach[i] = model[i]->diameter + radius;
    }
  }
  /// p's distance to part i's model at its pose (infinite beyond the radius)
  float distance(size_t i, const Vec3& p) const {
    if ((p - centre[i]).norm() > reach[i]) return std::numeric_limits<float>::infinity();
    return modelDistance(*model[i], Tinv[i], p, radius);
  }
  /// the part p belongs to (-1: none within the radius)
  int owner(const Vec3& p) const {
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
  /// another part than i lies nearer p than d
  bool nearerOther(size_t i, const Vec3& p, float d) const {
    for (size_t j = 0; j < centre.size(); ++j)
      if (j != i && distance(j, p) < d) return true;
    return false;
  }
};

/// How far a model point moves from pose a to pose b, the part's symmetry taken out: its
/// centroid's move plus the turn's arc at the part's radius (m).
double modelMove(const ModelMatcher::ModelIndex& m, const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  const PoseError e = poseError(m.info, m.centroid, b, a);
  return e.translation + e.rotation * 0.5 * m.diameter;
}

/// `d` polished (and centred in its slack) from T0 on `points` (thinned to max_cluster_points),
/// its figures taken with the scene's whole-scan grid, support and sweep where given; false when
/// the ICP diverged or the pose left the support.
bool polishOn(std::vector<Vec3> points, const ModelMatcher::ModelIndex& m, const MatchingConfig& cfg,
              const Eigen::Vector4f* support_plane, const PartDetection& d, const Eigen::Isometry3f& T0,
              const PointGrid* whole, const SupportSeen* seen, const LightSweep* light, PartDetection* r) {
  const size_t cap = static_cast<size_t>(std::max(1000.0, cfg.max_cluster_points));
  if (points.size() > cap) points = capPoints(points, cfg.icp_spacing, cap);
  const std::unique_ptr<SceneData> sd = prepareScene(points, cfg);
  sd->whole = whole;
  sd->support_seen = seen;
  if (light && cfg.check_illumination && !light->empty()) sd->light = light;
  const size_t all_points = static_cast<size_t>(std::max(100.0, cfg.icp_max_points));
  return finishPose(*sd, m, cfg, support_plane, d, T0, all_points, true, r);
}

PartDetection matchPair(const SceneData& s, const ModelMatcher::ModelIndex& m, const MatchingConfig& cfg,
                    const Eigen::Vector4f* support, uint64_t seed) {
  PartDetection d;
  d.model = m.id;
  d.matcher = cfg.coarse;
  std::vector<Hypothesis> candidates;
  const auto t_coarse = Clock::now();
  if (cfg.coarse == "ppf") {
    candidates = ppfHypotheses(s, m, cfg, support, &d.iterations);
  } else if (cfg.descriptor == "learned") {
    // every turn of the model's descriptors gives its own correspondences and hypotheses; the
    // refinement below scores them all (T = T_found · T_turn: the model points are not turned)
    for (size_t turn = 0; turn < m.learned.size(); ++turn) {
      if (cfg.coarse == "fgr") {
        // FGR matches the features itself
        const auto& sf = s.learned;
        const auto& mf = m.learned[turn];
        const auto& sp = s.coarse.points;
        const auto& mp = m.coarse->points;
        FgrOptions o;
        o.max_correspondence_distance = cfg.inlier_distance;
        o.seed = static_cast<int>((seed + turn) % 1000003);
        Hypothesis h;
        try {
          h.T = fastGlobalRegistration(mp, mf, sp, sf, o).cast<float>();
          candidates.push_back(h);
        } catch (const std::exception&) {
        }
        d.iterations += o.iterations;
      } else {
        int it = 0;
        for (auto& h : ransac(s, m, learnedCorrespondences(s, m, turn, cfg), cfg, seed + 31 * turn, &it))
          candidates.push_back(h);
        d.iterations += it;
      }
    }
    std::sort(candidates.begin(), candidates.end(), [](const Hypothesis& a, const Hypothesis& b) { return a.score > b.score; });
    if (cfg.coarse == "ransac" && candidates.size() > static_cast<size_t>(std::max(1, cfg.refine_candidates)))
      candidates.resize(std::max(1, cfg.refine_candidates));
  } else if (cfg.coarse == "fgr") {
    std::vector<Vec3> sp, mp;
    std::vector<Fpfh> sf, mf;
    for (int i : s.fpfh_valid) {
      sp.push_back(s.coarse.points[i]);
      sf.push_back(s.fpfh[i]);
    }
    for (int i : m.fpfh_valid) {
      mp.push_back(m.coarse->points[i]);
      mf.push_back(m.fpfh[i]);
    }
    FgrOptions o;
    o.max_correspondence_distance = cfg.inlier_distance;
    o.seed = static_cast<int>(seed % 1000003);
    Hypothesis h;
    try {
      h.T = fastGlobalRegistration(mp, mf, sp, sf, o).cast<float>();
      candidates.push_back(h);
    } catch (const std::exception&) {
      // Open3D throws when too few matches survive its tuple test: no hypothesis
    }
    d.iterations = o.iterations;
  } else {
    candidates = ransac(s, m, correspondences(s, m, cfg), cfg, seed, &d.iterations);
  }
  // a sphere's pose is its centre, and every point of it, with its normal, points there (on a
  // sphere every pair of a given distance has the same feature: votes do not tell poses apart,
  // and a small cap may get no pose from them at all)
  if (m.info.symmetry.type == Symmetry::Type::kSpherical) {
    Hypothesis h;
    if (sphereCentre(s, m, &h.T)) candidates.insert(candidates.begin(), h);
  }
  d.coarse_seconds = seconds(t_coarse);
  const auto t_refine = Clock::now();
  // Every candidate is refined on a thinned scene (distance-field neighbours only) and scored;
  // the best one is then refined on all the ICP points and polished with exact neighbours.
  auto evaluate = [&](const Eigen::Isometry3f& T0, size_t points, bool polish, PartDetection* c) {
    return finishPose(s, m, cfg, support, d, T0, points, polish, c);
  };
  const size_t all_points = static_cast<size_t>(std::max(100.0, cfg.icp_max_points));
  const size_t screen_points = std::min(all_points, static_cast<size_t>(std::max(100.0, cfg.icp_screen_points)));
  std::vector<PartDetection> screened;
  for (const auto& h : candidates) {
    if (!h.T.matrix().allFinite()) continue;
    PartDetection c;
    if (evaluate(h.T, screen_points, false, &c)) screened.push_back(c);
  }
  // the polish moves a pose by a fraction of a millimetre and does not change where the camera
  // saw the table: a pose it saw through ranks after every pose it did not
  auto clear = [&](const PartDetection& c) { return c.see_through <= cfg.max_see_through; };
  std::stable_sort(screened.begin(), screened.end(), [&](const PartDetection& a, const PartDetection& b) {
    if (clear(a) != clear(b)) return clear(a);
    return a.score > b.score;
  });
  // near-equal fitness does not tell a pose that converged from one that stopped a degree off:
  // the best kPolished are polished, and an accepted one beats a better-scored refused one;
  // while none is accepted the next ones are polished too (the best two can be one wrong pose
  // reached twice, hiding a right one ranked third)
  PartDetection fine = d;
  for (size_t k = 0; k < screened.size() && (k < kPolished || !accepted(fine, cfg)); ++k) {
    if (k > 0 && !clear(screened[k])) break;
    PartDetection f;
    if (!evaluate(screened[k].pose.cast<float>(), all_points, true, &f)) f = screened[k];
    const bool better = accepted(f, cfg) ? !accepted(fine, cfg) || f.score > fine.score : !accepted(fine, cfg) && f.score > fine.score;
    if (k == 0 || better) fine = f;
  }
  fine.refine_seconds = seconds(t_refine);
  return fine;
}

/// A detection whose pose moved from `before` to d->pose (polished on more points, on a second
/// scan): the turns it cannot be told from move with it, each put in the model's canonical form.
void carryTurns(const ModelMatcher::ModelIndex& m, const Eigen::Isometry3d& before, PartDetection* d) {
  const Eigen::Isometry3d move = d->pose * before.inverse();
  for (auto& a : d->ambiguous_poses) a = canonicalPose(m.info, m.centroid, move * a);
}

/// The found pose, or one turned about the support's normal that fits the scan about as closely
/// (RMSE within turned_rmse_ratio of the closest) and scores higher (MatchingConfig::turned_poses).
/// *turned: whether it was turned.
PartDetection turnedPose(const SceneData& s, const ModelMatcher::ModelIndex& m, const MatchingConfig& cfg,
                         const Eigen::Vector4f* support, const PartDetection& found, bool* turned) {
  *turned = false;
  if (!support || m.info.symmetry.type == Symmetry::Type::kSpherical || !accepted(found, cfg)) return found;
  const Eigen::Vector3f up = support->head<3>().normalized();
  // the turn's axis: the vertical through the scan points the part explains (a turn about the
  // model's centroid would carry the scanned face away, farther than the polish reaches)
  const Eigen::Isometry3f T = found.pose.cast<float>();
  const Eigen::Isometry3f Ti = T.inverse();
  const float r = static_cast<float>(cfg.fitness_radius);
  Vec3 pivot = Vec3::Zero();
  size_t n = 0;
  for (const auto& p : s.icp_points)
    if (std::isfinite(modelDistance(m, Ti, p, r))) pivot += p, ++n;
  if (n < 3) return found;
  pivot /= static_cast<float>(n);
  const size_t all_points = static_cast<size_t>(std::max(100.0, cfg.icp_max_points));
  const size_t screen_points = std::min(all_points, static_cast<size_t>(std::max(100.0, cfg.icp_screen_points)));
  std::vector<PartDetection> poses{found};
  for (int k = 1; k < 4; ++k) {
    const Eigen::Isometry3f Tk =
        Eigen::Translation3f(pivot) * Eigen::AngleAxisf(static_cast<float>(k * M_PI / 2), up) * Eigen::Translation3f(-pivot) * T;
    // a turn the model's symmetry undoes (an upright shaft, a holder standing on its base
    // turned by a half) leaves the found pose shifted sideways at most, which the polish would
    // undo; and a turned pose that screens at less than half the found one's score is not polished
    if (poseError(m.info, m.centroid, Tk.cast<double>(), found.pose).rotation < kSameTurn) continue;
    PartDetection screened, f;
    if (!finishPose(s, m, cfg, support, found, Tk, screen_points, false, &screened) || screened.score < 0.5 * found.score) continue;
    if (finishPose(s, m, cfg, support, found, screened.pose.cast<float>(), all_points, true, &f) && accepted(f, cfg))
      poses.push_back(f);
  }
  double closest = found.rmse;
  for (size_t k = 1; k < poses.size(); ++k) closest = std::min(closest, poses[k].rmse);
  // poses that fit about as closely as the closest compete on score; the found one wins ties
  // (turned_rmse_ratio <= 1, the constructor's check: the closest always qualifies)
  const PartDetection* best = nullptr;
  for (const auto& p : poses)
    if (p.rmse * cfg.turned_rmse_ratio <= closest && (!best || p.score > best->score)) best = &p;
  *turned = best != &poses.front();
  // the others among those, unless the polish brought them back towards the winner: the scan
  // tells the winner from them only by the difference of their scores
  PartDetection out = *best;
  std::vector<const PartDetection*> others;
  for (const auto& p : poses)
    if (&p != best && p.rmse * cfg.turned_rmse_ratio <= closest && p.score > 0 &&
        poseError(m.info, m.centroid, p.pose, best->pose).rotation >= kOtherTurn)
      others.push_back(&p);
  std::sort(others.begin(), others.end(), [](const PartDetection* a, const PartDetection* b) { return a->score > b->score; });
  if (!others.empty() && out.score > 0) out.alternative_score_share = others.front()->score / out.score;
  for (const PartDetection* p : others) {
    if (p->score < cfg.ambiguous_score_ratio * out.score) break;
    // two turns the polish brought to one pose are one alternative
    if (std::none_of(out.ambiguous_poses.begin(), out.ambiguous_poses.end(), [&](const Eigen::Isometry3d& q) {
          return poseError(m.info, m.centroid, p->pose, q).rotation < kOtherTurn;
        }))
      out.ambiguous_poses.push_back(p->pose);
  }
  return out;
}

}  // namespace
}  // namespace matching_detail

using namespace matching_detail;  // the stages and their data (matching_internal.hpp)

ModelMatcher::ModelMatcher(std::shared_ptr<const ModelLibrary> library, const MatchingConfig& config)
    : library_(std::move(library)), config_(config) {
  if (!library_) throw std::invalid_argument("ModelMatcher: no model library");
  if (config_.coarse != "ppf" && config_.coarse != "ransac" && config_.coarse != "fgr") {
    throw std::invalid_argument("ModelMatcher: coarse must be 'ppf', 'ransac' or 'fgr' (got '" + config_.coarse + "')");
  }
  if (config_.scene_search != "grid" && config_.scene_search != "kdtree") {
    throw std::invalid_argument("ModelMatcher: scene_search must be 'grid' or 'kdtree' (got '" + config_.scene_search + "')");
  }
  if (!(config_.turned_rmse_ratio > 0 && config_.turned_rmse_ratio <= 1)) {
    throw std::invalid_argument("ModelMatcher: turned_rmse_ratio must be in (0, 1] (got " +
                                std::to_string(config_.turned_rmse_ratio) + ")");
  }
  if (!(config_.ambiguous_score_ratio >= 0 && config_.ambiguous_score_ratio <= 1)) {
    throw std::invalid_argument("ModelMatcher: ambiguous_score_ratio must be in [0, 1] (got " +
                                std::to_string(config_.ambiguous_score_ratio) + ")");
  }
  if (config_.threads <= 0) config_.threads = std::max(1u, std::thread::hardware_concurrency());
  if (config_.descriptor == "learned" && config_.coarse != "ppf") {
    try {
      learned_ = std::make_shared<const LearnedDescriptor>(LearnedDescriptor::load(config_.learned_model, config_.learned_dims));
      LearnedDescriptor::setThreads(1);  // the matcher runs its pairs in parallel itself
    } catch (const DescriptorModelError& e) {
      if (!config_.learned_fallback) throw;
      fallback_warning_ = std::string(e.what()) + "; descriptor: fpfh is used instead (learned_fallback)";
      config_.descriptor = "fpfh";
    }
  }
}

ModelMatcher::~ModelMatcher() = default;

void ModelMatcher::addLearned(ModelIndex& m) const {
  if (!learned_) return;
  m.learned.clear();
  for (const Eigen::Matrix3f& R : descriptorTurns(config_.learned_rotations)) {
    std::vector<Vec3> p(m.coarse->size()), n(m.coarse->size());
    for (size_t i = 0; i < p.size(); ++i) {
      p[i] = R * m.coarse->points[i];
      n[i] = R * m.coarse->normals[i];
    }
    m.learned.push_back(learned_->compute(p, n, config_.learned_scale));
  }
}

std::shared_ptr<const ModelMatcher::ModelIndex> ModelMatcher::index(const std::string& id) const {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = indices_.find(id);
    if (it != indices_.end()) return it->second;
  }
  const ModelEntry& e = library_->model(id);
  auto m = std::make_shared<ModelIndex>();
  m->id = id;
  m->info = e.info;
  const std::string cache = config_.model_cache_dir.empty() ? std::string() : cacheFile(e, id);
  if (!cache.empty() && loadIndex(cache, e, *m)) {
    // stored: everything but the search trees and the ray caster, rebuilt here
    if (!m->fpfh_valid.empty()) {
      std::vector<Fpfh> valid;
      for (int i : m->fpfh_valid) valid.push_back(m->fpfh[static_cast<size_t>(i)]);
      m->fpfh_tree.setInputCloud(toPclFpfh(valid));
    }
    m->fine_tree.setInputCloud(toXyz(m->fine->points));
    if (m->has_mesh) m->caster.addMesh(e.mesh, Eigen::Isometry3d::Identity());
    m->caster.commit();
    if (m->has_mesh) m->patches = facePatches(e.mesh, m->faces, patchMinArea(config_));
    addRests(*m);
    addLearned(*m);
    std::lock_guard<std::mutex> lock(mutex_);
    return indices_.emplace(id, m).first->second;
  }
  m->fine = library_->cloud(id, config_.icp_spacing);
  {
    // Descriptors see the model as a scan sees it: PCA normals over normal_radius (not the
    // mesh's sharp face normals), turned outwards; computed on the coarse cloud like the scene's.
    auto coarse = std::make_shared<ScanCloud>(*library_->cloud(id, config_.voxel));
    auto pts = toXyz(coarse->points);
    pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
    ne.setInputCloud(pts);
    ne.setSearchSurface(toXyz(m->fine->points));
    ne.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
    ne.setRadiusSearch(config_.normal_radius);
    pcl::PointCloud<pcl::Normal> normals;
    ne.compute(normals);
    for (size_t i = 0; i < coarse->size(); ++i) {
      Vec3 n = normals[i].getNormalVector3fMap();
      if (!n.allFinite() || n.norm() < 0.5f) continue;
      n.normalize();
      coarse->normals[i] = n.dot(coarse->normals[i]) < 0 ? -n : n;
    }
    m->coarse = coarse;
  }
  if (config_.coarse == "ppf") {
    m->ppf_cloud = thinned(*m->coarse, config_.ppf_sampling);
    m->ppf = buildPpf(m->ppf_cloud, static_cast<float>(config_.ppf_distance_step), config_.ppf_angle_bins,
                      static_cast<size_t>(config_.ppf_max_bucket));
  } else if (config_.descriptor == "learned") {
    addLearned(*m);
  } else {
    m->fpfh = computeFpfh(*m->coarse, config_.feature_radius);
    std::vector<Fpfh> valid;
    for (size_t i = 0; i < m->fpfh.size(); ++i) {
      if (!validFpfh(m->fpfh[i])) continue;
      m->fpfh_valid.push_back(static_cast<int>(i));
      valid.push_back(m->fpfh[i]);
    }
    if (!valid.empty()) m->fpfh_tree.setInputCloud(toPclFpfh(valid));
  }
  m->fine_tree.setInputCloud(toXyz(m->fine->points));
  // the surface centroid: exact from the mesh (a mean of the random fine samples is off by
  // ~R/sqrt(3N), 0.08 mm on the 25 mm sphere, which turns into pose error wherever a symmetry
  // leaves the rotation free); the mean of the points for a cloud model
  if (!e.mesh.faces.empty() && e.mesh.area() > 0) {
    m->centroid = e.mesh.surfaceCentroid();
  } else {
    for (const auto& p : m->fine->points) m->centroid += p.cast<double>();
    if (!m->fine->points.empty()) m->centroid /= static_cast<double>(m->fine->size());
  }
  m->diameter = e.bounds.diagonal().norm();
  if (!e.mesh.faces.empty()) {
    for (const auto& v : e.mesh.vertices) m->extremes.push_back(v.cast<float>());
  } else {
    m->extremes = m->coarse->points;
  }
  // distance field: cells of ≈ 1/3 of the coarse inlier distance (at most 4 M cells); each
  // fine point claims the cells within the margin whose centre it is nearest to
  const float margin = static_cast<float>(std::max(2 * config_.inlier_distance, 6 * config_.icp_spacing));
  const Eigen::Vector3f lo = e.bounds.min() - Vec3::Constant(margin), hi = e.bounds.max() + Vec3::Constant(margin);
  const Eigen::Vector3f size = hi - lo;
  float cell = static_cast<float>(std::max(config_.icp_spacing, config_.inlier_distance / 3));
  cell = std::max(cell, std::cbrt(size.prod() / 4e6f));
  m->field.origin = lo;
  m->field.cell = cell;
  m->field.dims = (size / cell).array().ceil().cast<int>().max(1);
  const Eigen::Vector3i D = m->field.dims;
  m->field.nearest.assign(static_cast<size_t>(D.x()) * D.y() * D.z(), -1);
  std::vector<float> best(m->field.nearest.size(), margin * margin);
  const int r = static_cast<int>(std::ceil(margin / cell));
  for (size_t j = 0; j < m->fine->size(); ++j) {
    const Vec3& p = m->fine->points[j];
    const Eigen::Vector3i c = ((p - lo) / cell).array().floor().cast<int>();
    for (int z = std::max(0, c.z() - r); z <= std::min(D.z() - 1, c.z() + r); ++z) {
      for (int y = std::max(0, c.y() - r); y <= std::min(D.y() - 1, c.y() + r); ++y) {
        for (int x = std::max(0, c.x() - r); x <= std::min(D.x() - 1, c.x() + r); ++x) {
          const size_t k = (static_cast<size_t>(z) * D.y() + y) * D.x() + x;
          const float d2 = (lo + cell * Vec3(x + 0.5f, y + 0.5f, z + 0.5f) - p).squaredNorm();
          if (d2 < best[k]) {
            best[k] = d2;
            m->field.nearest[k] = static_cast<int32_t>(j);
          }
        }
      }
    }
  }
  m->has_mesh = !e.mesh.faces.empty();
  if (m->has_mesh) m->caster.addMesh(e.mesh, Eigen::Isometry3d::Identity());
  m->caster.commit();
  if (m->has_mesh) m->faces = planarFaces(e.mesh);
  if (m->has_mesh) m->patches = facePatches(e.mesh, m->faces, patchMinArea(config_));
  addRests(*m);
  if (m->has_mesh && config_.icp_mesh_polish && config_.closest_point_grid && e.mesh.faces.size() <= 5000) {
    const float dmin = static_cast<float>(std::max(3 * config_.icp_spacing, 0.5 * config_.fitness_radius));
    const float cell = static_cast<float>(std::max(2 * config_.icp_spacing, 0.001));
    // margin: the polish's smallest correspondence distance and a cell (farther points are
    // rare in the polish: the RayCaster answers them)
    m->closest = ClosestPointGrid(e.mesh, cell, dmin + cell);
  }
  if (!cache.empty()) {
    try {
      saveIndex(cache, *m);
    } catch (const std::exception&) {
      // an unwritable cache costs time on the next start, nothing else
    }
  }
  std::lock_guard<std::mutex> lock(mutex_);
  return indices_.emplace(id, m).first->second;
}

void ModelMatcher::prepare(const std::vector<std::string>& models_in) const {
  const std::vector<std::string> models = models_in.empty() ? library_->ids() : models_in;
  for (const auto& id : models) library_->model(id);
  for (const auto& id : models) index(id);
}

Eigen::Vector3d ModelMatcher::centroid(const std::string& model) const { return index(model)->centroid; }

namespace {

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

}  // namespace

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
  SupportSeen seen;
  // the see-through test reads where the table was seen; the unseen test, where the table is
  if (support_plane && support_points && (cfg.max_see_through < 1 || cfg.max_unseen < 1))
    seen = buildSupportSeen(*support_points, *support_plane, static_cast<float>(cfg.voxel));
  std::vector<PartDetection> out;
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
  std::vector<Vec3> scan = pieces;                 // every cluster's points and the fragments near them
  std::vector<int> scan_cluster(pieces.size(), -1);  // ... their cluster (-1: a fragment)
  for (const auto& w : round) {
    scan.insert(scan.end(), w.points.begin(), w.points.end());
    scan_cluster.insert(scan_cluster.end(), w.points.size(), w.cluster);
  }
  PointGrid whole;
  if (cfg.fitness_whole_scan && !round.empty() && (round.size() > 1 || !pieces.empty()))
    whole = PointGrid(scan, static_cast<float>(cfg.fitness_radius));
  // a round searches what is left of each cluster; a second look takes a round but finds no
  // more parts than max_instances, so the rounds are bounded by twice that
  for (int instance = 0; instance < 2 * std::max(1, cfg.max_instances) && !round.empty(); ++instance) {
    parallelFor(round.size(), cfg.threads, [&](size_t i) {
      const auto t = Clock::now();
      round[i].scene = prepareScene(round[i].points, cfg);
      round[i].scene->support_seen = &seen;
      if (light && cfg.check_illumination && !light->empty()) round[i].scene->light = light;
      if (whole.size() > 0) round[i].scene->whole = &whole;
      if (learned_ && cfg.descriptor == "learned" && round[i].scene->coarse.size() >= 3) {
        const auto td = Clock::now();
        SceneData& sd = *round[i].scene;
        try {
          sd.learned = learned_->compute(sd.coarse.points, sd.coarse.normals, cfg.learned_scale);
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
      const ModelIndex& mi = *idx[best_m];
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
    round = std::move(next);
  }
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
