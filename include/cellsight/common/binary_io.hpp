// Flat binary records for caches: plain values and vectors of plain values (Eigen fixed-size
// types included) appended to a string, read back with bounds checks. Native byte order; a
// cache file starts with its own magic and version, so a foreign file is refused, not misread.
#pragma once
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

namespace cellsight {

class BinaryWriter {
 public:
  template <typename T>
  void pod(const T& v) {
    bytes_.append(reinterpret_cast<const char*>(&v), sizeof(T));
  }
  template <typename T>
  void vec(const std::vector<T>& v) {
    pod<uint64_t>(v.size());
    if (!v.empty()) bytes_.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
  }
  void str(const std::string& s) {
    pod<uint64_t>(s.size());
    bytes_.append(s);
  }
  const std::string& bytes() const { return bytes_; }

 private:
  std::string bytes_;
};

class BinaryReader {
 public:
  explicit BinaryReader(const std::string& bytes) : bytes_(bytes) {}
  template <typename T>
  T pod() {
    T v;
    take(&v, sizeof(T));
    return v;
  }
  template <typename T>
  std::vector<T> vec() {
    const uint64_t n = pod<uint64_t>();
    if (n > (bytes_.size() - pos_) / (sizeof(T) ? sizeof(T) : 1)) throw std::runtime_error("binary record: truncated vector");
    std::vector<T> v(static_cast<size_t>(n));
    if (n) take(v.data(), static_cast<size_t>(n) * sizeof(T));
    return v;
  }
  std::string str() {
    const uint64_t n = pod<uint64_t>();
    if (n > bytes_.size() - pos_) throw std::runtime_error("binary record: truncated string");
    std::string s = bytes_.substr(pos_, static_cast<size_t>(n));
    pos_ += static_cast<size_t>(n);
    return s;
  }
  bool atEnd() const { return pos_ == bytes_.size(); }

 private:
  void take(void* out, size_t n) {
    if (n > bytes_.size() - pos_) throw std::runtime_error("binary record: truncated");
    std::memcpy(out, bytes_.data() + pos_, n);
    pos_ += n;
  }
  const std::string& bytes_;
  size_t pos_ = 0;
};

/// FNV-1a, 64 bit (cache keys; not a cryptographic hash).
inline uint64_t fnv1a64(const void* data, size_t n, uint64_t h = 1469598103934665603ull) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
  return h;
}

}  // namespace cellsight
