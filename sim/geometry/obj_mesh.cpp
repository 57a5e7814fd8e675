#include "sim/geometry/obj_mesh.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string_view>
#include <system_error>
#include <vector>

namespace stokes::sim {
inline namespace geometry {
namespace {

constexpr std::uint64_t kMinRecordBytes = 8;  // "v 0 0 0\n" and "f 1 2 3\n" are the shortest records
constexpr std::uint64_t kMaxIndexable = std::numeric_limits<std::uint32_t>::max();
constexpr std::size_t kMaxVertexNumbers = 7;  // x y z, then w or r g b (and one spare)

bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

/// A byte that never appears in a text OBJ file (control characters other than whitespace).
bool isBinaryByte(unsigned char c) {
  return (c < 0x20 && !isSpace(static_cast<char>(c))) || c == 0x7f;
}

std::string quoted(std::string_view s) {
  constexpr std::size_t kShown = 40;
  std::string out = "'";
  for (char c : s.substr(0, kShown)) out += (static_cast<unsigned char>(c) < 0x20 ? '?' : c);
  if (s.size() > kShown) out += "...";
  return out + "'";
}

/// Splits a line into whitespace-separated tokens (views into the line).
void tokenize(std::string_view line, std::vector<std::string_view>& tokens) {
  tokens.clear();
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && isSpace(line[i])) ++i;
    const std::size_t start = i;
    while (i < line.size() && !isSpace(line[i])) ++i;
    if (i > start) tokens.push_back(line.substr(start, i - start));
  }
}

/// "vertices:" -> "vertices", lower case, trailing punctuation removed.
std::string normalizedWord(std::string_view t) {
  std::string w;
  for (char c : t)
    if (c != ':' && c != ',' && c != ';') w += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return w;
}

enum class ParseStatus { Ok, Malformed, OutOfRange };

ParseStatus parseUnsigned(std::string_view t, std::uint64_t& out) {
  if (t.empty()) return ParseStatus::Malformed;
  const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), out);
  if (ec == std::errc::result_out_of_range) return ParseStatus::OutOfRange;
  if (ec != std::errc() || ptr != t.data() + t.size()) return ParseStatus::Malformed;
  return ParseStatus::Ok;
}

ParseStatus parseSigned(std::string_view t, std::int64_t& out) {
  if (t.size() > 1 && t[0] == '+') t.remove_prefix(1);
  if (t.empty()) return ParseStatus::Malformed;
  const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), out);
  if (ec == std::errc::result_out_of_range) return ParseStatus::OutOfRange;
  if (ec != std::errc() || ptr != t.data() + t.size()) return ParseStatus::Malformed;
  return ParseStatus::Ok;
}

/// Parses a decimal floating-point token. Underflow (1e-400) reads as 0; overflow is OutOfRange.
ParseStatus parseDouble(std::string_view t, double& out) {
  if (t.size() > 1 && t[0] == '+' && t[1] != '-' && t[1] != '+') t.remove_prefix(1);
  if (t.empty()) return ParseStatus::Malformed;
  const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), out, std::chars_format::general);
  if (ptr != t.data() + t.size() && ec != std::errc::result_out_of_range) return ParseStatus::Malformed;
  if (ec == std::errc::result_out_of_range) {
    if (ptr != t.data() + t.size()) return ParseStatus::Malformed;
    const std::string copy(t);  // strtod tells underflow (tiny result) from overflow (HUGE_VAL)
    errno = 0;
    const double v = std::strtod(copy.c_str(), nullptr);
    if (std::abs(v) >= 1.0) return ParseStatus::OutOfRange;
    out = 0.0;
    return ParseStatus::Ok;
  }
  if (ec != std::errc()) return ParseStatus::Malformed;
  return ParseStatus::Ok;
}

class ObjParser {
 public:
  ObjParser(std::istream& in, const std::string& source, const ObjLimits& limits, std::uint64_t sizeHint)
      : in_(in), source_(source), limits_(limits), sizeHint_(sizeHint) {
    maxVertices_ = std::min(limits.maxVertices, kMaxIndexable);
  }

  TriangleMesh run() {
    if (!in_.good() || in_.rdbuf() == nullptr) failFile("cannot read the stream");
    while (readLine()) parseLine();
    if (in_.bad()) fail("read error");
    finish();
    return std::move(mesh_);
  }

 private:
  [[noreturn]] void fail(const std::string& what) const {
    throw MeshError(source_ + ": line " + std::to_string(lineNo_) + ": " + what);
  }
  [[noreturn]] void failFile(const std::string& what) const { throw MeshError(source_ + ": " + what); }

