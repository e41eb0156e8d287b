// Laser-line extraction from one camera frame (thesis §1). Default: an orientation-free ridge
// detector in the manner of Steger (Hessian of the Gaussian-smoothed image; the centre where the
// first derivative across the line vanishes; the line's normal and width per point), linked into
// polylines that are filtered by strength, width and length and smoothed along their own
// direction. Beside it the column methods: one sub-pixel centre per image column (or row), with
// the thesis's run-centre estimator and two better ones, a histogram-based dynamic threshold,
// rejection of secondary peaks (reflections) and optional polynomial smoothing.
#pragma once
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace cellsight {

struct LineExtractionConfig {
  enum class Estimator {
    kRidge,      ///< orientation-free ridge centres (Steger), linked into polylines (default)
    kRunCentre,  ///< thesis: middle of the above-threshold run (edges interpolated)
    kCentroid,   ///< centre of gravity of (I - background) over the run ± margin
    kGaussian3,  ///< 3-point Gaussian fit (log-parabola) around the peak pixel
  };
  Estimator estimator = Estimator::kRidge;
  /// Column methods only (the ridge detector has no search direction): true: the line runs
  /// along image rows, one centre per column (searched along v); false: one centre per row.
  bool line_along_rows = true;
  /// Ridge: scale σ (px) of the Gaussian derivatives. Steger's rule: σ ≥ (half line width)/√3.
  double ridge_sigma = 1.5;
  /// Ridge sub-pixel step: true: Newton step on log(I − background) (exact for a Gaussian
  /// profile); false: Steger's step on I (biased by up to x³/(S² − x²) px off the pixel centre).
  bool ridge_gaussian_profile = true;
  /// Ridge: the second-largest Hessian eigenvalue must stay below this share of the largest
  /// (a line is curved across, flat along; a speckle blob is curved both ways).
  double ridge_max_isotropy = 0.5;
  /// Ridge linking: the next centre lies within this distance (px) ahead of the current one
  /// and turns by at most `link_max_angle` (rad).
  double link_max_gap = 2.5;
  double link_max_angle = 0.6;
  int channel = -1;                    ///< for colour images: channel index (RGB order); -1: mono
  double background_percentile = 0.9;  ///< background grey level: this histogram quantile
  double min_contrast = 25;            ///< peak must exceed background by this many grey levels
  double threshold_fraction = 0.5;     ///< run threshold = bg + fraction · (peak − bg)
  int centroid_margin = 2;             ///< px added on each side of the run for the centroid
  /// Centroid weights are I − (bg + floor · (peak − bg)), clipped at 0: a floor above the
  /// background keeps noise in the tails out of the centre.
  double centroid_floor = 0.1;
  int max_run = 40;                    ///< wider above-threshold runs (ridge: wider lines, FWHM px) are not a laser line
  /// A second peak ≥ ratio · main peak (measured above background) at ≥ gap px from the main
  /// run makes the column ambiguous (a reflection): it is dropped. 0 disables the check.
  double secondary_peak_ratio = 0.6;
  int secondary_peak_gap = 4;
  /// Edge (veil) points: the polyline is cut into segments where neighbouring columns are
  /// missing or the centre jumps by more than `segment_max_jump` px (column methods; the ridge
  /// detector cuts where linking finds no continuation); `segment_erode` points are dropped at
  /// each segment end (mixed pixels at depth edges and at the ends of the fan; the ridge drops
  /// ⌈ridge_sigma⌉ more, where its Gaussian reaches past the end) and segments shorter than
  /// `min_segment` points are dropped. segment_erode = 0 disables.
  double segment_max_jump = 1.0;
  int segment_erode = 2;
  int min_segment = 5;
  /// Local polynomial (Savitzky–Golay) smoothing of the centre polyline: degree 0 disables
  /// (the ridge fits at most a quadratic across the line; 3 acts as 2 there).
  int smoothing_degree = 2;
  int smoothing_half_window = 7;       ///< columns on each side
  double smoothing_max_jump = 1.5;     ///< px; a larger step between neighbours breaks a segment

  static Estimator parseEstimator(const std::string& name);  ///< ridge|run_centre|centroid|gaussian3
  static const char* estimatorName(Estimator e);
};

struct LinePoint {
  float u = 0, v = 0;  ///< sub-pixel image coordinates of the line centre
  float peak = 0;      ///< column methods: peak grey level above background; ridge: above its surroundings
  float width = 0;     ///< column methods: above-threshold run length; ridge: estimated FWHM, px
  float nx = 0, ny = 1;  ///< unit normal of the line at this point (across the line)
  int segment = 0;     ///< polyline (segment) index within the frame; points of one are in order
};

struct LineExtractionStats {
  int scanned = 0;      ///< columns (or rows) searched; ridge: candidate pixels examined
  int found = 0;
  int no_line = 0;      ///< peak below background + min_contrast
  int ambiguous = 0;    ///< secondary peak (reflection)
  int too_wide = 0;
  int edge = 0;         ///< dropped at segment ends or in short segments
  int saturated = 0;    ///< found, with the peak at 255
  int segments = 0;     ///< polylines kept
  int not_ridge = 0;    ///< ridge: candidates that are no line centre (blob, off-centre, dark)
  // (ridge: centres merged into another of the same pixel or cross-section are not counted, so
  // the counters do not add up to `scanned`)
  double background = 0;
};

/// Extracts the laser line from a CV_8UC1 or CV_8UC3 image. Throws std::invalid_argument for
/// another type or a channel that does not exist.
std::vector<LinePoint> extractLine(const cv::Mat& image, const LineExtractionConfig& config,
                                   LineExtractionStats* stats = nullptr);

}  // namespace cellsight
