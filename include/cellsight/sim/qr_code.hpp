// QR code generation (libqrencode) for the simulated fixtures.
#pragma once
#include <string>
#include <vector>

namespace cellsight {

/// A square module matrix: modules[row * size + col] is true for a dark module.
struct QrMatrix {
  int size = 0;
  std::vector<bool> modules;
  bool dark(int row, int col) const { return modules[static_cast<size_t>(row * size + col)]; }
};

/// Encodes `text` (8-bit mode, error correction level M). Throws std::runtime_error on failure.
QrMatrix encodeQr(const std::string& text);

}  // namespace cellsight