  /// Reads one record (without its '\n') into line_; false at the end of the stream. Enforces the
  /// line and file size limits and rejects binary data.
  bool readLine() {
    line_.clear();
    std::streambuf* sb = in_.rdbuf();
    int c = sb->sbumpc();
    if (c == std::char_traits<char>::eof()) {
      in_.setstate(std::ios::eofbit);
      return false;
    }
    ++lineNo_;
    while (c != std::char_traits<char>::eof() && c != '\n') {
      if (++bytesRead_ > limits_.maxFileBytes)
        fail("the input is longer than " + std::to_string(limits_.maxFileBytes) +
             " bytes (ObjLimits::maxFileBytes)");
      if (line_.size() >= limits_.maxLineBytes)
        fail("line longer than " + std::to_string(limits_.maxLineBytes) + " bytes (ObjLimits::maxLineBytes)");
      const auto byte = static_cast<unsigned char>(c);
      if (isBinaryByte(byte)) {
        char hex[8];
        std::snprintf(hex, sizeof hex, "0x%02x", byte);
        fail(std::string("control byte ") + hex + " at column " + std::to_string(line_.size() + 1) +
             ": this is not a text OBJ file");
      }
      line_.push_back(static_cast<char>(c));
      c = sb->sbumpc();
    }
    ++bytesRead_;  // the newline
    return true;
  }

  void parseLine() {
    tokenize(line_, tokens_);
    if (tokens_.empty()) return;
    const std::string_view kind = tokens_[0];
    if (kind == "v") parseVertex();
    else if (kind == "f") parseFace();
    else if (kind[0] == '#') parseHeaderHint();
    // every other record is ignored
  }

  void parseVertex() {
    const std::size_t numbers = tokens_.size() - 1;
    if (numbers < 3 || numbers > kMaxVertexNumbers)
      fail("vertex record needs 3 coordinates (optionally followed by w or r g b), got " +
           std::to_string(numbers) + " numbers");
    if (mesh_.points.size() >= maxVertices_)
      fail("more than " + std::to_string(maxVertices_) + " vertices (ObjLimits::maxVertices)");
    openvdb::Vec3s p;
    for (std::size_t i = 1; i <= numbers; ++i) {
      const double x = coordinate(tokens_[i], i);
      if (i <= 3) p[static_cast<int>(i - 1)] = static_cast<float>(x);
    }
    mesh_.points.push_back(p);
  }

  double coordinate(std::string_view t, std::size_t position) const {
    double x = 0.0;
    switch (parseDouble(t, x)) {
      case ParseStatus::Malformed: fail("malformed number " + quoted(t) + " in vertex field " + std::to_string(position));
      case ParseStatus::OutOfRange: fail("number " + quoted(t) + " is out of the range of a double");
      case ParseStatus::Ok: break;
    }
    if (!std::isfinite(x)) fail("vertex coordinate " + quoted(t) + " is NaN or infinite");
    if (std::abs(x) > std::numeric_limits<float>::max())
      fail("vertex coordinate " + quoted(t) + " does not fit in single precision");
    return x;
  }

  void parseFace() {
    const std::size_t corners = tokens_.size() - 1;
    if (corners < 3) fail("face with " + std::to_string(corners) + " vertices (at least 3 needed)");
    const std::uint64_t added = corners - 2;
    if (mesh_.triangles.size() + added > limits_.maxTriangles)
      fail("more than " + std::to_string(limits_.maxTriangles) + " triangles (ObjLimits::maxTriangles)");
    const std::uint32_t first = cornerIndex(tokens_[1]);
    std::uint32_t previous = cornerIndex(tokens_[2]);
    for (std::size_t i = 3; i <= corners; ++i) {
      const std::uint32_t current = cornerIndex(tokens_[i]);
      mesh_.triangles.emplace_back(first, previous, current);
      previous = current;
    }
  }

  /// "v", "v/vt", "v//vn" or "v/vt/vn" -> 0-based vertex index, checked against the vertices so far.
  std::uint32_t cornerIndex(std::string_view corner) const {
    std::array<std::string_view, 3> parts{};
    std::size_t count = 0;
    for (std::size_t start = 0;;) {
      const std::size_t slash = corner.find('/', start);
      if (count == parts.size()) fail("face corner " + quoted(corner) + " has more than 3 '/'-separated fields");
      parts[count++] = corner.substr(start, slash == std::string_view::npos ? slash : slash - start);
      if (slash == std::string_view::npos) break;
      start = slash + 1;
    }
    for (std::size_t i = 1; i < count; ++i) {
      std::int64_t ignored = 0;
      if (!parts[i].empty() && parseSigned(parts[i], ignored) == ParseStatus::Malformed)
        fail("malformed index " + quoted(parts[i]) + " in face corner " + quoted(corner));
    }
    std::int64_t index = 0;
    const ParseStatus status = parseSigned(parts[0], index);
    const std::uint64_t defined = mesh_.points.size();
    if (status == ParseStatus::Malformed) fail("malformed vertex index " + quoted(parts[0]) + " in face");
    if (status == ParseStatus::OutOfRange)
      fail("vertex index " + quoted(parts[0]) + " out of range (" + std::to_string(defined) + " vertices defined so far)");
    if (index == 0) fail("vertex index 0 in face (OBJ indices start at 1; negative ones count back from the last vertex)");
    const std::int64_t zeroBased = index > 0 ? index - 1 : static_cast<std::int64_t>(defined) + index;
    if (zeroBased < 0 || static_cast<std::uint64_t>(zeroBased) >= defined)
      fail("vertex index " + std::to_string(index) + " out of range (" + std::to_string(defined) +
           " vertices defined so far)");
    return static_cast<std::uint32_t>(zeroBased);
  }

