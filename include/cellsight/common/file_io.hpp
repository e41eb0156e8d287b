// Small file helpers shared by every writer: atomic replacement, paths.
#pragma once
#include <string>

namespace cellsight {

/// Writes `content` to `path` atomically: a temporary file in the same folder, flushed and
/// fsync'ed, then renamed over the target. On any failure the old file stays as it was and a
/// std::runtime_error names the path. Temporary files of earlier writes of the same path whose
/// process is gone (`<path>.tmp.<pid>`, left by a kill between create and rename) are removed.
void writeFileAtomic(const std::string& path, const std::string& content);

/// Directory part of a path ("." when there is none).
std::string parentDir(const std::string& path);

/// Resolves `relative` against the folder of `base_file` unless it is absolute.
std::string resolveRelative(const std::string& base_file, const std::string& relative);

/// rm -r (best effort): links are removed, not followed; errors are ignored.
void removeTree(const std::string& path);

/// mkdir -p; throws std::runtime_error naming the path on failure.
void makeDirs(const std::string& path);

}  // namespace cellsight
