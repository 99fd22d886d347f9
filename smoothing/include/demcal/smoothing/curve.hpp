// Curves: named, unit-carrying columns of doubles read from and written to delimited text files.
//
// The reader accepts real laboratory files as they are:
//   - any number of preamble lines before the data ("Test unit,SW.30.1", a reference line, ...);
//     they are kept in Curve::preamble;
//   - a row of column names, optionally followed by a row of units ("[mm],[kN],[%]" or "(mm)");
//     a name written as "displacement [mm]" also carries its unit;
//   - comma, semicolon or tab separators (detected, or forced); with ';' or tab a decimal comma is
//     accepted ("0,23");
//   - UTF-8 or Latin-1 bytes (Latin-1 lines are converted to UTF-8), a UTF-8 byte-order mark, CRLF;
//   - NaN rows between cycles ("nan", "NaN", "NA" or an empty cell read as NaN) and blank lines
//     (skipped); abscissae that repeat or step back are kept as they are (callers decide, see
//     objective.hpp for the rule the objective functions use).
// Bad input throws CurveError naming the file, the 1-based line, the column and the offending value.
#pragma once

#include <cstddef>
#include <stdexcept>
#include <string>
#include <vector>

namespace demcal::smoothing {

// Bad curve input: the message names file, line and column where they are known, e.g.
//   "data.csv: line 7, column 'force': non-numeric value 'abc'".
class CurveError : public std::runtime_error {
 public:
  explicit CurveError(const std::string& message) : std::runtime_error(message) {}
};

struct Column {
  std::string name;            // as in the file's header, trimmed, quotes removed
  std::string unit;            // without brackets ("mm"); empty when the file gives none
  std::vector<double> values;  // one per data row; NaN where the file has a NaN/empty cell
};

struct Curve {
  std::vector<Column> columns;
  std::string source;                 // file name (or a label) used in error messages
  std::vector<std::string> preamble;  // lines before the names row, UTF-8, written back by write_curve

  // Column by exact name; throws CurveError "<source>: no column '<name>' (columns: a, b, c)".
  const Column& column(const std::string& name) const;
  Column& column(const std::string& name);
  bool has_column(const std::string& name) const;
  // Names in file order.
  std::vector<std::string> column_names() const;
  // Number of data rows (0 for a curve without columns).
  std::size_t rows() const;
};

struct CurveReadOptions {
  char separator = 0;        // ',', ';' or '\t'; 0 = detect (tab, then ';', then ',')
  std::size_t min_rows = 2;  // fewer finite data rows than this is an error (a curve needs two points)
  // Every column must hold at least one finite value (an all-NaN column is an error naming it).
  bool reject_all_nan_columns = true;
};

// Reads a delimited text file (see the top of this header). Throws CurveError on: a missing or
// unreadable file, an empty file, no names row, duplicate column names, a row with a different
// number of cells than the names row, a non-numeric cell, fewer than min_rows rows with finite
// values, an all-NaN column.
Curve read_curve(const std::string& path, const CurveReadOptions& options = {});

// The same parser on text already in memory; `source` names it in messages.
Curve parse_curve(const std::string& text, const std::string& source,
                  const CurveReadOptions& options = {});

// Writes preamble lines, a comma-separated names row, a units row ("[mm],[kN]") when any unit is
// non-empty, then the values (shortest text that reads back to the same double; NaN as "nan").
// read_curve reads the result back to an equal curve. Throws CurveError if the file cannot be
// written, columns differ in length, or a name contains a separator, quote or newline.
void write_curve(const Curve& curve, const std::string& path);
std::string format_curve(const Curve& curve);

// A plain x–y series (one channel), e.g. displacement and force.
struct XYSeries {
  std::vector<double> x;
  std::vector<double> y;
};

// Two columns of a curve as a series, skipping rows where either value is NaN (cycle separators).
XYSeries series(const Curve& curve, const std::string& x_column, const std::string& y_column);

}  // namespace demcal::smoothing
