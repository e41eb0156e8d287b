// Laser-line extraction from one camera frame (thesis §1): one sub-pixel line centre per image
// column (or row), with the thesis's run-centre estimator and two better ones, a histogram-based
// dynamic threshold, rejection of secondary peaks (reflections) and optional polynomial smoothing.
#pragma once
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace cellsight {

struct LineExtractionConfig {
  enum class Estimator {
    kRunCentre,  ///< thesis: middle of the above-threshold run (edges interpolated)
    kCentroid,   ///< centre of gravity of (I - background) over the run ± margin
    kGaussian3,  ///< 3-point Gaussian fit (log-parabola) around the peak pixel
  };
  Estimator estimator = Estimator::kCentroid;
  /// true: the line runs along image rows, one centre per column (searched along v);
  /// false: the line runs along columns, one centre per row.
  bool line_along_rows = true;
  int channel = -1;                    ///< for colour images: channel index (RGB order); -1: mono
  double background_percentile = 0.9;  ///< background grey level: this histogram quantile
  double min_contrast = 25;            ///< peak must exceed background by this many grey levels
  double threshold_fraction = 0.5;     ///< run threshold = bg + fraction · (peak − bg)
  int centroid_margin = 2;             ///< px added on each side of the run for the centroid
  /// Centroid weights are I − (bg + floor · (peak − bg)), clipped at 0: a floor above the
  /// background keeps noise in the tails out of the centre.
  double centroid_floor = 0.1;
  int max_run = 40;                    ///< wider above-threshold runs are not a laser line
  /// A second peak ≥ ratio · main peak (measured above background) at ≥ gap px from the main
  /// run makes the column ambiguous (a reflection): it is dropped. 0 disables the check.
  double secondary_peak_ratio = 0.6;
  int secondary_peak_gap = 4;
  /// Edge (veil) points: the polyline is cut into segments where neighbouring columns are
  /// missing or the centre jumps by more than `segment_max_jump` px; `segment_erode` points are
  /// dropped at each segment end (mixed pixels at depth edges and at the ends of the fan) and
  /// segments shorter than `min_segment` are dropped. segment_erode = 0 disables.
  double segment_max_jump = 1.0;
  int segment_erode = 2;
  int min_segment = 5;
  /// Local polynomial (Savitzky–Golay) smoothing of the centre polyline: degree 0 disables.
  int smoothing_degree = 2;
  int smoothing_half_window = 7;       ///< columns on each side
  double smoothing_max_jump = 1.5;     ///< px; a larger step between neighbours breaks a segment

  static Estimator parseEstimator(const std::string& name);  ///< run_centre|centroid|gaussian3
};

struct LinePoint {
  float u = 0, v = 0;  ///< sub-pixel image coordinates of the line centre
  float peak = 0;      ///< peak grey level above background
  float width = 0;     ///< above-threshold run length, px
};

struct LineExtractionStats {
  int scanned = 0;      ///< columns (or rows) searched
  int found = 0;
  int no_line = 0;      ///< peak below background + min_contrast
  int ambiguous = 0;    ///< secondary peak (reflection)
  int too_wide = 0;
  int edge = 0;         ///< dropped at segment ends or in short segments
  int saturated = 0;    ///< found, with the peak at 255
  double background = 0;
};

/// Extracts the laser line from a CV_8UC1 or CV_8UC3 image. Throws std::invalid_argument for
/// another type or a channel that does not exist.
std::vector<LinePoint> extractLine(const cv::Mat& image, const LineExtractionConfig& config,
                                   LineExtractionStats* stats = nullptr);

}  // namespace cellsight
