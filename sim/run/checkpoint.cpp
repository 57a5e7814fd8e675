// Checkpoints of a run: see checkpoint.h.
#include "sim/run/checkpoint.h"
#include "sim/output/atomic_file.h"


#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <type_traits>

namespace stokes::sim {
inline namespace run {

namespace fs = std::filesystem;

namespace {

constexpr char kMagic[] = "STOKESVDB-CKPT\n";
/// 2 added the tile history; version 1 files (no history) are still read.
constexpr std::uint32_t kVersion = 2;
constexpr std::uint32_t kOldestVersion = 1;

std::uint64_t fnv1a(const char* data, std::size_t n) {
  std::uint64_t h = 14695981039346656037ull;
  for (std::size_t i = 0; i < n; ++i) {
    h ^= std::uint8_t(data[i]);
    h *= 1099511628211ull;
  }
  return h;
}

/// Appends plain values and arrays of them to a byte buffer.
class Writer {
 public:
  template <class T>
  void put(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    const char* p = reinterpret_cast<const char*>(&v);
    bytes_.insert(bytes_.end(), p, p + sizeof(T));
  }
  template <class Container>
  void putArray(const Container& c) {
    using T = typename Container::value_type;
    static_assert(std::is_trivially_copyable_v<T>);
    put<std::uint64_t>(c.size());
    const char* p = reinterpret_cast<const char*>(c.data());
    bytes_.insert(bytes_.end(), p, p + c.size() * sizeof(T));
  }
  std::vector<char>& bytes() { return bytes_; }

 private:
  std::vector<char> bytes_;
};

/// Reads what Writer wrote; every read checks the bounds and names the file.
class Reader {
 public:
  Reader(const std::vector<char>& bytes, std::size_t end, std::string path)
      : bytes_(bytes), end_(end), path_(std::move(path)) {}
  template <class T>
  T get(const char* what) {
    T v;
    take(reinterpret_cast<char*>(&v), sizeof(T), what);
    return v;
  }
  template <class Container>
  void getArray(Container& c, const char* what) {
    using T = typename Container::value_type;
    const std::uint64_t n = get<std::uint64_t>(what);
    if (n > (end_ - pos_) / std::max<std::size_t>(sizeof(T), 1)) fail(what);
    c.resize(n);
    take(reinterpret_cast<char*>(c.data()), n * sizeof(T), what);
  }
  std::size_t position() const { return pos_; }

 private:
  void take(char* to, std::size_t n, const char* what) {
    if (n > end_ - pos_) fail(what);
    std::memcpy(to, bytes_.data() + pos_, n);
    pos_ += n;
  }
  [[noreturn]] void fail(const char* what) const {
    throw std::runtime_error("checkpoint '" + path_ + "' is truncated or corrupt: cannot read " + what + " at byte " +
                             std::to_string(pos_));
  }
  const std::vector<char>& bytes_;
  std::size_t end_, pos_ = 0;
  std::string path_;
};

/// The tile history as plain words (solver::TileHistory::State::decisionWords).
void putTileHistory(Writer& w, const solver::TileHistory::State& h) {
  w.putArray(h.decisionWords());
  w.putArray(h.tiles);
}

solver::TileHistory::State getTileHistory(Reader& r) {
  std::vector<std::int64_t> words;
  std::vector<std::uint64_t> tiles;
  r.getArray(words, "tile history decisions");
  r.getArray(tiles, "tile history tiles");
  try {
    return solver::TileHistory::State::fromWords(words, std::move(tiles));
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(e.what());
  }
}

void putState(Writer& w, const SimulatorState& s) {
  w.put(s.time);
  w.put(s.lastDt);
  w.put(s.volumeTarget);
  w.put(s.steps);
  w.put<std::int32_t>(s.frame);
  w.put<std::int32_t>(s.frameSubsteps);
  w.put(s.retryDtLimit);
  w.putArray(s.particles.x);
  w.putArray(s.particles.v);
  w.putArray(s.particles.c);
  w.put<std::uint8_t>(s.warm ? 1 : 0);
  if (s.warm) {
    w.put(s.warm->dx);
    w.put(s.warm->origin);
    w.putArray(s.warm->blockOrigins);
    w.putArray(s.warm->activeSlots);
    w.putArray(s.warm->solution);
  }
  w.put<std::uint8_t>(s.coil ? 1 : 0);
  if (s.coil) w.put(*s.coil);
  putTileHistory(w, s.tileHistory);
}

SimulatorState getState(Reader& r, std::uint32_t version) {
  SimulatorState s;
  s.time = r.get<double>("time");
  s.lastDt = r.get<double>("previous dt");
  s.volumeTarget = r.get<double>("volume target");
  s.steps = r.get<std::int64_t>("step count");
  s.frame = r.get<std::int32_t>("frame");
  s.frameSubsteps = r.get<std::int32_t>("substeps");
  s.retryDtLimit = r.get<double>("retry dt limit");
  r.getArray(s.particles.x, "particle positions");
  r.getArray(s.particles.v, "particle velocities");
  r.getArray(s.particles.c, "particle affine vectors");
  if (s.particles.v.size() != s.particles.x.size() || s.particles.c.size() != s.particles.x.size())
    throw std::runtime_error("particle arrays of different lengths");
  if (r.get<std::uint8_t>("warm start flag")) {
    WarmStartState w;
    w.dx = r.get<double>("warm start dx");
    w.origin = r.get<Vec3d>("warm start origin");
    r.getArray(w.blockOrigins, "warm start blocks");
    r.getArray(w.activeSlots, "warm start cells");
    r.getArray(w.solution, "warm start solution");
    s.warm = std::move(w);
  }
  if (r.get<std::uint8_t>("coil flag")) s.coil = r.get<CoilMeasure::State>("coil measure");
  if (version >= 2) s.tileHistory = getTileHistory(r);
  return s;
}

/// The checkpoint files of a folder, newest (highest step) first.
std::vector<fs::path> checkpointFiles(const std::string& outDir) {
  std::vector<fs::path> files;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(checkpointFolder(outDir), ec)) {
    const fs::path& p = entry.path();
    if (p.extension() == ".ckpt" && p.filename().string().rfind("step_", 0) == 0) files.push_back(p);
  }
  std::sort(files.begin(), files.end(), [](const fs::path& a, const fs::path& b) { return a.filename() > b.filename(); });
  return files;
}

}  // namespace

std::string checkpointFolder(const std::string& outDir) { return (fs::path(outDir) / "checkpoints").string(); }

std::string writeCheckpoint(const std::string& outDir, const RunCheckpoint& checkpoint, int keep) {
  const fs::path folder = checkpointFolder(outDir);
  std::error_code ec;
  fs::create_directories(folder, ec);
  if (ec) throw std::runtime_error("cannot create checkpoint folder '" + folder.string() + "': " + ec.message());
  char name[48];
  std::snprintf(name, sizeof name, "step_%09lld.ckpt", static_cast<long long>(checkpoint.state.steps));
  const std::string path = (folder / name).string();

  Writer w;
  w.bytes().insert(w.bytes().end(), kMagic, kMagic + sizeof kMagic - 1);
  w.put(kVersion);
  w.putArray(checkpoint.signature);
  w.put<std::int32_t>(checkpoint.progress.framesWritten);
  w.put(checkpoint.progress.initialVolume);
  w.put<std::int32_t>(checkpoint.progress.maxIterations);
  putState(w, checkpoint.state);
  w.put(fnv1a(w.bytes().data(), w.bytes().size()));
  writeBytesAtomically(path, "checkpoint", std::string_view(w.bytes().data(), w.bytes().size()));

  const std::vector<fs::path> files = checkpointFiles(outDir);
  for (std::size_t i = std::size_t(std::max(keep, 1)); i < files.size(); ++i) fs::remove(files[i], ec);
  return path;
}

RunCheckpoint readCheckpoint(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot open checkpoint '" + path + "'");
  const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::size_t magic = sizeof kMagic - 1;
  if (bytes.size() < magic + sizeof(std::uint32_t) + sizeof(std::uint64_t) ||
      std::memcmp(bytes.data(), kMagic, magic) != 0)
    throw std::runtime_error("'" + path + "' is not a StokesVDB checkpoint");
  const std::size_t end = bytes.size() - sizeof(std::uint64_t);
  std::uint64_t stored;
  std::memcpy(&stored, bytes.data() + end, sizeof stored);
  if (stored != fnv1a(bytes.data(), end))
    throw std::runtime_error("checkpoint '" + path + "' is corrupt (checksum mismatch; " + std::to_string(bytes.size()) +
                             " bytes)");
  std::vector<char> body(bytes.begin() + std::ptrdiff_t(magic), bytes.begin() + std::ptrdiff_t(end));
  Reader r(body, body.size(), path);
  const std::uint32_t version = r.get<std::uint32_t>("format version");
  if (version < kOldestVersion || version > kVersion)
    throw std::runtime_error("checkpoint '" + path + "' has format version " + std::to_string(version) +
                             "; this build reads versions " + std::to_string(kOldestVersion) + " to " +
                             std::to_string(kVersion));
  RunCheckpoint c;
  r.getArray(c.signature, "run signature");
  c.progress.framesWritten = r.get<std::int32_t>("frames written");
  c.progress.initialVolume = r.get<double>("initial volume");
  c.progress.maxIterations = r.get<std::int32_t>("most iterations");
  try {
    c.state = getState(r, version);
  } catch (const std::runtime_error& e) {
    throw std::runtime_error("checkpoint '" + path + "': " + e.what());
  }
  if (r.position() != body.size())
    throw std::runtime_error("checkpoint '" + path + "' has " + std::to_string(body.size() - r.position()) +
                             " unread bytes");
  return c;
}

std::optional<std::pair<std::string, RunCheckpoint>> findNewestCheckpoint(const std::string& outDir,
                                                                          std::vector<std::string>* notes) {
  for (const fs::path& file : checkpointFiles(outDir)) {
    try {
      return std::make_pair(file.string(), readCheckpoint(file.string()));
    } catch (const std::exception& e) {
      if (notes) notes->push_back(std::string("skipped: ") + e.what());
    }
  }
  return std::nullopt;
}

}  // namespace run
}  // namespace stokes::sim
