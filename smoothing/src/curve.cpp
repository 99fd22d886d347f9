// Curve reading and writing (see curve.hpp for the accepted format).
#include "demcal/smoothing/curve.hpp"

#include "demcal/limits/limits.hpp"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <fstream>
#include <limits>
#include <optional>
#include <set>
#include <sstream>

namespace demcal::smoothing {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

bool valid_utf8(const std::string& s) {
  std::size_t i = 0;
  while (i < s.size()) {
    const auto c = static_cast<unsigned char>(s[i]);
    if (c < 0x80) {
      ++i;
      continue;
    }
    const std::size_t extra = (c >> 5) == 0x6 ? 1 : (c >> 4) == 0xE ? 2 : (c >> 3) == 0x1E ? 3 : 0;
    if (extra == 0 || i + extra >= s.size()) return false;
    for (std::size_t k = 1; k <= extra; ++k)
      if ((static_cast<unsigned char>(s[i + k]) >> 6) != 0x2) return false;
    i += extra + 1;
  }
  return true;
}

std::string latin1_to_utf8(const std::string& s) {
  std::string out;
  for (char ch : s) {
    const auto c = static_cast<unsigned char>(ch);
    if (c < 0x80) {
      out += ch;
    } else {
      out += static_cast<char>(0xC0 | (c >> 6));
      out += static_cast<char>(0x80 | (c & 0x3F));
    }
  }
  return out;
}

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

std::string unquote(std::string s) {
  s = trim(s);
  if (s.size() >= 2 && ((s.front() == '"' && s.back() == '"') || (s.front() == '\'' && s.back() == '\'')))
    s = trim(s.substr(1, s.size() - 2));
  return s;
}

std::vector<std::string> split(const std::string& line, char sep) {
  std::vector<std::string> cells;
  std::string cell;
  bool quoted = false;
  for (char c : line) {
    if (c == '"') quoted = !quoted;
    if (c == sep && !quoted) {
      cells.push_back(cell);
      cell.clear();
    } else {
      cell += c;
    }
  }
  cells.push_back(cell);
  return cells;
}

enum class CellKind { number, nan, empty, text };

// Parses one cell; `decimal_comma` accepts "0,23".
CellKind parse_cell(const std::string& raw, bool decimal_comma, double* value) {
  std::string s = unquote(raw);
  if (s.empty()) {
    *value = kNaN;
    return CellKind::empty;
  }
  std::string lower = s;
  std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return std::tolower(c); });
  if (lower == "nan" || lower == "-nan" || lower == "na" || lower == "n/a") {
    *value = kNaN;
    return CellKind::nan;
  }
  if (decimal_comma) std::replace(s.begin(), s.end(), ',', '.');
  const char* begin = s.data();
  if (*begin == '+') ++begin;
  double v = 0;
  const auto [ptr, ec] = std::from_chars(begin, s.data() + s.size(), v);
  if (ec != std::errc() || ptr != s.data() + s.size()) return CellKind::text;
  if (!std::isfinite(v)) return CellKind::text;  // "inf" is not a measurement
  *value = v;
  return CellKind::number;
}

bool is_data_line(const std::vector<std::string>& cells, bool decimal_comma) {
  if (cells.size() < 2) return false;
  bool any_number = false;
  for (const auto& c : cells) {
    double v;
    const auto kind = parse_cell(c, decimal_comma, &v);
    if (kind == CellKind::text) return false;
    any_number = any_number || kind == CellKind::number;
  }
  return any_number;
}

bool is_units_row(const std::vector<std::string>& cells) {
  bool any = false;
  for (const auto& raw : cells) {
    const std::string c = unquote(raw);
    if (c.empty()) continue;
    const bool bracketed = (c.front() == '[' && c.back() == ']') || (c.front() == '(' && c.back() == ')');
    if (!bracketed) return false;
    any = true;
  }
  return any;
}

std::string strip_unit_brackets(const std::string& raw) {
  std::string c = unquote(raw);
  if (c.size() >= 2 && (c.front() == '[' || c.front() == '(')) c = trim(c.substr(1, c.size() - 2));
  return c;
}

// "displacement [mm]" -> name "displacement", unit "mm".
void split_name_unit(const std::string& raw, std::string* name, std::string* unit) {
  std::string c = unquote(raw);
  unit->clear();
  if (!c.empty() && (c.back() == ']' || c.back() == ')')) {
    const char open = c.back() == ']' ? '[' : '(';
    const auto pos = c.rfind(open);
    if (pos != std::string::npos && pos > 0) {
      *unit = trim(c.substr(pos + 1, c.size() - pos - 2));
      c = trim(c.substr(0, pos));
    }
  }
  *name = c;
}

