// Internal to cellsight_scanner: the orientation-free ridge detector behind extractLine's
// default estimator, and the helpers it shares with the column methods.
#pragma once
#include <opencv2/core.hpp>
#include <vector>

#include "cellsight/scanner/line_extraction.hpp"

namespace cellsight::detail {

/// Grey level at the given histogram quantile, from every 8th row of a CV_8UC1 image.
double backgroundLevel(const cv::Mat& mono, double percentile);

/// Ridge centres of a CV_8UC1 image (background already in st.background), linked, filtered,
/// eroded at segment ends and smoothed along each polyline.
std::vector<LinePoint> extractRidge(const cv::Mat& mono, const LineExtractionConfig& c, LineExtractionStats& st);

}  // namespace cellsight::detail
