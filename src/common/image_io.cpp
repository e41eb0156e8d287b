#include "cellsight/common/image_io.hpp"

#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <stdexcept>
#include <vector>

#include "cellsight/common/camera_model.hpp"

namespace cellsight {

namespace {
uint32_t be32(const unsigned char* p) { return (uint32_t(p[0]) << 24) | (uint32_t(p[1]) << 16) | (uint32_t(p[2]) << 8) | p[3]; }
uint32_t be16(const unsigned char* p) { return (uint32_t(p[0]) << 8) | p[1]; }

std::string limitText() {
  return std::to_string(kMaxImageSide) + " px a side and " + std::to_string(kMaxImagePixels / 1000000) + " MP";
}
}  // namespace

bool imageHeaderSize(const std::string& path, int* width, int* height) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return false;
  std::vector<unsigned char> h(64 * 1024);
  f.read(reinterpret_cast<char*>(h.data()), static_cast<std::streamsize>(h.size()));
  const size_t n = static_cast<size_t>(f.gcount());
  static const unsigned char png[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (n >= 24 && std::equal(png, png + 8, h.begin()) && std::equal(h.begin() + 12, h.begin() + 16, "IHDR")) {
    *width = static_cast<int>(std::min<uint32_t>(be32(&h[16]), 0x7fffffff));
    *height = static_cast<int>(std::min<uint32_t>(be32(&h[20]), 0x7fffffff));
    return true;
  }
  if (n >= 4 && h[0] == 0xFF && h[1] == 0xD8) {  // JPEG: walk the segments to a start-of-frame
    size_t i = 2;
    while (i + 9 < n) {
      if (h[i] != 0xFF) return false;
      const unsigned char marker = h[i + 1];
      if (marker == 0xFF) {
        ++i;
        continue;
      }
      const bool sof = marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
      if (sof) {
        *height = static_cast<int>(be16(&h[i + 5]));
        *width = static_cast<int>(be16(&h[i + 7]));
        return true;
      }
      i += 2 + be16(&h[i + 2]);
    }
  }
  return false;
}

cv::Mat readImage(const std::string& path, int flags) {
  int w = 0, h = 0;
  if (imageHeaderSize(path, &w, &h) &&
      (w > kMaxImageSide || h > kMaxImageSide || static_cast<int64_t>(w) * h > kMaxImagePixels)) {
    throw std::runtime_error(path + ": the image claims " + std::to_string(w) + "x" + std::to_string(h) +
                             " pixels, over the limit of " + limitText());
  }
  cv::Mat img;
  try {
    img = cv::imread(path, flags);
  } catch (const cv::Exception& e) {
    throw std::runtime_error(path + ": cannot decode the image: " + e.what());
  }
  if (img.empty()) throw std::runtime_error(path + ": cannot read the image (missing, unreadable or not an image)");
  if (img.cols > kMaxImageSide || img.rows > kMaxImageSide || static_cast<int64_t>(img.cols) * img.rows > kMaxImagePixels)
    throw std::runtime_error(path + ": " + std::to_string(img.cols) + "x" + std::to_string(img.rows) +
                             " pixels, over the limit of " + limitText());
  return img;
}

}  // namespace cellsight
