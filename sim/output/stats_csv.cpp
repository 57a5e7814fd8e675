#include "sim/output/stats_csv.h"

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <stdexcept>

#include "sim/output/atomic_file.h"

namespace stokes::sim {
inline namespace output {

namespace {

/// RFC 4180 quoting for header names that contain a comma, quote or newline.
std::string csvField(const std::string& s) {
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

std::string formatNumber(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

}  // namespace

namespace {

std::string csvHeader(const std::vector<std::string>& columns) {
  std::string header;
  for (std::size_t c = 0; c < columns.size(); ++c) {
    if (c) header += ',';
    header += csvField(columns[c]);
  }
  return header;
}

/// The fields of a CSV line (RFC 4180 quoting undone).
std::vector<std::string> csvFields(const std::string& line) {
  std::vector<std::string> fields(1);
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted) {
      if (c == '"' && i + 1 < line.size() && line[i + 1] == '"') fields.back() += line[++i];
      else if (c == '"') quoted = false;
      else fields.back() += c;
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      fields.emplace_back();
    } else {
      fields.back() += c;
    }
  }
  return fields;
}

}  // namespace

void StatsCsv::checkColumns() const {
  if (columns_.empty()) throw std::invalid_argument("StatsCsv: no columns for '" + path_ + "'");
  for (std::size_t c = 0; c < columns_.size(); ++c)
    if (std::find(columns_.begin(), columns_.begin() + c, columns_[c]) != columns_.begin() + c)
      throw std::invalid_argument("StatsCsv: duplicate column '" + columns_[c] + "' for '" + path_ + "'");
}

StatsCsv::StatsCsv(const std::string& path, std::vector<std::string> columns)
    : path_(path), columns_(std::move(columns)) {
  checkColumns();
  file_ = std::fopen(path_.c_str(), "w");
  if (!file_) throw std::runtime_error("StatsCsv: cannot open '" + path_ + "' for writing");
  writeLine(csvHeader(columns_));
}

StatsCsv::StatsCsv(StatsCsv&& other) noexcept
    : path_(std::move(other.path_)), columns_(std::move(other.columns_)), file_(other.file_), rows_(other.rows_) {
  other.file_ = nullptr;
}

StatsCsv StatsCsv::resume(const std::string& path, std::vector<std::string> columns, const std::string& keyColumn,
                          double keyLimit) {
  StatsCsv csv;
  csv.path_ = path;
  csv.columns_ = std::move(columns);
  csv.checkColumns();
  const auto key = std::find(csv.columns_.begin(), csv.columns_.end(), keyColumn);
  if (key == csv.columns_.end())
    throw std::invalid_argument("StatsCsv::resume: unknown column '" + keyColumn + "' for '" + path + "'");
  std::ifstream in(path);
  if (!in) throw std::runtime_error("StatsCsv: cannot read '" + path + "' to resume it");
  std::string line, kept;
  if (!std::getline(in, line) || line != csvHeader(csv.columns_))
    throw std::runtime_error("StatsCsv: '" + path + "' has other columns than this build writes; move it away to resume");
  kept = line + '\n';
  while (std::getline(in, line)) {
    // a row cut short by a killed process (its last) lacks fields, or its key may be cut: dropped
    const std::vector<std::string> fields = csvFields(line);
    if (fields.size() != csv.columns_.size()) continue;
    const std::string& field = fields[std::size_t(key - csv.columns_.begin())];
    char* end = nullptr;
    const double value = std::strtod(field.c_str(), &end);
    if (field.empty() || end != field.c_str() + field.size() || !(value < keyLimit)) continue;
    kept += line + '\n';
    ++csv.rows_;
  }
  in.close();
  writeFileAtomically(path, "StatsCsv", [&](const std::string& tmp) {
    std::ofstream out(tmp, std::ios::trunc);
    out << kept;
    out.close();
    if (!out) throw std::runtime_error("disk full or not writable?");
  });
  csv.file_ = std::fopen(path.c_str(), "a");
  if (!csv.file_) throw std::runtime_error("StatsCsv: cannot open '" + path + "' for appending");
  return csv;
}

StatsCsv::~StatsCsv() {
  if (file_) std::fclose(file_);
}

void StatsCsv::writeLine(const std::string& line) {
  if (std::fputs(line.c_str(), file_) < 0 || std::fputc('\n', file_) == EOF || std::fflush(file_) != 0)
    throw std::runtime_error("StatsCsv: write failed on '" + path_ + "'");
}

void StatsCsv::row(const std::vector<std::pair<std::string, double>>& values) { row(values, {}); }

void StatsCsv::row(const std::vector<std::pair<std::string, double>>& values,
                   const std::vector<std::pair<std::string, std::string>>& text) {
  std::vector<std::string> fields(columns_.size());
  auto field = [&](const std::string& name) -> std::string& {
    const auto it = std::find(columns_.begin(), columns_.end(), name);
    if (it == columns_.end())
      throw std::invalid_argument("StatsCsv: unknown column '" + name + "' for '" + path_ + "'");
    return fields[static_cast<std::size_t>(it - columns_.begin())];
  };
  for (const auto& [name, value] : values) field(name) = formatNumber(value);
  for (const auto& [name, value] : text) field(name) = csvField(value);
  std::string line;
  for (std::size_t c = 0; c < fields.size(); ++c) {
    if (c) line += ',';
    line += fields[c];
  }
  writeLine(line);
  ++rows_;
}

void StatsCsv::row(const std::vector<double>& values) {
  if (values.size() != columns_.size())
    throw std::invalid_argument("StatsCsv: " + std::to_string(values.size()) + " values for " +
                                std::to_string(columns_.size()) + " columns in '" + path_ + "'");
  std::string line;
  for (std::size_t c = 0; c < values.size(); ++c) {
    if (c) line += ',';
    line += formatNumber(values[c]);
  }
  writeLine(line);
  ++rows_;
}

}  // namespace output
}  // namespace stokes::sim