std::string shown(const std::string& cell) {
  std::string out(1, '\'');
  out += trim(cell);
  out += '\'';
  return out;
}

// "a, b, c"
std::string joined_names(const std::vector<Column>& columns) {
  std::string names;
  for (const auto& c : columns) names += (names.empty() ? "" : ", ") + c.name;
  return names;
}

}  // namespace

const Column& Curve::column(const std::string& name) const {
  for (const auto& c : columns)
    if (c.name == name) return c;
  const std::string names = joined_names(columns);
  throw CurveError(source + ": no column '" + name + "' (columns: " + (names.empty() ? "none" : names) + ")");
}

Column& Curve::column(const std::string& name) {
  return const_cast<Column&>(static_cast<const Curve&>(*this).column(name));
}

bool Curve::has_column(const std::string& name) const {
  return std::any_of(columns.begin(), columns.end(), [&](const Column& c) { return c.name == name; });
}

std::vector<std::string> Curve::column_names() const {
  std::vector<std::string> out;
  for (const auto& c : columns) out.push_back(c.name);
  return out;
}

std::size_t Curve::rows() const { return columns.empty() ? 0 : columns.front().values.size(); }

namespace {

// A non-blank line of the file, converted to UTF-8, with its 1-based number.
using NumberedLine = std::pair<std::size_t, std::string>;

std::string at_line(const std::string& source, std::size_t number) {
  return source + ": line " + std::to_string(number);
}

std::vector<NumberedLine> non_blank_lines(const std::string& text) {
  std::vector<NumberedLine> lines;
  std::size_t start = 0, number = 0;
  while (start <= text.size()) {
    auto end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    std::string line = text.substr(start, end - start);
    ++number;
    if (number == 1 && line.rfind("\xEF\xBB\xBF", 0) == 0) line = line.substr(3);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (!valid_utf8(line)) line = latin1_to_utf8(line);
    if (!trim(line).empty()) lines.emplace_back(number, line);
    start = end + 1;
  }
  return lines;
}

// How the data is written: its separator, its decimal mark and its first line (an index of lines).
struct DataLayout {
  char separator = 0;  // 0: no line of numbers found
  bool decimal_comma = false;
  std::size_t first_data = 0;
};

// The first candidate separator that yields a line of >= 2 numeric cells wins.
DataLayout find_data_layout(const std::vector<NumberedLine>& lines, const CurveReadOptions& options) {
  const std::vector<char> candidates =
      options.separator ? std::vector<char>{options.separator} : std::vector<char>{'\t', ';', ','};
  DataLayout layout;
  layout.first_data = lines.size();
  for (char c : candidates) {
    for (bool dc : {false, true}) {
      if (dc && c == ',') continue;
      for (std::size_t i = 0; i < lines.size(); ++i) {
        if (is_data_line(split(lines[i].second, c), dc)) {
          if (i < layout.first_data || (i == layout.first_data && !layout.separator)) {
            layout.first_data = i;
            layout.separator = c;
            layout.decimal_comma = dc;
          }
          break;
        }
      }
      if (layout.separator) break;
    }
    if (layout.separator) break;
  }
  return layout;
}

// No numeric row at all: reports the first line after the header that is not numeric.
[[noreturn]] void throw_no_data_rows(const std::vector<NumberedLine>& lines, const std::string& source) {
  const auto& [number, line] = lines.size() > 1 ? lines[1] : lines[0];
  if (lines.size() == 1) throw CurveError(at_line(source, lines[0].first) + ": no data rows (only a header)");
  if (is_data_line({trim(line), "0"}, false))  // a number alone on its line: a file of one column
    throw CurveError(at_line(source, number) + ": one column only ('" + trim(line) +
                     "'); a curve needs a force column and at least one displacement column, separated by ',', ';' "
                     "or a tab");
  throw CurveError(at_line(source, number) + ": no numeric data rows found (first: '" + trim(line) +
                   "'); cells must be numbers separated by ',', ';' or a tab");
}

// The rows above the data: [preamble...] names [units].
struct Header {
  std::size_t names_index = 0;  // index in lines of the column names
  std::vector<std::string> name_cells;
  std::vector<std::string> units;  // empty without a units row
};

Header find_header(const std::vector<NumberedLine>& lines, const DataLayout& layout, const std::string& source) {
  if (layout.first_data == 0) throw CurveError(at_line(source, lines[0].first) + ": no column names before the data");
  Header header;
  header.names_index = layout.first_data - 1;
  if (is_units_row(split(lines[header.names_index].second, layout.separator))) {
    header.units = split(lines[header.names_index].second, layout.separator);
    if (header.names_index == 0)
      throw CurveError(at_line(source, lines[0].first) + ": a units row but no column names");
    --header.names_index;
  }
  header.name_cells = split(lines[header.names_index].second, layout.separator);
  return header;
}

// A "names" row that holds a number is a data row with a bad cell (e.g. the first data row).
void reject_numeric_names(const std::vector<std::string>& name_cells, bool decimal_comma, std::size_t line_of_names,
                          const std::string& source) {
  for (std::size_t j = 0; j < name_cells.size(); ++j) {
    double v;
    if (parse_cell(name_cells[j], decimal_comma, &v) == CellKind::number && name_cells.size() > 1) {
      for (std::size_t k = 0; k < name_cells.size(); ++k)
        if (parse_cell(name_cells[k], decimal_comma, &v) == CellKind::text)
          throw CurveError(at_line(source, line_of_names) + ", column " + std::to_string(k + 1) +
                           ": non-numeric value " + shown(name_cells[k]) + " (no column names found above it)");
    }
  }
}

// Empty columns named by the header, with their units (a units row overrides a unit in the name).
std::vector<Column> header_columns(const Header& header, std::size_t line_of_names, const std::string& source) {
  std::vector<Column> columns;
  std::set<std::string> seen;
  for (std::size_t j = 0; j < header.name_cells.size(); ++j) {
    Column col;
    split_name_unit(header.name_cells[j], &col.name, &col.unit);
    if (j < header.units.size() && !trim(header.units[j]).empty()) col.unit = strip_unit_brackets(header.units[j]);
    if (col.name.empty())
      throw CurveError(at_line(source, line_of_names) + ", column " + std::to_string(j + 1) + ": empty column name");
    if (!seen.insert(col.name).second)
      throw CurveError(at_line(source, line_of_names) + ", column " + std::to_string(j + 1) +
                       ": duplicate column name '" + col.name + "'");
    columns.push_back(std::move(col));
  }
  return columns;
}

// Appends the data rows to the curve's columns; returns how many rows hold only finite values.
std::size_t read_data_rows(const std::vector<NumberedLine>& lines, const DataLayout& layout, Curve& curve) {
  const std::string& source = curve.source;
  if (auto m = limits::check(limits::Limit::curve_rows, static_cast<double>(lines.size() - layout.first_data)))
    throw CurveError(at_line(source, lines[layout.first_data].first) + " on: " + *m);
  const std::size_t ncol = curve.columns.size();
  std::size_t finite_rows = 0;
  for (std::size_t i = layout.first_data; i < lines.size(); ++i) {
    auto cells = split(lines[i].second, layout.separator);
    while (cells.size() > ncol && trim(cells.back()).empty()) cells.pop_back();  // trailing separator
    if (cells.size() != ncol)
      throw CurveError(at_line(source, lines[i].first) + ": " + std::to_string(cells.size()) + " cells, expected " +
                       std::to_string(ncol) + " (columns: " + joined_names(curve.columns) + ")");
    bool all_finite = true;
    for (std::size_t j = 0; j < ncol; ++j) {
      double v;
      if (parse_cell(cells[j], layout.decimal_comma, &v) == CellKind::text)
        throw CurveError(at_line(source, lines[i].first) + ", column '" + curve.columns[j].name +
                         "': non-numeric value " + shown(cells[j]));
      all_finite = all_finite && std::isfinite(v);
      curve.columns[j].values.push_back(v);
    }
    if (all_finite) ++finite_rows;
  }
  return finite_rows;
}

}  // namespace

