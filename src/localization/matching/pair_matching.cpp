// One (cluster, model) pair from coarse hypotheses to a validated pose (screened, polished,
// centred in its slack, laid into a rest), the pose turned about the support's normal, and a
// found pose polished again on other points.
#include <algorithm>
#include <array>
#include <cmath>
#include <exception>
#include <vector>

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

}  // namespace

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

namespace {

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

/// ICP from T0 (polished with exact neighbours when `polish`), scored into *c (a copy of `d`
/// with the pose and its figures); a polished pose good enough to report goes to the middle of
/// its slack, kept if it still is. False when the ICP diverged or the pose is off the support.
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

}  // namespace

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

/// One (cluster, model) pair: the coarse stage's hypotheses, each refined on a thinned scene and
/// scored, the best polished on all the ICP points (an accepted pose beats a refused one).
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

}  // namespace matching_detail
}  // namespace cellsight
