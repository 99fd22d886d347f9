// A number as text, one way for the whole project: in messages, report and study tables, gnuplot
// scripts and command lines alike.
//
// The text is exactly printf's %.Ng (significant digits) or %.Nf (fixed decimals) in the "C"
// locale, whatever the process's locale: "." as the decimal point, no digit grouping, and
// "nan", "-nan", "inf", "-inf" for the non-finite values unless NumberFormat::non_finite says
// otherwise. A std::ostream with precision(N) and default flags writes the same text as significant_digits = N.
//
//   format_number(0.000139, 3)                             "0.000139"
//   format_number(1234567.0, 3)                            "1.23e+06"
//   format_number(2.5, 6)                                  "2.5"       (printf's %g)
//   format_number(0.1, round_trip_digits)                  "0.10000000000000001"
//   format_number(2.0, {.fixed_decimals = 3})              "2.000"
//   format_number(NAN, {.non_finite = "-"})                "-"
#pragma once

#include <string>
#include <string_view>

namespace demcal {

// The significant digits with which every double reads back to itself (max_digits10).
inline constexpr int round_trip_digits = 17;

struct NumberFormat {
  // Significant digits, as printf's %.Ng: the shorter of fixed and scientific notation, trailing
  // zeros dropped. 6 is printf's and iostream's default; round_trip_digits keeps every bit. 0 counts
  // as 1; at most 100. Not used when fixed_decimals is set.
  int significant_digits = 6;
  // >= 0: fixed notation with this many digits after the point instead, as printf's %.Nf
  // (2: 0.5 -> "0.50"; 0: 3.0 -> "3", no point; at most 100). -1: significant digits.
  int fixed_decimals = -1;
  // Not empty: the whole text for NaN and +/-inf (a table's "-"). Empty: printf's own words above.
  std::string_view non_finite = {};
};

std::string format_number(double value, const NumberFormat& format);

// format_number(value, {.significant_digits = significant_digits}). No default: every caller says
// how many digits its text shows.
std::string format_number(double value, int significant_digits);

}  // namespace demcal