Curve parse_curve(const std::string& text, const std::string& source, const CurveReadOptions& options) {
  const std::vector<NumberedLine> lines = non_blank_lines(text);
  if (lines.empty()) throw CurveError(source + ": empty file (no header, no data)");
  const DataLayout layout = find_data_layout(lines, options);
  if (!layout.separator) throw_no_data_rows(lines, source);

  Curve curve;
  curve.source = source;
  const Header header = find_header(lines, layout, source);
  const std::size_t line_of_names = lines[header.names_index].first;
  reject_numeric_names(header.name_cells, layout.decimal_comma, line_of_names, source);
  for (std::size_t i = 0; i < header.names_index; ++i) curve.preamble.push_back(lines[i].second);
  curve.columns = header_columns(header, line_of_names, source);
  if (!header.units.empty() && header.units.size() != header.name_cells.size())
    throw CurveError(at_line(source, lines[header.names_index + 1].first) + ": " +
                     std::to_string(header.units.size()) + " units for " + std::to_string(header.name_cells.size()) +
                     " columns");

  const std::size_t finite_rows = read_data_rows(lines, layout, curve);
  if (options.reject_all_nan_columns)
    for (const auto& c : curve.columns)
      if (std::none_of(c.values.begin(), c.values.end(), [](double v) { return std::isfinite(v); }))
        throw CurveError(source + ": column '" + c.name + "' (line " + std::to_string(line_of_names) +
                         "): every value is NaN or empty");
  if (finite_rows < options.min_rows)
    throw CurveError(at_line(source, lines[layout.first_data].first) + ": " + std::to_string(finite_rows) +
                     " data row" + (finite_rows == 1 ? "" : "s") + " with finite values, at least " +
                     std::to_string(options.min_rows) + " needed");
  return curve;
}

