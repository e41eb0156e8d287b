#include "cellsight/common/file_io.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <stdexcept>

namespace cellsight {

namespace {

/// `<path>.tmp.<pid>.<random>` files whose writer is gone (killed between create and rename) are
/// removed: an interrupted write leaves no leftovers after the next write of the same file.
void removeStaleTemporaries(const std::string& path) {
  namespace fs = std::filesystem;
  const fs::path target(path);
  const std::string prefix = target.filename().string() + ".tmp.";
  std::error_code ec;
  const fs::path dir = target.has_parent_path() ? target.parent_path() : fs::path(".");
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.rfind(prefix, 0) != 0) continue;
    const std::string rest = name.substr(prefix.size());
    const std::string pid_text = rest.substr(0, rest.find('.'));
    if (pid_text.empty() || pid_text.find_first_not_of("0123456789") != std::string::npos) continue;
    const long pid = std::strtol(pid_text.c_str(), nullptr, 10);
    if (pid == ::getpid()) continue;
    if (pid > 0 && ::kill(static_cast<pid_t>(pid), 0) == 0) continue;  // its writer still runs
    if (pid > 0 && errno == EPERM) continue;                           // alive, another user's
    fs::remove(it->path(), ec);
  }
}

}  // namespace

void writeFileAtomic(const std::string& path, const std::string& content) {
  // a new file of a name no one can guess, in the target's folder (mkstemp: O_CREAT | O_EXCL, so
  // a file or symlink planted there is never opened or followed)
  std::string tmp = path + ".tmp." + std::to_string(::getpid()) + ".XXXXXX";
  int fd = ::mkstemp(tmp.data());
  if (fd < 0) {
    throw std::runtime_error(path + ": cannot create temporary file " + tmp + ": " +
                             std::strerror(errno));
  }
  ::fchmod(fd, 0644);  // mkstemp makes it 0600; the file keeps the usual mode
  size_t done = 0;
  while (done < content.size()) {
    ssize_t n = ::write(fd, content.data() + done, content.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      const std::string err = std::strerror(errno);
      ::close(fd);
      ::unlink(tmp.c_str());
      throw std::runtime_error(path + ": write failed: " + err);
    }
    done += static_cast<size_t>(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    const std::string err = std::strerror(errno);
    ::unlink(tmp.c_str());
    throw std::runtime_error(path + ": flush failed: " + err);
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string err = std::strerror(errno);
    ::unlink(tmp.c_str());
    throw std::runtime_error(path + ": rename of the temporary file failed: " + err);
  }
  removeStaleTemporaries(path);
}

std::string parentDir(const std::string& path) {
  const auto pos = path.find_last_of('/');
  if (pos == std::string::npos) return ".";
  if (pos == 0) return "/";
  return path.substr(0, pos);
}

std::string resolveRelative(const std::string& base_file, const std::string& relative) {
  if (relative.empty() || relative[0] == '/') return relative;
  return parentDir(base_file) + "/" + relative;
}

void removeTree(const std::string& path) {
  // rm -r, best effort: links are removed, not followed; errors are ignored.
  std::error_code ec;
  std::filesystem::remove_all(path, ec);
}

void makeDirs(const std::string& path) {
  std::string partial;
  for (size_t i = 0; i <= path.size(); ++i) {
    if (i == path.size() || path[i] == '/') {
      if (!partial.empty() && ::mkdir(partial.c_str(), 0755) != 0 && errno != EEXIST) {
        throw std::runtime_error(partial + ": cannot create folder: " + std::strerror(errno));
      }
    }
    if (i < path.size()) partial += path[i];
  }
}

}  // namespace cellsight
