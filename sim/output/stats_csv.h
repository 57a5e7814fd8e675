#pragma once
// Per-step statistics as CSV (DIR/stats.csv of a run).
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

namespace stokes::sim {
inline namespace output {

/// A CSV file of per-step statistics. The header is written on construction; every row is flushed
/// (a crash keeps the rows so far); numbers are written with %.9g. Not thread-safe.
class StatsCsv {
 public:
  /// Opens (truncates) `path`; throws std::runtime_error naming the path when it cannot, and
  /// std::invalid_argument for an empty or duplicated column list.
  StatsCsv(const std::string& path, std::vector<std::string> columns);
  /// Continues the file of a resumed run: keeps its header and the rows whose `keyColumn` value is
  /// below `keyLimit` (the steps before the checkpoint; rows of steps after it are dropped, they
  /// will be written again), rewritten through a temporary file, then appends. Throws
  /// std::runtime_error naming the path when it is missing, unreadable, or its header is not
  /// `columns`.
  static StatsCsv resume(const std::string& path, std::vector<std::string> columns, const std::string& keyColumn,
                         double keyLimit);
  StatsCsv(StatsCsv&& other) noexcept;
  ~StatsCsv();
  StatsCsv(const StatsCsv&) = delete;
  StatsCsv& operator=(const StatsCsv&) = delete;
  StatsCsv& operator=(StatsCsv&&) = delete;

  /// One row by column name; columns not given are left empty. Throws std::invalid_argument
  /// naming an unknown column.
  void row(const std::vector<std::pair<std::string, double>>& values);
  /// The same with text columns too (quoted where CSV needs it).
  void row(const std::vector<std::pair<std::string, double>>& values,
           const std::vector<std::pair<std::string, std::string>>& text);
  /// One row in column order; throws std::invalid_argument when the count differs.
  void row(const std::vector<double>& values);

  const std::string& path() const { return path_; }
  const std::vector<std::string>& columns() const { return columns_; }
  std::size_t rowsWritten() const { return rows_; }

 private:
  StatsCsv() = default;
  void checkColumns() const;
  void writeLine(const std::string& line);
  std::string path_;
  std::vector<std::string> columns_;
  std::FILE* file_ = nullptr;
  std::size_t rows_ = 0;
};

}  // namespace output
}  // namespace stokes::sim