Curve read_curve(const std::string& path, const CurveReadOptions& options) {
  if (auto m = limits::check_file_size(path)) throw CurveError(path + ": " + *m);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw CurveError(path + ": cannot open the file for reading");
  std::ostringstream buffer;
  buffer << in.rdbuf();
  if (in.bad()) throw CurveError(path + ": read error");
  return parse_curve(buffer.str(), path, options);
}

std::string format_curve(const Curve& curve) {
  const std::size_t n = curve.rows();
  for (const auto& c : curve.columns) {
    if (c.values.size() != n)
      throw CurveError(curve.source + ": column '" + c.name + "' has " + std::to_string(c.values.size()) +
                       " values, others " + std::to_string(n));
    double v;
    if (c.name.empty() || c.name.find_first_of(",;\t\"\n\r[]()") != std::string::npos ||
        parse_cell(c.name, false, &v) != CellKind::text || parse_cell(c.name, true, &v) != CellKind::text)
      throw CurveError(curve.source + ": column name '" + c.name +
                       "' cannot be written (empty, a number, or holds a separator, quote, bracket, parenthesis or newline)");
    if (c.unit.find_first_of(",;\t\"\n\r[]") != std::string::npos)
      throw CurveError(curve.source + ": unit '" + c.unit + "' of column '" + c.name +
                       "' cannot be written (holds a separator, quote, bracket or newline)");
  }
  // A preamble line that the reader would take for a data row (two or more numeric cells under any
  // separator it detects) would move the header when the file is read back: refused.
  for (std::size_t i = 0; i < curve.preamble.size(); ++i) {
    const std::string& line = curve.preamble[i];
    bool data_like = false;
    for (const char sep : {'\t', ';', ','})
      for (const bool dc : {false, true}) data_like = data_like || is_data_line(split(line, sep), dc);
    if (trim(line).empty() || line.find_first_of("\n\r") != std::string::npos || data_like)
      throw CurveError(curve.source + ": preamble line " + std::to_string(i + 1) + " '" + line +
                       "' cannot be written (blank, holds a line break, or reads as a data row)");
  }
  std::string out;
  for (const auto& line : curve.preamble) out += line + "\n";
  bool any_unit = false;
  for (std::size_t j = 0; j < curve.columns.size(); ++j) {
    out += (j ? "," : "") + curve.columns[j].name;
    any_unit = any_unit || !curve.columns[j].unit.empty();
  }
  out += "\n";
  if (any_unit) {
    for (std::size_t j = 0; j < curve.columns.size(); ++j) out += std::string(j ? "," : "") + "[" + curve.columns[j].unit + "]";
    out += "\n";
  }
  std::array<char, 64> buf{};
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = 0; j < curve.columns.size(); ++j) {
      if (j) out += ',';
      const double v = curve.columns[j].values[i];
      if (std::isnan(v)) {
        out += "nan";
      } else {
        const auto [ptr, ec] = std::to_chars(buf.data(), buf.data() + buf.size(), v);
        out.append(buf.data(), ptr);
      }
    }
    // One column: a trailing separator keeps the row recognisable as data (the reader needs two
    // cells to detect the separator and drops a trailing empty cell).
    if (curve.columns.size() == 1) out += ',';
    out += '\n';
  }
  return out;
}

void write_curve(const Curve& curve, const std::string& path) {
  const std::string text = format_curve(curve);
  std::ofstream out(path, std::ios::binary);
  if (!out) throw CurveError(path + ": cannot open the file for writing");
  out << text;
  if (!out) throw CurveError(path + ": write error");
}

XYSeries series(const Curve& curve, const std::string& x_column, const std::string& y_column) {
  const auto& xc = curve.column(x_column);
  const auto& yc = curve.column(y_column);
  XYSeries s;
  for (std::size_t i = 0; i < xc.values.size() && i < yc.values.size(); ++i) {
    if (std::isnan(xc.values[i]) || std::isnan(yc.values[i])) continue;
    s.x.push_back(xc.values[i]);
    s.y.push_back(yc.values[i]);
  }
  return s;
}

}  // namespace demcal::smoothing