  /// Header comments such as "# Vertices: 49990" or "# 5000 faces": a declared count above the
  /// limits is an error; otherwise it only reserves memory, clamped by the size of the file.
  void parseHeaderHint() {
    for (std::size_t i = 0; i < tokens_.size(); ++i) {
      const std::string word = normalizedWord(tokens_[i]);
      const bool vertices = word == "vertices" || word == "#vertices";
      const bool faces = word == "faces" || word == "#faces";
      if (!vertices && !faces) continue;
      const std::string_view before = i > 0 ? tokens_[i - 1] : std::string_view{};
      const std::string_view after = i + 1 < tokens_.size() ? tokens_[i + 1] : std::string_view{};
      std::uint64_t declared = 0;
      ParseStatus status = parseUnsigned(after, declared);
      if (status == ParseStatus::Malformed) status = parseUnsigned(before, declared);
      if (status == ParseStatus::Malformed) continue;
      if (vertices) declareCount(status, declared, maxVertices_, "vertices", "maxVertices", vertexHintSeen_, mesh_.points);
      else declareCount(status, declared, limits_.maxTriangles, "faces", "maxTriangles", faceHintSeen_, mesh_.triangles);
    }
  }

  template <class Vec>
  void declareCount(ParseStatus status, std::uint64_t declared, std::uint64_t limit, const char* what,
                    const char* limitName, bool& seen, Vec& storage) {
    if (status == ParseStatus::OutOfRange || declared > limit)
      fail(std::string("the header declares ") + (status == ParseStatus::OutOfRange ? "an overflowing number of" : std::to_string(declared)) +
           " " + what + ", more than the limit of " + std::to_string(limit) + " (ObjLimits::" + limitName + ")");
    if (seen) return;
    seen = true;
    const std::uint64_t remaining = sizeHint_ > bytesRead_ ? sizeHint_ - bytesRead_ : 0;
    storage.reserve(static_cast<std::size_t>(std::min(declared, remaining / kMinRecordBytes)));
  }

  void finish() const {
    if (bytesRead_ == 0) throw MeshError(source_ + ": line 1: the file is empty");
    if (mesh_.points.empty()) fail("end of file reached without any vertex ('v') record");
    if (mesh_.triangles.empty()) fail("end of file reached without any face ('f') record");
  }

  std::istream& in_;
  const std::string& source_;
  const ObjLimits& limits_;
  std::uint64_t sizeHint_ = 0;  ///< bytes in the file (0 = unknown): caps reserve hints
  std::uint64_t maxVertices_ = 0;
  std::uint64_t lineNo_ = 0;
  std::uint64_t bytesRead_ = 0;
  bool vertexHintSeen_ = false, faceHintSeen_ = false;
  std::string line_;
  std::vector<std::string_view> tokens_;
  TriangleMesh mesh_;
};

}  // namespace

TriangleMesh readObj(std::istream& in, const std::string& sourceName, const ObjLimits& limits) {
  return ObjParser(in, sourceName, limits, 0).run();
}

TriangleMesh loadObj(const std::string& path, const ObjLimits& limits) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (ec || !fs::exists(status)) throw MeshError(path + ": cannot open the mesh file: no such file");
  if (!fs::is_regular_file(status)) throw MeshError(path + ": cannot open the mesh file: not a regular file");
  const std::uintmax_t size = fs::file_size(path, ec);
  if (ec) throw MeshError(path + ": cannot read the mesh file size: " + ec.message());
  if (size > limits.maxFileBytes)
    throw MeshError(path + ": the file has " + std::to_string(size) + " bytes, more than the limit of " +
                    std::to_string(limits.maxFileBytes) + " (ObjLimits::maxFileBytes)");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw MeshError(path + ": cannot open the mesh file: " + std::strerror(errno));
  return ObjParser(in, path, limits, size).run();
}

}  // namespace geometry
}  // namespace stokes::sim
