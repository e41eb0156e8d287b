// Helpers shared by the libFuzzer targets: an input written to a file of a chosen name (the
// loaders under test take paths), in a private folder removed at exit.
#pragma once
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <string>

namespace cellsight_fuzz {

/// The process's private folder (created on first use, removed at exit).
inline const std::string& scratchDir() {
  static const std::string dir = [] {
    const char* base = std::getenv("TMPDIR");
    std::string tmpl = std::string(base && *base ? base : "/tmp") + "/cellsight_fuzz_XXXXXX";
    if (!mkdtemp(tmpl.data())) throw std::runtime_error("fuzz: cannot create a scratch folder");
    static const std::string keep = tmpl;
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(keep, ec);
    });
    return tmpl;
  }();
  return dir;
}

/// Writes `size` bytes to <scratch>/<name> and returns the path.
inline std::string writeInput(const uint8_t* data, size_t size, const std::string& name) {
  const std::string path = scratchDir() + "/" + name;
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) throw std::runtime_error("fuzz: cannot write " + path);
  if (size > 0 && std::fwrite(data, 1, size, f) != size) {
    std::fclose(f);
    throw std::runtime_error("fuzz: short write to " + path);
  }
  std::fclose(f);
  return path;
}

}  // namespace cellsight_fuzz
