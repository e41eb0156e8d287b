// Reading images from disk within a size budget: the header's width and height are checked
// against kMaxImageSide / kMaxImagePixels before OpenCV decodes anything, so a file that claims
// 100000 x 100000 pixels costs an error naming it, not gigabytes or an abort.
#pragma once
#include <opencv2/core.hpp>
#include <string>

namespace cellsight {

/// Width and height from a PNG or JPEG header; false for other formats or a short header.
bool imageHeaderSize(const std::string& path, int* width, int* height);

/// cv::imread with the size budget (PNG and JPEG headers checked first; any format's decoded
/// size checked after). Throws std::runtime_error naming the file: unreadable, not an image,
/// or over the limit.
cv::Mat readImage(const std::string& path, int flags);

}  // namespace cellsight
