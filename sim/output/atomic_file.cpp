#include "sim/output/atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <stdexcept>

namespace stokes::sim {
inline namespace output {

namespace {

namespace fs = std::filesystem;

/// fsync of `path` (a file, or a folder with O_DIRECTORY); returns errno, 0 on success.
int syncPath(const std::string& path, int flags) {
  const int fd = ::open(path.c_str(), flags | O_CLOEXEC);
  if (fd < 0) return errno;
  const int rc = ::fsync(fd) == 0 ? 0 : errno;
  ::close(fd);
  return rc;
}

}  // namespace

void writeFileAtomically(const std::string& path, const std::string& what,
                         const std::function<void(const std::string& tmp)>& fill) {
  const std::string tmp = path + ".tmp";
  auto fail = [&](const std::string& cause) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw std::runtime_error(what + ": cannot write '" + path + "': " + cause);
  };
  try {
    fill(tmp);
  } catch (const std::exception& e) {
    fail(e.what());
  }
  if (const int err = syncPath(tmp, O_RDONLY)) fail(std::string("fsync: ") + std::strerror(err));
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) fail("rename: " + ec.message());
  // the rename itself is durable once the folder is synced (best effort: some file systems refuse)
  const fs::path folder = fs::path(path).parent_path();
  syncPath(folder.empty() ? "." : folder.string(), O_RDONLY | O_DIRECTORY);
}

void writeBytesAtomically(const std::string& path, const std::string& what, std::string_view bytes) {
  writeFileAtomically(path, what, [&](const std::string& tmp) {
    const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd < 0) throw std::runtime_error(std::string("open: ") + std::strerror(errno));
    std::size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        const int err = n < 0 ? errno : ENOSPC;
        ::close(fd);
        throw std::runtime_error(std::string("write: ") + std::strerror(err));
      }
      done += std::size_t(n);
    }
    if (::close(fd) != 0) throw std::runtime_error(std::string("close: ") + std::strerror(errno));
  });
}

}  // namespace output
}  // namespace stokes::sim
