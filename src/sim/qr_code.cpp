#include "cellsight/sim/qr_code.hpp"

#include <qrencode.h>

#include <stdexcept>

namespace cellsight {

QrMatrix encodeQr(const std::string& text) {
  QRcode* code = QRcode_encodeString8bit(text.c_str(), 0, QR_ECLEVEL_M);
  if (!code) throw std::runtime_error("QR encoding failed for payload '" + text + "'");
  QrMatrix m;
  m.size = code->width;
  m.modules.resize(static_cast<size_t>(m.size * m.size));
  for (int i = 0; i < m.size * m.size; ++i) m.modules[static_cast<size_t>(i)] = code->data[i] & 1;
  QRcode_free(code);
  return m;
}

}  // namespace cellsight
